//! Several devices on one collection: batch extraction and pair matching spread over a list of
//! workers, each result equal to the one-device call's.

mod lane;
mod schedule;

use crate::backend::Backend;
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::extract::{Extractor, ExtractorConfig};
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::matcher::Matcher;
use crate::matching::{Match, MatchConfig};
use lane::Collection;

/// A collection's work spread over several devices in one process: batch extraction and pair
/// matching, with every result equal to what one [`Extractor`] or [`Matcher`] gives, in the same
/// order.
///
/// A pool is a list of workers, each a [`Backend`]; a device may be listed several times, and each
/// listing is a worker of its own (its own thread and, on a GPU, its own streams). `Backend::Cpu`
/// workers share the CPU's threads; they stand in for devices where there are none (tests, CI).
///
/// Work is handed out dynamically: a worker takes the next image, or the next *block* of pairs, when
/// it is done with the last. A block is a tile of the pair matrix (and its mirror): the pairs
/// `(a, b)` with `a / tile` and `b / tile` the block's two tile indices, so a worker on a block reads
/// at most `2 * tile` sets, and holds each of them ready for its device (resident) for the whole
/// block instead of preparing it again for every pair. On the CPU a set needs no preparing; a CUDA
/// worker keeps one [`crate::DescriptorCollection`] for the whole run, uploads each set the first
/// time a block reads it (later blocks find it resident, up to 2^24 descriptors, after which the
/// collection starts afresh) and matches each block's pairs many per launch, as one-device
/// [`Matcher::match_pairs`] does with all of its sets.
///
/// Every result is computed by one device exactly as the single-device call computes it, so which
/// worker took it, and how many workers there are, change nothing: results are bit-identical and in
/// input order, ties included. The first error of any worker stops the others at their next item
/// and is returned as [`Error::Worker`], naming the worker.
///
/// ```
/// use clatch::{Backend, DescriptorSet, DescriptorWidth, DevicePool, MatchConfig, Matcher};
///
/// // Three workers: stand-ins for three GPUs (`Backend::Cuda { device: 0 }`, `{ device: 1 }`, ...).
/// let pool = DevicePool::new(&[Backend::Cpu; 3])?.with_tile(2)?;
/// let width = DescriptorWidth::from_bits(64)?;
/// let owned: Vec<DescriptorSet> = (0..5u64)
///     .map(|s| {
///         let words = (0..200u64).map(|i| (i * 7 + s).wrapping_mul(0x9E37_79B9_7F4A_7C15)).collect();
///         DescriptorSet::from_words(width, words)
///     })
///     .collect::<Result<_, _>>()?;
/// let sets: Vec<&DescriptorSet> = owned.iter().collect();
///
/// let config = MatchConfig::default();
/// let all = pool.match_all_pairs(&config, &sets)?;
/// let one_device = Matcher::new(Backend::Cpu, config)?;
/// assert_eq!(all, one_device.match_pairs(&sets, &Matcher::all_pairs(5))?);
/// assert_eq!(all[0], one_device.match_descriptors(&owned[0], &owned[1])?); // pair (0, 1)
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DevicePool {
    workers: Vec<Backend>,
    tile: usize,
}

impl DevicePool {
    /// Sets per side of a block of pairs unless [`DevicePool::with_tile`] says otherwise: blocks of
    /// up to 1024 pairs, 64 sets resident per worker at most.
    pub const DEFAULT_TILE: usize = 32;

    /// A pool of `workers`, one per entry (repeats allowed: each is a worker of its own), with
    /// [`DevicePool::DEFAULT_TILE`]. Every worker's backend is checked: an empty list is
    /// [`Error::NoWorkers`], a backend that cannot run here (a device index past the last device,
    /// CUDA not compiled in) is [`Error::Worker`] with the backend's own error as its source.
    pub fn new(workers: &[Backend]) -> Result<Self> {
        if workers.is_empty() {
            return Err(Error::NoWorkers);
        }
        for (worker, backend) in workers.iter().enumerate() {
            backend.ensure_available().map_err(|source| Error::Worker {
                worker,
                backend: backend.to_string(),
                source: Box::new(source),
            })?;
        }
        Ok(Self {
            workers: workers.to_vec(),
            tile: Self::DEFAULT_TILE,
        })
    }

    /// The same pool with blocks of pairs of `tile` x `tile` sets (at least 1; 0 is
    /// [`Error::InvalidConfig`]). Larger tiles mean fewer, larger blocks: fewer set preparations,
    /// more memory per worker and coarser load balance. Results do not depend on it.
    pub fn with_tile(self, tile: usize) -> Result<Self> {
        if tile == 0 {
            return Err(Error::InvalidConfig {
                field: "tile",
                value: tile.to_string(),
                reason: "a block of pairs spans at least one set per side",
            });
        }
        Ok(Self { tile, ..self })
    }

    /// The workers' backends, in the order given.
    pub fn workers(&self) -> &[Backend] {
        &self.workers
    }

    /// Sets per side of a block of pairs.
    pub fn tile(&self) -> usize {
        self.tile
    }

    /// [`Extractor::detect_and_describe`] of every image with `config`, in input order, each result
    /// equal to [`Extractor::detect_and_describe_batch`]'s on one device. The configuration and every
    /// image are checked before any work. Images are handed to workers one at a time as they free
    /// up.
    pub fn detect_and_describe_batch(
        &self,
        config: &ExtractorConfig,
        images: &[GrayView],
    ) -> Result<Vec<Features>> {
        self.detect_and_describe_batch_with_progress(config, images, &|_| {})
    }

    /// [`DevicePool::detect_and_describe_batch`], calling `progress(i)` once per image `i` as it
    /// finishes, in any order, from the workers' threads.
    pub fn detect_and_describe_batch_with_progress(
        &self,
        config: &ExtractorConfig,
        images: &[GrayView],
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<Vec<Features>> {
        // Checks the configuration (the CPU is always there); each worker runs it on its backend.
        let template = Extractor::new(Backend::Cpu, config.clone())?;
        for image in images {
            Extractor::check_image(image)?;
        }
        schedule::run_workers(
            &self.workers,
            images.len(),
            images.len(),
            |_, backend, queue| lane::extract_on(&template.on(backend), images, queue, progress),
        )
    }

    /// The matches of every pair with `config`, in pair order, equal pair by pair to
    /// [`Matcher::match_pairs`] on one device (so to one [`Matcher::match_descriptors`] per pair;
    /// pairs without a query or with too small a gallery get no matches). Pairs may come in any
    /// order and repeat. The configuration, every index and every width are checked before any work
    /// ([`Error::PairOutOfRange`], [`Error::DescriptorWidthMismatch`]). Blocks of pairs (see
    /// [`DevicePool`]) are handed to workers as they free up.
    pub fn match_pairs(
        &self,
        config: &MatchConfig,
        sets: &[&DescriptorSet],
        pairs: &[(usize, usize)],
    ) -> Result<Vec<Vec<Match>>> {
        self.match_pairs_with_progress(config, sets, pairs, &|_| {})
    }

    /// [`DevicePool::match_pairs`], calling `progress(p)` once per pair `p` as it finishes, in any
    /// order, from the workers' threads.
    pub fn match_pairs_with_progress(
        &self,
        config: &MatchConfig,
        sets: &[&DescriptorSet],
        pairs: &[(usize, usize)],
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<Vec<Vec<Match>>> {
        // Checks the configuration (the CPU is always there); each worker runs it on its backend.
        let matcher = Matcher::new(Backend::Cpu, config.clone())?;
        matcher.check_pairs(sets, pairs)?;
        let blocks = schedule::blocks(pairs, self.tile, |pair| matcher.matchable(sets, pair));
        let collection = Collection {
            sets,
            pairs,
            blocks,
            matcher,
        };
        schedule::run_workers(
            &self.workers,
            collection.blocks.len(),
            pairs.len(),
            |_, backend, queue| {
                let on_worker = collection.matcher.on(backend);
                lane::match_on(&on_worker, &collection, queue, progress)
            },
        )
    }

    /// [`DevicePool::match_pairs`] of every pair `(i, j)`, `i < j`, in [`Matcher::all_pairs`] order
    /// (with progress: [`DevicePool::match_pairs_with_progress`] of [`Matcher::all_pairs`]).
    pub fn match_all_pairs(
        &self,
        config: &MatchConfig,
        sets: &[&DescriptorSet],
    ) -> Result<Vec<Vec<Match>>> {
        self.match_pairs(config, sets, &Matcher::all_pairs(sets.len()))
    }
}
