//! One grouped run: blocks of pairs through `kernels/match_pairs.cu`, two blocks in flight, each
//! block's results handed on in pair order as soon as it is back.
//!
//! Everything runs on the collection's one stream, so no buffer crosses streams (the device disables
//! cudarc's event tracking on that promise). Two slots of scratch alternate: block `b + 1` is queued
//! before the host waits for block `b`, so the device moves on to the next launch while the host splits
//! the last one's matches; the uploads and the copies back go through page-locked buffers (true
//! asynchronous DMA). With event tracking off, cudarc never records the events of those buffers, so
//! their `as_slice`/`as_mut_slice` and drop do not wait for anything: each slot records events of its
//! own (`uploaded` after its uploads, `landed` after its copies back) and waits on them before the host
//! writes or reads the buffers, and its drop waits for the stream before they are freed.

use std::collections::VecDeque;
use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex};

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, DeviceRepr, LaunchConfig, PinnedHostSlice, PushKernelArg,
    ValidAsZeroBits,
};

use super::kernel_name;
use super::plan::{Block, Budget, PairRows, blocks};
use crate::cuda::device::GpuDevice;
use crate::cuda::error::driver_error;
use crate::cuda::header::{
    CLATCH_MATCH_SELECT_THREADS, CLATCH_MATCH_THREADS, CLATCH_TENSOR_WARPS, clatch_pair,
    clatch_pair_task,
};
use crate::cuda::kernels::{self, Kernel};
use crate::cuda::matching_tensor;
use crate::cuda::memory::{alloc_pinned, alloc_zeros};
use crate::error::Result;
use crate::matching::{Match, MatchConfig};

// SAFETY: clatch_pair is bindgen's #[repr(C)] copy of the C struct: four u64 and two u32, no padding
// the kernel reads, no pointers; all-zero bits are a valid value.
unsafe impl DeviceRepr for clatch_pair {}
// SAFETY: as above.
unsafe impl ValidAsZeroBits for clatch_pair {}
// SAFETY: clatch_pair_task is #[repr(C)] with two u32; all-zero bits are valid.
unsafe impl DeviceRepr for clatch_pair_task {}
// SAFETY: as above.
unsafe impl ValidAsZeroBits for clatch_pair_task {}

/// Most tasks of one grouped kNN launch: one block each (grid x), as the tensor-core kernels need
/// (the popcount ones would take more grid-stride). A block within the budget has far fewer.
const MAX_TASKS: usize = i32::MAX as usize;
/// Most blocks of the compaction (grid x); more pairs are taken grid-stride.
const MAX_COMPACT_GRID: usize = 65_535;

/// The sizes one slot is allocated for: the largest block of the run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Capacity {
    pairs: usize,
    tasks: usize,
    query_rows: usize,
    train_rows: usize,
}

impl Capacity {
    /// Whether buffers of this capacity hold those of `other`.
    fn covers(&self, other: &Self) -> bool {
        self.pairs >= other.pairs
            && self.tasks >= other.tasks
            && self.query_rows >= other.query_rows
            && self.train_rows >= other.train_rows
    }

    fn of(blocks: &[Block]) -> Self {
        blocks.iter().fold(Self::default(), |c, b| Self {
            pairs: c.pairs.max(b.device.len()),
            tasks: c.tasks.max(b.tasks),
            query_rows: c.query_rows.max(b.query_rows),
            train_rows: c.train_rows.max(b.train_rows),
        })
    }
}

/// Page-locked host memory of `len` (at least one) zeroed elements, read back without write-combining
/// (through the crate's one pinned allocation site: failure injection and the allocation counter).
fn pinned<T: DeviceRepr + ValidAsZeroBits + Copy>(
    stream: &Arc<CudaStream>,
    len: usize,
    zero: T,
) -> Result<PinnedHostSlice<T>> {
    let operation = "pinned buffers of grouped matching";
    let mut buffer = alloc_pinned::<T>(stream, len, false, operation)?;
    // Zeroed before anything reads it.
    buffer
        .as_mut_slice()
        .map_err(driver_error(operation))?
        .fill(zero);
    Ok(buffer)
}

/// The page-locked buffers of one slot: the records uploaded and the results copied back.
struct Pinned {
    pairs: PinnedHostSlice<clatch_pair>,
    tasks: PinnedHostSlice<clatch_pair_task>,
    kept: PinnedHostSlice<Match>,
    counts: PinnedHostSlice<u32>,
}

/// The scratch of one block in flight, on the device and in pinned host memory.
struct Slot {
    capacity: Capacity,
    stream: Arc<CudaStream>,
    pairs: CudaSlice<clatch_pair>,
    tasks: CudaSlice<clatch_pair_task>,
    best: CudaSlice<Match>,
    kept: CudaSlice<Match>,
    reverse: CudaSlice<u64>,
    counts: CudaSlice<u32>,
    /// Freed by `Slot`'s drop only once no copy from or into them can be pending (never otherwise).
    host: ManuallyDrop<Pinned>,
    /// Recorded after the uploads from `host.pairs` and `host.tasks`.
    uploaded: CudaEvent,
    /// Recorded after the copies back into `host.counts` and `host.kept`.
    landed: CudaEvent,
    /// Copies on the pinned buffers may be queued that no wait has covered: set before a block's
    /// first copy is queued, cleared once `finish` has waited for its copies back.
    in_flight: bool,
}

impl Drop for Slot {
    fn drop(&mut self) {
        // A slot dropped between `queue` and `finish` (an error, or a panic in a callback) may have
        // copies queued on its pinned buffers, and their own drop would free them at once (cudarc
        // records no events for them with tracking off). `queue` may have failed part way, after a
        // copy and before its event, so wait for the whole stream, not the slot's events.
        let idle = !self.in_flight || self.stream.synchronize().is_ok();
        if idle {
            // SAFETY: dropped once, here, with no copy queued on the buffers any more.
            unsafe { ManuallyDrop::drop(&mut self.host) };
        }
        // Otherwise the wait failed (the context is broken, and a DMA may still be pending): the
        // page-locked memory is leaked rather than freed under it.
    }
}

/// Slots kept by a collection between its runs: a run takes those whose capacity covers its largest
/// block and gives them back when it has handed every block on, so a steady state of runs (a pool
/// worker's blocks, a gallery's searches) allocates no device or page-locked memory. A run that
/// finds none (the first, a larger one, or one started from another's callback) makes its own.
#[derive(Default)]
pub(super) struct SlotCache(Mutex<Vec<Slot>>);

impl SlotCache {
    /// Most slots kept: a run uses two.
    const KEPT: usize = 2;

    fn take(&self, needed: Capacity) -> Option<Slot> {
        let mut kept = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let i = kept.iter().position(|s| s.capacity.covers(&needed))?;
        Some(kept.swap_remove(i))
    }

    /// Keeps `slot` (no copy pending on it: its block was handed on), the largest ones first.
    fn give(&self, slot: Slot) {
        if slot.in_flight {
            return;
        }
        let mut kept = self.0.lock().unwrap_or_else(|p| p.into_inner());
        kept.push(slot);
        kept.sort_by_key(|s| std::cmp::Reverse(s.capacity.query_rows));
        kept.truncate(Self::KEPT);
    }
}

impl std::fmt::Debug for SlotCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kept = self.0.lock().map_or(0, |k| k.len());
        f.debug_struct("SlotCache").field("kept", &kept).finish()
    }
}

const NO_MATCH: Match = Match {
    query: 0,
    train: 0,
    distance: 0,
};

impl Slot {
    fn new(dev: &GpuDevice, stream: &Arc<CudaStream>, capacity: Capacity) -> Result<Self> {
        // The pinned record buffers and their device twins have the same length: the uploads copy
        // whole buffers.
        let (pairs_len, tasks_len) = (capacity.pairs.max(1), capacity.tasks.max(1));
        let (uploaded, landed) = (dev.new_event()?, dev.new_event()?);
        // Made before the slot: a failure below drops them with no copy queued on them (once in the
        // slot, only the slot's drop frees them).
        let host = Pinned {
            pairs: pinned(stream, pairs_len, clatch_pair::default())?,
            tasks: pinned(stream, tasks_len, clatch_pair_task::default())?,
            kept: pinned(stream, capacity.query_rows, NO_MATCH)?,
            counts: pinned(stream, capacity.pairs, 0u32)?,
        };
        Ok(Self {
            stream: stream.clone(),
            pairs: alloc_zeros(stream, pairs_len, "grouped matching pair records")?,
            tasks: alloc_zeros(stream, tasks_len, "grouped matching task list")?,
            best: alloc_zeros(stream, capacity.query_rows, "grouped matching best matches")?,
            kept: alloc_zeros(stream, capacity.query_rows, "grouped matching kept matches")?,
            reverse: alloc_zeros(stream, capacity.train_rows, "grouped matching reverse keys")?,
            counts: alloc_zeros(stream, capacity.pairs, "grouped matching counts")?,
            host: ManuallyDrop::new(host),
            uploaded,
            landed,
            in_flight: false,
            capacity,
        })
    }

    /// Queues `block`'s launches and the copies of its results into the pinned buffers.
    fn queue(&mut self, run: &Run<'_>, block: &Block) -> Result<()> {
        let (pairs, tasks) = block.layout();
        crate::cuda::invariant(
            pairs.len() <= self.capacity.pairs
                && tasks.len() <= MAX_TASKS
                && tasks.len() <= self.capacity.tasks
                && block.query_rows <= self.capacity.query_rows
                && block.train_rows <= self.capacity.train_rows,
            "grouped matching",
            || {
                format!(
                    "block {block:?} over the slot's capacity {:?}",
                    self.capacity
                )
            },
        )?;
        let stream = run.stream;
        let copy = driver_error("uploading the pair records of grouped matching");
        // The last uploads from these buffers (two blocks ago) must have read them; as_mut_slice does
        // not wait (see the module notes).
        self.uploaded.synchronize().map_err(&copy)?;
        self.in_flight = true;
        let host = &mut *self.host;
        host.pairs.as_mut_slice().map_err(&copy)?[..pairs.len()].copy_from_slice(&pairs);
        host.tasks.as_mut_slice().map_err(&copy)?[..tasks.len()].copy_from_slice(&tasks);
        stream
            .memcpy_htod(&host.pairs, &mut self.pairs)
            .map_err(&copy)?;
        stream
            .memcpy_htod(&host.tasks, &mut self.tasks)
            .map_err(&copy)?;
        self.uploaded.record(stream).map_err(&copy)?;
        if run.config.cross_check {
            // The reverse keys are folded in with atomics: start from zero (no candidate).
            stream
                .memset_zeros(&mut self.reverse.slice_mut(..block.train_rows))
                .map_err(driver_error(
                    "clearing the reverse keys of grouped matching",
                ))?;
        }

        let k = run.config.neighbours_needed();
        let n_tasks = tasks.len() as u32;
        let use_ratio = run.config.ratio.is_some() as i32;
        let ratio = run.config.ratio.unwrap_or(0.0);
        let use_max = run.config.max_distance.is_some() as i32;
        let max_distance = run.config.max_distance.unwrap_or(u32::MAX);
        let (kernel, threads, shared) = match &run.tensor {
            Some(signs) => (
                signs.kernel,
                CLATCH_TENSOR_WARPS * 32,
                matching_tensor::shared_bytes(signs.bits) as u32,
            ),
            None => (
                kernel_name(run.words, k, run.config.cross_check),
                CLATCH_MATCH_THREADS,
                0,
            ),
        };
        let mut launch = stream.launch_builder(run.dev.kernel(kernel));
        match &run.tensor {
            Some(signs) => launch.arg(signs.query).arg(signs.train),
            None => launch.arg(run.query).arg(run.train),
        };
        launch
            .arg(&self.pairs)
            .arg(&self.tasks)
            .arg(&n_tasks)
            .arg(&use_ratio)
            .arg(&ratio)
            .arg(&use_max)
            .arg(&max_distance)
            .arg(&mut self.best)
            .arg(&mut self.reverse);
        let config = LaunchConfig {
            grid_dim: (tasks.len().max(1) as u32, 1, 1),
            block_dim: (threads, 1, 1),
            shared_mem_bytes: shared,
        };
        // SAFETY: the arguments match the signature of clatch_pairs_knn_* (rows of `run.words` words)
        // or, with `run.tensor`, of clatch_knn_tensor_pairs_* (sign rows of `bits` bytes, the dynamic
        // shared memory its stages need, allowed at load by `matching_tensor::configure`). Every pair
        // record was checked against the buffers it is read from by `Run::check` (its rows, and a
        // whole query block and tile past them, lie inside them); `pairs` holds the block's records and
        // `tasks` its n_tasks tasks (one block each: the grid is n_tasks blocks, at most MAX_TASKS),
        // each naming a pair of the block and one of its query blocks;
        // `best` holds the block's query_rows records and `reverse` its train_rows keys (best_row and
        // reverse_row pack them, see `Block::layout`), both within this slot's capacity (checked above).
        // With k = 2 every pair has two gallery rows or more (`Run::check`).
        unsafe { launch.launch(config) }.map_err(driver_error(kernel.name()))?;

        let n_pairs = pairs.len() as u32;
        let cross_check = run.config.cross_check as i32;
        let mut launch = stream.launch_builder(run.dev.kernel(kernels::PAIRS_COMPACT));
        launch
            .arg(&self.pairs)
            .arg(&n_pairs)
            .arg(&self.best)
            .arg(&cross_check)
            .arg(&self.reverse)
            .arg(&mut self.kept)
            .arg(&mut self.counts);
        let config = LaunchConfig {
            grid_dim: (pairs.len().clamp(1, MAX_COMPACT_GRID) as u32, 1, 1),
            block_dim: (CLATCH_MATCH_SELECT_THREADS, 1, 1),
            shared_mem_bytes: 0,
        };
        // SAFETY: as above; `best` was written for every query of every pair by the kNN launch queued
        // before on this stream, `reverse` (read with the cross-check only) for every gallery row, at
        // train indices below each pair's train_rows; `kept` has room for every pair's queries at its
        // best_row and `counts` one word per pair.
        unsafe { launch.launch(config) }.map_err(driver_error("clatch_pairs_compact"))?;

        let back = driver_error("copying the matches of grouped matching back");
        let host = &mut *self.host;
        stream
            .memcpy_dtoh(&self.counts.slice(..pairs.len()), &mut host.counts)
            .map_err(&back)?;
        stream
            .memcpy_dtoh(&self.kept.slice(..block.query_rows), &mut host.kept)
            .map_err(&back)?;
        self.landed.record(stream).map_err(&back)?;
        Ok(())
    }

    /// Waits for `block`'s copies and hands each of its pairs' matches to `each`, in pair order.
    fn finish(&mut self, block: &Block, each: &mut dyn FnMut(usize, Vec<Match>)) -> Result<()> {
        let wait = driver_error("grouped matching (running, or copying matches back)");
        // as_slice does not wait (see the module notes): `landed` follows the copies back, and the
        // uploads before them, in stream order.
        self.landed.synchronize().map_err(&wait)?;
        self.in_flight = false;
        let counts = self.host.counts.as_slice().map_err(&wait)?;
        let kept = self.host.kept.as_slice().map_err(&wait)?;
        let mut device = block.device.iter().enumerate().peekable();
        let mut best_row = 0;
        for index in block.range.clone() {
            let Some((p, &(_, rows))) = device.next_if(|(_, (i, _))| *i == index) else {
                each(index, Vec::new());
                continue;
            };
            let count = counts[p] as usize;
            crate::cuda::invariant(count <= rows.query_rows, "grouped matching", || {
                format!("{count} kept matches of {} queries", rows.query_rows)
            })?;
            each(index, kept[best_row..best_row + count].to_vec());
            best_row += rows.query_rows;
        }
        Ok(())
    }
}

/// The rows as +-1 bytes for the tensor-core kernels: rows of `bits` bytes, in the same row order as
/// the bit buffers.
pub(super) struct SignRows<'a> {
    pub(super) query: &'a CudaSlice<u8>,
    pub(super) train: &'a CudaSlice<u8>,
    pub(super) bits: usize,
    /// The `clatch_knn_tensor_pairs_*` kernel for this width, k and cross-check.
    pub(super) kernel: Kernel,
}

/// What every block of one run shares.
pub(super) struct Run<'a> {
    pub(super) dev: &'a GpuDevice,
    pub(super) stream: &'a Arc<CudaStream>,
    /// Query and gallery buffers (the same one for pairs among a collection's sets), `words` 64-bit
    /// words per row.
    pub(super) query: &'a CudaSlice<u64>,
    pub(super) train: &'a CudaSlice<u64>,
    pub(super) words: usize,
    pub(super) config: &'a MatchConfig,
    /// The tensor-core kernels run instead of the popcount ones when set.
    pub(super) tensor: Option<SignRows<'a>>,
    /// Where the run's slots come from and go back to.
    pub(super) slots: &'a SlotCache,
}

impl Run<'_> {
    /// Checks that a pair's rows, plus the whole query block and tile the kernel may read past them,
    /// lie in the buffers, and that it has the rows its kernel needs.
    fn check(&self, rows: &PairRows) -> Result<()> {
        use crate::cuda::header::{CLATCH_MATCH_ROW_PAD, CLATCH_PAIRS_ROW_ALIGN};
        let pad = CLATCH_MATCH_ROW_PAD as usize;
        let align = CLATCH_PAIRS_ROW_ALIGN as usize;
        let inside = |row: usize, n: usize, len: usize, per_row: usize| {
            row.is_multiple_of(align) && (row + n + pad) * per_row <= len
        };
        let in_signs = self.tensor.as_ref().is_none_or(|s| {
            inside(rows.query_row, rows.query_rows, s.query.len(), s.bits)
                && inside(rows.train_row, rows.train_rows, s.train.len(), s.bits)
        });
        crate::cuda::invariant(
            self.config.can_match(rows.query_rows, rows.train_rows)
                && rows.query_rows <= u32::MAX as usize
                && rows.train_rows <= u32::MAX as usize
                && inside(
                    rows.query_row,
                    rows.query_rows,
                    self.query.len(),
                    self.words,
                )
                && inside(
                    rows.train_row,
                    rows.train_rows,
                    self.train.len(),
                    self.words,
                )
                && in_signs,
            "grouped matching",
            || {
                format!(
                    "pair {rows:?} against buffers of {} and {} words ({} per row)",
                    self.query.len(),
                    self.train.len(),
                    self.words
                )
            },
        )
    }

    /// Matches every pair of `places` (`None`: no device work, no matches), `budget` bounding each
    /// block; `each(i, matches)` for every input pair `i`, in order.
    pub(super) fn all(
        &self,
        places: &[Option<PairRows>],
        budget: Budget,
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        for rows in places.iter().flatten() {
            self.check(rows)?;
        }
        let blocks = blocks(places, budget);
        let capacity = Capacity::of(&blocks);
        let mut slots: [Option<Slot>; 2] = [None, None];
        // (block, slot) of the blocks queued and not yet handed on, oldest first; slot None: no
        // device work.
        let mut queued: VecDeque<(usize, Option<usize>)> = VecDeque::new();
        for (b, block) in blocks.iter().enumerate() {
            if queued.len() == 2 {
                let (oldest, slot) = queued.pop_front().expect("two queued");
                hand_on(&blocks[oldest], slot, &mut slots, each)?;
            }
            if block.device.is_empty() {
                queued.push_back((b, None));
                continue;
            }
            // The block two before this one, which used this slot, has been handed on just above.
            let s = b % 2;
            let slot = match &mut slots[s] {
                Some(slot) => slot,
                empty => empty.insert(match self.slots.take(capacity) {
                    Some(kept) => kept,
                    None => Slot::new(self.dev, self.stream, capacity)?,
                }),
            };
            slot.queue(self, block)?;
            queued.push_back((b, Some(s)));
        }
        while let Some((oldest, slot)) = queued.pop_front() {
            hand_on(&blocks[oldest], slot, &mut slots, each)?;
        }
        for slot in slots.into_iter().flatten() {
            self.slots.give(slot);
        }
        Ok(())
    }
}

/// Hands on `block`'s results: from `slots[slot]` where it ran on the device, else none for each pair.
fn hand_on(
    block: &Block,
    slot: Option<usize>,
    slots: &mut [Option<Slot>; 2],
    each: &mut dyn FnMut(usize, Vec<Match>),
) -> Result<()> {
    let Some(s) = slot else {
        block.range.clone().for_each(|i| each(i, Vec::new()));
        return Ok(());
    };
    let slot = slots[s].as_mut().ok_or_else(|| crate::Error::Internal {
        operation: "grouped matching",
        message: format!("block {:?} has no slot", block.range),
    })?;
    slot.finish(block, each)
}
