//! A collection of descriptor sets held ready for matching on one backend: added once, matched many
//! times (every pair, listed pairs, or a query set against the held ones), results handed out pair by
//! pair as they complete.

use std::ops::Range;

mod pairs;
mod pool;

pub use pool::DevicePool;

use crate::backend::Backend;
use crate::cuda;
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::error::{Error, Result};
use crate::keypoint::KeyPoint;
use crate::matcher::Matcher;
use crate::matching::{self, Match, MatchConfig};
use crate::parallel::*;

/// Pairs the CPU matches at once (over all its threads) before handing their results out in order.
const HOST_BLOCK: usize = 256;

/// Descriptor sets of one width held by a backend for matching, as a gallery (FAISS's
/// `GpuIndexBinaryFlat` with add and search) or as the photos of a collection (every pair, as structure
/// from motion needs).
///
/// On `Backend::Cuda` the sets live on the device from [`DescriptorCollection::add`] on: each crosses
/// the bus once, however many pairs read it, and many pairs are matched per kernel launch. On
/// `Backend::Cpu` they are kept in host memory. Every result equals [`Matcher::match_descriptors`] of
/// the pair with the collection's [`MatchConfig`], ties included, on either backend; a pair with no
/// query, or with too small a gallery (none, or one descriptor under the ratio test), gets no matches,
/// as in [`Matcher::match_pairs`].
///
/// Each request comes in two forms. The plain call ([`DescriptorCollection::match_pairs`],
/// [`match_all_pairs`](DescriptorCollection::match_all_pairs), [`search`](DescriptorCollection::search),
/// [`search_sets`](DescriptorCollection::search_sets)) returns every result in request order, as
/// [`Matcher::match_pairs`] does. Its `*_each` form ([`DescriptorCollection::match_pairs_each`], ...)
/// holds none of them: it hands each to a callback, `each(i, matches)`, once per pair `i` of the
/// request, in increasing `i`, as soon as the block of pairs holding it is back, so memory stays
/// bounded for any number of pairs (blocks of pairs are matched one after another) and the caller may
/// write each result out and drop it; `each` is the progress report too. The callback may match on
/// the same collection again, and several threads may match one collection at once (it is `Sync`; on
/// CUDA their work shares the collection's stream).
///
/// ```
/// use clatch::{Backend, DescriptorCollection, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};
///
/// let width = DescriptorWidth::from_bits(64)?;
/// let set = |seed: u64| {
///     let words = (0..100).map(|i| (i as u64 + seed).wrapping_mul(0x9E37_79B9_7F4A_7C15)).collect();
///     DescriptorSet::from_words(width, words)
/// };
/// let (a, b, c) = (set(0)?, set(50)?, set(7)?);
/// let matcher = Matcher::new(Backend::Cpu, MatchConfig::default())?;
/// let mut collection = DescriptorCollection::new(&matcher, width)?;
/// assert_eq!(collection.add(&[&a, &b])?, 0..2);
/// assert_eq!(collection.add(&[&c])?, 2..3);
///
/// let all = collection.match_all_pairs()?;
/// assert_eq!(all.len(), 3); // (0, 1), (0, 2), (1, 2)
/// assert_eq!(all[1], matcher.match_descriptors(&a, &c)?);
///
/// let found = collection.search(&b)?; // b against sets 0, 1 and 2
/// assert_eq!(found[1], matcher.match_descriptors(&b, &b)?);
///
/// // Each result handed over as it is ready, none held: e.g. written out, counted, dropped.
/// let mut total = 0;
/// collection.match_all_pairs_each(|_pair, matches| total += matches.len())?;
/// assert_eq!(total, all.iter().map(Vec::len).sum::<usize>());
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Debug)]
pub struct DescriptorCollection {
    matcher: Matcher,
    width: DescriptorWidth,
    sizes: Vec<usize>,
    store: Store,
}

/// Where the sets are held.
#[derive(Debug)]
enum Store {
    Host(Vec<DescriptorSet>),
    Device(cuda::DeviceCollection),
}

impl DescriptorCollection {
    /// An empty collection of `width`-bit sets on `matcher`'s backend, matched with its configuration.
    pub fn new(matcher: &Matcher, width: DescriptorWidth) -> Result<Self> {
        let store = match matcher.backend() {
            Backend::Cpu => Store::Host(Vec::new()),
            Backend::Cuda { device } => {
                Store::Device(cuda::DeviceCollection::new(cuda::device(device)?, width)?)
            }
        };
        Ok(Self {
            matcher: matcher.clone(),
            width,
            sizes: Vec::new(),
            store,
        })
    }

    /// The matcher whose backend holds the sets and whose configuration matches them.
    pub fn matcher(&self) -> &Matcher {
        &self.matcher
    }

    /// The width of every set.
    pub fn width(&self) -> DescriptorWidth {
        self.width
    }

    /// Sets held.
    pub fn len(&self) -> usize {
        self.sizes.len()
    }

    /// True when no set is held.
    pub fn is_empty(&self) -> bool {
        self.sizes.is_empty()
    }

    /// Descriptors in set `id`; `None` past the last set.
    pub fn set_len(&self, id: usize) -> Option<usize> {
        self.sizes.get(id).copied()
    }

    /// Adds `sets` after the ones held and returns their ids (consecutive, in order). Every set must
    /// have the collection's width ([`Error::DescriptorWidthMismatch`], checked before any is added).
    /// On a CUDA backend this is where the descriptors are uploaded.
    pub fn add(&mut self, sets: &[&DescriptorSet]) -> Result<Range<usize>> {
        for set in sets {
            self.check_width(set)?;
        }
        match &mut self.store {
            Store::Host(held) => held.extend(sets.iter().map(|&s| s.clone())),
            Store::Device(device) => device.add(sets)?,
        }
        let first = self.sizes.len();
        self.sizes.extend(sets.iter().map(|s| s.len()));
        Ok(first..self.sizes.len())
    }

    /// Adds the features `pending` is computing ([`crate::Extractor::detect_and_describe_async`]) as
    /// the next set and returns its id with the keypoints. On a CUDA collection of the same device
    /// the descriptors go from the extraction's buffers into the collection's on the device, ordered
    /// by stream events, and never cross the bus; only the keypoints are read back (the host needs
    /// their positions). A CPU collection waits for the features and keeps the copy. The set equals
    /// the one `pending.wait()` would give, so every match does too.
    ///
    /// Errors: [`Error::DescriptorWidthMismatch`] when the extraction's width is not the
    /// collection's, [`Error::InvalidInput`] when it runs on another device; nothing is added then.
    ///
    /// ```no_run
    /// use clatch::cuda::GpuStream;
    /// use clatch::{Backend, DescriptorCollection, DescriptorWidth, Extractor, ExtractorConfig};
    /// use clatch::{GrayView, MatchConfig, Matcher};
    ///
    /// let gpu = Backend::Cuda { device: 0 };
    /// let extractor = Extractor::new(gpu, ExtractorConfig::default())?;
    /// let matcher = Matcher::new(gpu, MatchConfig::default())?;
    /// let mut collection = DescriptorCollection::new(&matcher, DescriptorWidth::FULL)?;
    /// let stream = GpuStream::new(0)?;
    /// let frames: Vec<Vec<u8>> = vec![vec![0; 640 * 480]; 2];
    /// for frame in &frames {
    ///     let view = GrayView::new(frame, 640, 480, 640)?;
    ///     let pending = extractor.detect_and_describe_async(&stream, &view)?;
    ///     let (id, keypoints) = collection.add_pending(pending)?;
    ///     println!("set {id}: {} keypoints", keypoints.len());
    /// }
    /// collection.match_all_pairs_each(|pair, matches| println!("pair {pair}: {} matches", matches.len()))?;
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn add_pending(
        &mut self,
        pending: cuda::PendingFeatures,
    ) -> Result<(usize, Vec<KeyPoint>)> {
        let width = pending.width();
        if width != self.width {
            return Err(Error::DescriptorWidthMismatch {
                query_bits: width.bits(),
                train_bits: self.width.bits(),
            });
        }
        let (keypoints, rows) = match &mut self.store {
            Store::Host(held) => {
                let features = pending.wait()?;
                let rows = features.descriptors.len();
                held.push(features.descriptors);
                (features.keypoints, rows)
            }
            Store::Device(device) => {
                if let Backend::Cuda { device: ordinal } = self.matcher.backend() {
                    pending.stream().check_device(ordinal)?;
                }
                let keypoints = pending.into_collection(device)?;
                let rows = keypoints.len();
                (keypoints, rows)
            }
        };
        self.sizes.push(rows);
        Ok((self.sizes.len() - 1, keypoints))
    }

    /// The matches of every `(a, b)` of `pairs` (held set `a` the queries, `b` the gallery; any
    /// order, repeats allowed), in pair order. Every id is checked before any work
    /// ([`Error::PairOutOfRange`]). [`DescriptorCollection::match_pairs_each`] gives the same results
    /// one at a time, without holding them.
    pub fn match_pairs(&self, pairs: &[(usize, usize)]) -> Result<Vec<Vec<Match>>> {
        collected(pairs.len(), |each| self.match_pairs_each(pairs, each))
    }

    /// [`DescriptorCollection::match_pairs`], each result handed to `each(i, matches)` (for
    /// `pairs[i]`, in increasing `i`) as soon as it is ready instead of returned: for more pairs
    /// than their matches fit in memory together.
    pub fn match_pairs_each(
        &self,
        pairs: &[(usize, usize)],
        mut each: impl FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        for (p, &(a, b)) in pairs.iter().enumerate() {
            self.check_id(p, a)?;
            self.check_id(p, b)?;
        }
        let config = self.matcher.config();
        match &self.store {
            Store::Host(held) => {
                in_host_blocks(pairs, each, |&(a, b)| {
                    match_on_host(&held[a], &held[b], config)
                });
                Ok(())
            }
            Store::Device(device) => device.match_pairs(pairs, config, &mut each),
        }
    }

    /// [`DescriptorCollection::match_pairs`] of every pair `(a, b)`, `a < b`, of the sets held, in
    /// [`Matcher::all_pairs`] order.
    pub fn match_all_pairs(&self) -> Result<Vec<Vec<Match>>> {
        self.match_pairs(&Matcher::all_pairs(self.len()))
    }

    /// [`DescriptorCollection::match_all_pairs`], each result handed to `each(i, matches)` as soon
    /// as it is ready (as [`DescriptorCollection::match_pairs_each`] does).
    pub fn match_all_pairs_each(&self, each: impl FnMut(usize, Vec<Match>)) -> Result<()> {
        self.match_pairs_each(&Matcher::all_pairs(self.len()), each)
    }

    /// The matches of `query` (the queries) against every held set (the galleries), in id order.
    /// `query` must have the collection's width.
    pub fn search(&self, query: &DescriptorSet) -> Result<Vec<Vec<Match>>> {
        collected(self.len(), |each| self.search_each(query, each))
    }

    /// [`DescriptorCollection::search`], the result of each set handed to `each(id, matches)` as soon
    /// as it is ready, in id order.
    pub fn search_each(
        &self,
        query: &DescriptorSet,
        each: impl FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        let ids: Vec<usize> = (0..self.len()).collect();
        self.search_sets_each(query, &ids, each)
    }

    /// The matches of `query` against the held sets `ids` (any order, repeats allowed), in the order
    /// of `ids`. The width and every id are checked before any work.
    pub fn search_sets(&self, query: &DescriptorSet, ids: &[usize]) -> Result<Vec<Vec<Match>>> {
        collected(ids.len(), |each| self.search_sets_each(query, ids, each))
    }

    /// [`DescriptorCollection::search_sets`], each result handed to `each(i, matches)` (for
    /// `ids[i]`, in increasing `i`) as soon as it is ready.
    pub fn search_sets_each(
        &self,
        query: &DescriptorSet,
        ids: &[usize],
        mut each: impl FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        self.check_width(query)?;
        for (i, &id) in ids.iter().enumerate() {
            self.check_id(i, id)?;
        }
        let config = self.matcher.config();
        match &self.store {
            Store::Host(held) => {
                in_host_blocks(ids, each, |&id| match_on_host(query, &held[id], config));
                Ok(())
            }
            Store::Device(device) => device.search(query, ids, config, &mut each),
        }
    }

    /// The device collection behind a CUDA collection (for the `internals` hooks).
    #[cfg(all(feature = "cuda", feature = "internals"))]
    pub(crate) fn device_store(&self) -> Option<&cuda::DeviceCollection> {
        match &self.store {
            Store::Device(device) => Some(device),
            Store::Host(_) => None,
        }
    }

    fn check_width(&self, set: &DescriptorSet) -> Result<()> {
        if set.width() != self.width {
            return Err(Error::DescriptorWidthMismatch {
                query_bits: set.width().bits(),
                train_bits: self.width.bits(),
            });
        }
        Ok(())
    }

    fn check_id(&self, pair: usize, index: usize) -> Result<()> {
        if index >= self.len() {
            return Err(Error::PairOutOfRange {
                pair,
                index,
                sets: self.len(),
            });
        }
        Ok(())
    }
}

/// The `n` results an `*_each` call hands over (in increasing index), collected in order.
fn collected(
    n: usize,
    run: impl FnOnce(&mut dyn FnMut(usize, Vec<Match>)) -> Result<()>,
) -> Result<Vec<Vec<Match>>> {
    let mut results = Vec::with_capacity(n);
    run(&mut |_, matches| results.push(matches))?;
    Ok(results)
}

/// One pair on the CPU, as [`Matcher::match_pairs`] treats it: no matches without queries or with
/// too small a gallery.
fn match_on_host(query: &DescriptorSet, train: &DescriptorSet, config: &MatchConfig) -> Vec<Match> {
    if !config.can_match(query.len(), train.len()) {
        return Vec::new();
    }
    matching::cpu::match_descriptors(query, train, config)
}

/// `matches(item)` of every item, `HOST_BLOCK` at a time over the CPU's threads, each block's
/// results handed to `each` in item order before the next block starts.
fn in_host_blocks<T: Sync>(
    items: &[T],
    mut each: impl FnMut(usize, Vec<Match>),
    matches: impl Fn(&T) -> Vec<Match> + Sync,
) {
    for (b, block) in items.chunks(HOST_BLOCK).enumerate() {
        let found: Vec<Vec<Match>> = block.par_iter().map(&matches).collect();
        for (i, m) in found.into_iter().enumerate() {
            each(b * HOST_BLOCK + i, m);
        }
    }
}
