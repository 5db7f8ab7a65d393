//! Descriptor sets kept on the device for a whole collection, and grouped matching over them:
//! `kernels/match_pairs.cu`, reproducing [`crate::matching::cpu::match_descriptors`] exactly, pair by
//! pair, ties included.
//!
//! Storage: one contiguous device buffer of rows; each set added starts at a multiple of
//! `CLATCH_PAIRS_ROW_ALIGN` rows (16-byte tile loads for every width) and `CLATCH_MATCH_ROW_PAD` zeroed
//! rows follow the last set, so a kernel may read a whole query block and a whole tile from any set's
//! start. A set crosses the bus once, when it is added; adding more grows the buffer by doubling
//! (device-to-device copy), never re-uploading.
//!
//! Matching: a pair list is cut into blocks of bounded scratch (`plan.rs`); each block is two launches
//! (the grouped kNN with the ratio test, distance limit and, for the cross-check, the fused reverse
//! 1-NN; then a per-pair compaction), whatever the number and sizes of its pairs (`grouped.rs`).
//! Exactness strategy: the kNN body is `kernels/knn.cuh`'s (integer popcounts, strict inserts in
//! increasing gallery index, reverse keys folded by atomic maxima), and each block scans its pair's
//! whole gallery, so no list is merged; the ratio test is the CPU's single `f32` product.

mod grouped;
mod plan;

use std::sync::{Arc, Mutex};

use cudarc::driver::{CudaSlice, CudaStream, CudaViewMut};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::{CLATCH_MATCH_ROW_PAD, CLATCH_PAIRS_ROW_ALIGN};
use super::kernels::{self, Kernel};
use super::matching_tensor::{self, MatchKernel};
use super::memory::alloc_zeros;
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::error::{Error, Result};
use crate::matching::{Match, MatchConfig};
use plan::{Budget, PairRows};

const ROW_ALIGN: usize = CLATCH_PAIRS_ROW_ALIGN as usize;
const ROW_PAD: usize = CLATCH_MATCH_ROW_PAD as usize;

/// The grouped tensor-core kNN kernel for sign rows of `bits` (64, 128, 256, 512) bytes.
fn tensor_kernel_name(bits: usize, k: usize, mutual: bool) -> Kernel {
    let slot = bits.trailing_zeros() as usize - 6;
    kernels::TENSOR_PAIRS_KNN[slot * 4 + 2 * mutual as usize + (k - 1)]
}

/// The grouped kNN kernel for rows of `words` words, `k` (1, or 2 with the ratio test), with the
/// reverse 1-NN when `mutual`.
fn kernel_name(words: usize, k: usize, mutual: bool) -> Kernel {
    kernels::PAIRS_KNN[(words - 1) * 4 + 2 * mutual as usize + (k - 1)]
}

/// Where one set lies in the buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Place {
    first_row: usize,
    rows: usize,
}

/// Descriptor sets of one width resident on one device, added once and matched many times.
pub(crate) struct DeviceCollection {
    dev: Arc<GpuDevice>,
    stream: Arc<CudaStream>,
    width: DescriptorWidth,
    /// Rows of every set, padded (see the module notes); `capacity_rows` rows.
    rows: CudaSlice<u64>,
    capacity_rows: usize,
    places: Vec<Place>,
    /// The first row after the last set, rounded up to `ROW_ALIGN`: where the next set goes.
    end_row: usize,
    /// The rows expanded to +-1 bytes for the tensor-core kernels (`capacity_rows` rows of the padded
    /// width): made on first use, dropped when sets are added. A run clones the `Arc` out and lets
    /// the lock go before it starts, so callbacks may match on this collection again and threads run
    /// side by side; a buffer dropped while a run holds it is freed with the run's last clone, queued
    /// on the collection's one stream after every launch that read it.
    signs: Mutex<Option<Arc<CudaSlice<u8>>>>,
    /// Scratch of grouped runs kept between them (see [`grouped::SlotCache`]).
    slots: grouped::SlotCache,
}

impl std::fmt::Debug for DeviceCollection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceCollection")
            .field("device", &self.dev.name())
            .field("width", &self.width)
            .field("sets", &self.places.len())
            .field("rows", &self.end_row)
            .finish()
    }
}

impl DeviceCollection {
    /// An empty collection of `width`-bit sets on `dev`, with a stream of its own.
    pub(crate) fn new(dev: Arc<GpuDevice>, width: DescriptorWidth) -> Result<Self> {
        let stream = dev.new_stream()?;
        let rows = alloc_zeros(&stream, ROW_PAD * width.words(), "descriptor collection")?;
        Ok(Self {
            dev,
            stream,
            width,
            rows,
            capacity_rows: ROW_PAD,
            places: Vec::new(),
            end_row: 0,
            signs: Mutex::new(None),
            slots: grouped::SlotCache::default(),
        })
    }

    /// Uploads `sets` (each of this collection's width, checked by the caller) after the ones held;
    /// they get the next ids.
    pub(crate) fn add(&mut self, sets: &[&DescriptorSet]) -> Result<()> {
        let words = self.width.words();
        let mut places = Vec::with_capacity(sets.len());
        let mut end = self.end_row;
        for set in sets {
            super::matching::check_rows(set, "collection descriptors")?;
            places.push(Place {
                first_row: end,
                rows: set.len(),
            });
            end = (end + set.len()).next_multiple_of(ROW_ALIGN);
        }
        let needed = end + ROW_PAD;
        if needed > self.capacity_rows {
            self.grow(needed.max(2 * self.capacity_rows))?;
        }
        // One copy of everything new, alignment gaps as zeros: the rows past `end` stay the zeros
        // the buffer was allocated with.
        let mut staged = vec![0u64; (end - self.end_row) * words];
        for (set, place) in sets.iter().zip(&places) {
            let at = (place.first_row - self.end_row) * words;
            staged[at..at + set.as_words().len()].copy_from_slice(set.as_words());
        }
        if !staged.is_empty() {
            let mut target = self.rows.slice_mut(self.end_row * words..end * words);
            self.stream
                .memcpy_htod(&staged, &mut target)
                .map_err(driver_error("uploading collection descriptors"))?;
        }
        self.places.extend(places);
        self.end_row = end;
        *self.signs.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        Ok(())
    }

    /// Adds a set of `rows` rows that work queued on `writer` (another stream of this device) puts in
    /// place: `fill(target)` queues that work on `writer`, `target` being the set's rows in this
    /// collection's buffer. The descriptors never cross the bus. Ordering, by events both ways:
    /// `writer` first waits for this collection's stream (the buffer may just have been allocated or
    /// grown there), and this collection's stream then waits for `writer`, so every later match, growth
    /// or free queued here runs after the rows are written.
    pub(crate) fn append_rows(
        &mut self,
        writer: &Arc<CudaStream>,
        rows: usize,
        fill: impl FnOnce(&mut CudaViewMut<'_, u64>) -> Result<()>,
    ) -> Result<()> {
        let words = self.width.words();
        let first = self.end_row;
        let end = (first + rows).next_multiple_of(ROW_ALIGN);
        if end + ROW_PAD > self.capacity_rows {
            self.grow((end + ROW_PAD).max(2 * self.capacity_rows))?;
        }
        let ready = self
            .stream
            .record_event(None)
            .map_err(driver_error("event record"))?;
        writer
            .wait(&ready)
            .map_err(driver_error("ordering a collection's writer"))?;
        let mut target = self.rows.slice_mut(first * words..(first + rows) * words);
        let filled = fill(&mut target);
        // The set's rows are this collection's from here, whatever `fill` did: this stream waits for
        // the writer before anything else touches the buffer.
        let written = writer
            .record_event(None)
            .map_err(driver_error("event record"))?;
        self.stream
            .wait(&written)
            .map_err(driver_error("ordering a collection's writer"))?;
        if let Err(e) = filled {
            // Rows past the last set must stay zero (the next set's alignment gap may lie there).
            let _ = self.stream.memset_zeros(&mut target);
            return Err(e);
        }
        self.places.push(Place {
            first_row: first,
            rows,
        });
        self.end_row = end;
        *self.signs.get_mut().unwrap_or_else(|p| p.into_inner()) = None;
        Ok(())
    }

    /// Moves the rows held into a zeroed buffer of `rows` rows.
    fn grow(&mut self, rows: usize) -> Result<()> {
        let words = self.width.words();
        let mut bigger = alloc_zeros::<u64>(&self.stream, rows * words, "descriptor collection")?;
        if self.end_row > 0 {
            self.stream
                .memcpy_dtod(
                    &self.rows.slice(..self.end_row * words),
                    &mut bigger.slice_mut(..self.end_row * words),
                )
                .map_err(driver_error("growing the descriptor collection"))?;
        }
        // The old buffer is freed in stream order, after the copy.
        self.rows = bigger;
        self.capacity_rows = rows;
        Ok(())
    }

    fn rows_of(&self, query: Place, train: Place) -> PairRows {
        PairRows {
            query_row: query.first_row,
            query_rows: query.rows,
            train_row: train.first_row,
            train_rows: train.rows,
        }
    }

    /// Matches `pairs` of held sets (ids in range, checked by the caller) with `config`, as
    /// `match_descriptors(set a, set b)` for each `(a, b)`, a pair without queries or with too small a
    /// gallery getting none; `each(p, matches)` for every pair `p`, in order, as blocks complete.
    pub(crate) fn match_pairs(
        &self,
        pairs: &[(usize, usize)],
        config: &MatchConfig,
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        self.match_pairs_within(pairs, config, (Budget::DEFAULT, None), each)
    }

    /// [`DeviceCollection::match_pairs`] with blocks of at most `budget`, on the kernel family asked
    /// for (the device's choice when `None`).
    pub(crate) fn match_pairs_within(
        &self,
        pairs: &[(usize, usize)],
        config: &MatchConfig,
        (budget, family): (Budget, Option<MatchKernel>),
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        let places = pairs
            .iter()
            .map(|&(a, b)| {
                let (query, train) = (self.place(a)?, self.place(b)?);
                Ok(config
                    .can_match(query.rows, train.rows)
                    .then(|| self.rows_of(query, train)))
            })
            .collect::<Result<Vec<_>>>()?;
        self.run(None, &places, config, (budget, family), each)
    }

    /// Matches `query` (this collection's width, checked by the caller) against each held set of
    /// `ids` (in range), uploading it once; `each(i, matches)` for every `ids[i]`, in order.
    pub(crate) fn search(
        &self,
        query: &DescriptorSet,
        ids: &[usize],
        config: &MatchConfig,
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        self.search_within(query, ids, config, (Budget::DEFAULT, None), each)
    }

    /// [`DeviceCollection::search`] with blocks of at most `budget`, on the kernel family asked for.
    pub(crate) fn search_within(
        &self,
        query: &DescriptorSet,
        ids: &[usize],
        config: &MatchConfig,
        (budget, family): (Budget, Option<MatchKernel>),
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        super::matching::check_rows(query, "query descriptors")?;
        let words = self.width.words();
        let padded = query.len().next_multiple_of(ROW_ALIGN) + ROW_PAD;
        let mut buffer = alloc_zeros::<u64>(&self.stream, padded * words, "query descriptors")?;
        if !query.is_empty() {
            self.stream
                .memcpy_htod(
                    query.as_words(),
                    &mut buffer.slice_mut(..query.as_words().len()),
                )
                .map_err(driver_error("query descriptor upload"))?;
        }
        let query_place = Place {
            first_row: 0,
            rows: query.len(),
        };
        let places = ids
            .iter()
            .map(|&id| {
                let train = self.place(id)?;
                Ok(config
                    .can_match(query.len(), train.rows)
                    .then(|| self.rows_of(query_place, train)))
            })
            .collect::<Result<Vec<_>>>()?;
        self.run(Some(&buffer), &places, config, (budget, family), each)
    }

    /// Runs `places` with queries from `query` (a padded buffer of its own) or, when `None`, from the
    /// collection itself.
    fn run(
        &self,
        query: Option<&CudaSlice<u64>>,
        places: &[Option<PairRows>],
        config: &MatchConfig,
        (budget, family): (Budget, Option<MatchKernel>),
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        let k = config.neighbours_needed();
        let family = match family {
            Some(f) => self.dev.check_match_kernel(f, k)?,
            None => self.dev.match_kernel(k),
        };
        let words = self.width.words();
        let mut run = grouped::Run {
            dev: &self.dev,
            stream: &self.stream,
            query: query.unwrap_or(&self.rows),
            train: &self.rows,
            words,
            config,
            tensor: None,
            slots: &self.slots,
        };
        if family == MatchKernel::Popcount {
            return run.all(places, budget, each);
        }
        let bits = matching_tensor::padded_bits(words);
        let train_signs = self.signs()?;
        let train = &*train_signs;
        let query_signs = match query {
            Some(q) => Some(self.expand(q, q.len() / words)?),
            None => None,
        };
        run.tensor = Some(grouped::SignRows {
            query: query_signs.as_ref().unwrap_or(train),
            train,
            bits,
            kernel: tensor_kernel_name(bits, k, config.cross_check),
        });
        run.all(places, budget, each)
    }

    /// The rows expanded to +-1 bytes (made now if they are not yet), shared: the lock is held only
    /// while they are looked up or queued for expansion, never while they are used.
    fn signs(&self) -> Result<Arc<CudaSlice<u8>>> {
        let mut signs = self.signs.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(signs) = &*signs {
            return Ok(signs.clone());
        }
        let made = Arc::new(self.expand(&self.rows, self.capacity_rows)?);
        *signs = Some(made.clone());
        Ok(made)
    }

    /// `rows` rows of `buffer` expanded to +-1 bytes of the padded width, on the collection's stream.
    fn expand(&self, buffer: &CudaSlice<u64>, rows: usize) -> Result<CudaSlice<u8>> {
        let (words, bits) = (
            self.width.words(),
            matching_tensor::padded_bits(self.width.words()),
        );
        let mut signs = alloc_zeros::<u8>(&self.stream, rows * bits, "expanded collection rows")?;
        matching_tensor::expand(
            &self.dev,
            &self.stream,
            buffer,
            words as u32,
            bits,
            &mut signs,
        )?;
        Ok(signs)
    }

    fn place(&self, id: usize) -> Result<Place> {
        self.places.get(id).copied().ok_or_else(|| Error::Internal {
            operation: "descriptor collection",
            message: format!("set {id} of {} (ids are checked before)", self.places.len()),
        })
    }
}

#[cfg(feature = "internals")]
pub mod hooks;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_names_follow_width_k_and_cross_check() {
        for words in 1..=8 {
            for k in 1..=2 {
                assert_eq!(
                    kernel_name(words, k, false).name(),
                    format!("clatch_pairs_knn_w{words}_k{k}")
                );
                assert_eq!(
                    kernel_name(words, k, true).name(),
                    format!("clatch_pairs_knn_mutual_w{words}_k{k}")
                );
            }
        }
        assert_eq!(kernels::PAIRS_KNN.len(), 8 * 4);
        for bits in [64, 128, 256, 512] {
            for k in 1..=2 {
                assert_eq!(
                    tensor_kernel_name(bits, k, false).name(),
                    format!("clatch_knn_tensor_pairs_b{bits}_k{k}")
                );
                assert_eq!(
                    tensor_kernel_name(bits, k, true).name(),
                    format!("clatch_knn_tensor_pairs_mutual_b{bits}_k{k}")
                );
            }
        }
    }

    #[test]
    fn padding_covers_a_query_block_and_a_tile() {
        use crate::cuda::header::{CLATCH_MATCH_TILE, CLATCH_PAIRS_BLOCK_QUERIES};
        assert!(ROW_PAD >= CLATCH_PAIRS_BLOCK_QUERIES as usize);
        assert!(ROW_PAD >= CLATCH_MATCH_TILE as usize);
        assert!(ROW_ALIGN.is_multiple_of(2), "16-byte loads for odd widths");
        assert_eq!(
            CLATCH_PAIRS_BLOCK_QUERIES,
            crate::cuda::header::CLATCH_MATCH_THREADS
                * crate::cuda::header::CLATCH_MATCH_QUERIES_PER_THREAD
        );
    }
}
