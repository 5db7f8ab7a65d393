//! GPU matching: `kernels/matching.cu` (with `kernels/knn.cuh`), reproducing [`crate::matching::cpu::knn`]
//! and [`crate::matching::cpu::match_descriptors`] exactly, ties included.
//!
//! Exactness strategy: distances are integer popcounts; each kNN thread scans its gallery segment in
//! increasing index order and inserts only on a strictly smaller distance, and segment lists are merged
//! by `(distance, index)`, which is the CPU's order. The ratio test is the same single `f32` product
//! (`__fmul_rn`, nothing contracted). The kept matches are compacted on the device by an exclusive scan,
//! so they come back in query order.
//!
//! One call = one stream of our own: upload both sets (zero-padded to whole tiles), kNN (fused with the
//! reverse 1-NN when cross-checking), filter, scan, compact, then copy back the count and the kept
//! matches. No host round trip sits between the kernels.

use std::sync::Arc;

use cudarc::driver::{
    CudaSlice, CudaStream, DeviceRepr, LaunchConfig, PushKernelArg, ValidAsZeroBits,
};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::{
    CLATCH_MATCH_QUERIES_PER_THREAD, CLATCH_MATCH_ROW_PAD, CLATCH_MATCH_SCAN_THREADS,
    CLATCH_MATCH_SELECT_THREADS, CLATCH_MATCH_THREADS, CLATCH_MATCH_TILE,
};
use super::kernels::{self, Kernel};
use super::matching_tensor::{MatchKernel, TensorKnn};
use super::memory::alloc_zeros;
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::matching::{KnnMatches, Match, MatchConfig};

// SAFETY: Match is #[repr(C)] plain old data (three u32) with the layout of clatch_match (checked in
// tests); all-zero bits are a valid Match.
unsafe impl DeviceRepr for Match {}
// SAFETY: as above.
unsafe impl ValidAsZeroBits for Match {}

pub use crate::matching::GPU_MAX_K as MAX_K;

/// List lengths the kNN kernels are compiled for; `k` is rounded up to one of them. The kernels with
/// the fused reverse 1-NN (cross-check) exist for the first two.
const LIST_LENGTHS: [usize; 4] = [1, 2, 4, 8];
/// kNN kernels per descriptor width: one per list length, then the two with the reverse 1-NN.
const KERNELS_PER_WIDTH: usize = 6;

/// The kNN kernel for rows of `words` 64-bit words and `k` neighbours, with the reverse 1-NN of the
/// cross-check when `mutual` (then `k` is 1 or 2).
fn knn_kernel(words: usize, k: usize, mutual: bool) -> Kernel {
    let slot = LIST_LENGTHS
        .iter()
        .position(|&len| len >= k)
        .expect("k checked against MAX_K");
    let slot = if mutual { 4 + slot } else { slot };
    kernels::KNN[(words - 1) * KERNELS_PER_WIDTH + slot]
}

const THREADS: usize = CLATCH_MATCH_THREADS as usize;
const TILE: usize = CLATCH_MATCH_TILE as usize;
const ROW_PAD: usize = CLATCH_MATCH_ROW_PAD as usize;
const SELECT_THREADS: usize = CLATCH_MATCH_SELECT_THREADS as usize;
/// Blocks per multiprocessor the kNN grid aims at (several waves, so the last one is short).
const TARGET_BLOCKS_PER_SM: usize = 16;
/// Fewest tiles per gallery segment, so the prefetch pipeline has something to overlap.
const MIN_SEGMENT_TILES: usize = 2;
/// Most gallery segments (grid y).
const MAX_SEGMENTS: usize = 65_535;
/// Largest set the u32 indices of the kernels (and of [`Match`]) can address, padding included.
const MAX_ROWS: usize = u32::MAX as usize - ROW_PAD;

/// Checks that the GPU matcher can return `k` neighbours.
fn check_k(k: usize) -> Result<()> {
    if k > MAX_K {
        return Err(Error::KTooLargeForBackend {
            k,
            max: MAX_K,
            backend: "cuda".into(),
        });
    }
    Ok(())
}

pub(crate) fn check_rows(set: &DescriptorSet, what: &'static str) -> Result<()> {
    if set.len() > MAX_ROWS {
        return Err(Error::InvalidInput {
            what,
            reason: format!(
                "{} descriptors; the CUDA matcher indexes descriptors with u32: at most \
                 2^32 - 257 per set",
                set.len()
            ),
        });
    }
    Ok(())
}

/// Uploads a set's rows into a zeroed buffer of a whole number of `ROW_PAD` rows.
fn upload(stream: &Arc<CudaStream>, set: &DescriptorSet, what: &str) -> Result<CudaSlice<u64>> {
    let rows = set.len().div_ceil(ROW_PAD).max(1) * ROW_PAD;
    let mut buffer = alloc_zeros::<u64>(stream, rows * set.width().words(), what)?;
    stream
        .memcpy_htod(set.as_words(), &mut buffer)
        .map_err(driver_error(what))?;
    Ok(buffer)
}

/// How one kNN is cut into blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Geometry {
    query_blocks: usize,
    /// Gallery rows per segment, a multiple of TILE.
    segment: usize,
    segments: usize,
}

impl Geometry {
    /// Enough blocks to fill the device several times over: queries in blocks of `THREADS * qpt`,
    /// the gallery cut into segments (grid y) when there are too few query blocks.
    /// `segment_tiles` forces the segment length (tests).
    fn new(
        dev: &GpuDevice,
        nq: usize,
        nt: usize,
        qpt: usize,
        segment_tiles: Option<usize>,
    ) -> Self {
        let query_blocks = nq.div_ceil(THREADS * qpt);
        let tiles = nt.div_ceil(TILE);
        let target = dev.multiprocessors.max(1) * TARGET_BLOCKS_PER_SM;
        let segments_wanted = target.div_ceil(query_blocks).max(1);
        let segment_tiles = segment_tiles
            .unwrap_or_else(|| tiles.div_ceil(segments_wanted).max(MIN_SEGMENT_TILES))
            .max(tiles.div_ceil(MAX_SEGMENTS))
            .clamp(1, tiles);
        Self {
            query_blocks,
            segment: segment_tiles * TILE,
            segments: tiles.div_ceil(segment_tiles),
        }
    }
}

/// One kNN on the device: kernel choice, geometry, the per-segment scratch buffer and, for the
/// cross-check, the reverse 1-NN keys.
struct KnnRun {
    kernel: Kernel,
    geometry: Geometry,
    nq: u32,
    nt: u32,
    k: u32,
    partial: CudaSlice<u64>,
    /// Whether the kernel also computes the reverse 1-NN (a `clatch_knn_mutual_*` kernel).
    mutual: bool,
    /// Per gallery descriptor, `!(distance << 32 | query)` of its nearest query (one unused element
    /// unless `mutual`).
    reverse: CudaSlice<u64>,
    /// The tensor-core kernels run this kNN instead of `kernel` (see `matching_tensor.rs`).
    tensor: Option<TensorKnn>,
}

impl KnnRun {
    /// Plans the production kernel for `nq` queries against `nt` gallery rows of `words` words;
    /// `mutual` (k = 1 or 2) also computes the nearest query of every gallery row.
    /// `family` picks the kernels (the device's choice for `k` when `None`).
    fn new(
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        (nq, nt, words): (usize, usize, usize),
        (k, mutual): (usize, bool),
        family: Option<MatchKernel>,
        segment_tiles: Option<usize>,
    ) -> Result<Self> {
        let family = match family {
            Some(f) => dev.check_match_kernel(f, k)?,
            None => dev.match_kernel(k),
        };
        let kernel = knn_kernel(words, k, mutual);
        let qpt = CLATCH_MATCH_QUERIES_PER_THREAD as usize;
        let mut run = Self::with_kernel(dev, stream, kernel, qpt, (nq, nt), k, segment_tiles)?;
        if mutual {
            run.mutual = true;
            run.reverse = alloc_zeros(stream, nt, "reverse 1-NN keys")?;
        }
        if family == MatchKernel::Tensor {
            let shape = (nq, nt, words);
            run.tensor = Some(TensorKnn::new(
                dev,
                stream,
                shape,
                k,
                mutual,
                segment_tiles,
            )?);
        }
        Ok(run)
    }

    fn with_kernel(
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        kernel: Kernel,
        qpt: usize,
        (nq, nt): (usize, usize),
        k: usize,
        segment_tiles: Option<usize>,
    ) -> Result<Self> {
        let geometry = Geometry::new(dev, nq, nt, qpt, segment_tiles);
        let partial_len = if geometry.segments > 1 {
            geometry.segments.saturating_mul(nq).saturating_mul(k)
        } else {
            1
        };
        Ok(Self {
            kernel,
            geometry,
            nq: nq as u32,
            nt: nt as u32,
            k: k as u32,
            partial: alloc_zeros(stream, partial_len, "kNN segment lists")?,
            mutual: false,
            reverse: alloc_zeros(stream, 1, "kNN placeholder")?,
            tensor: None,
        })
    }

    /// Queues the kNN (and the merge of the segment lists) on `stream`; `out` gets `nq * k` matches.
    fn launch(
        &mut self,
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        query: &CudaSlice<u64>,
        train: &CudaSlice<u64>,
        out: &mut CudaSlice<Match>,
    ) -> Result<()> {
        let g = self.geometry;
        let segment = g.segment as u32;
        if self.mutual {
            // The reverse keys are folded in with atomics: start from zero (no candidate) every run.
            stream
                .memset_zeros(&mut self.reverse)
                .map_err(driver_error("clearing the reverse 1-NN keys"))?;
        }
        if let Some(tensor) = &mut self.tensor {
            return tensor.launch(dev, stream, (query, train), out, &mut self.reverse);
        }
        let mut launch = stream.launch_builder(dev.kernel(self.kernel));
        launch
            .arg(query)
            .arg(&self.nq)
            .arg(train)
            .arg(&self.nt)
            .arg(&segment)
            .arg(&self.k)
            .arg(&mut *out)
            .arg(&mut self.partial)
            .arg(&mut self.reverse);
        let config = LaunchConfig {
            grid_dim: (g.query_blocks as u32, g.segments as u32, 1),
            block_dim: (CLATCH_MATCH_THREADS, 1, 1),
            shared_mem_bytes: 0,
        };
        // SAFETY: the arguments match clatch_knn_*'s signature. Both descriptor buffers hold whole
        // ROW_PAD-row blocks (so every tile and query block the kernel loads is in bounds), `out` holds
        // nq * k matches, `partial` segments * nq * k keys when there is more than one segment, and
        // `reverse` nt keys for the mutual kernels (the only ones that touch it).
        unsafe { launch.launch(config) }.map_err(driver_error(self.kernel.name()))?;
        if g.segments > 1 {
            launch_merge(
                dev,
                stream,
                &self.partial,
                (self.nq, g.segments as u32, self.k),
                out,
            )?;
        }
        Ok(())
    }
}

/// Queues `clatch_knn_merge`: the k best of `segments` sorted lists per query in `partial` (every one
/// written) into `out` (nq * k matches).
pub(crate) fn launch_merge(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    partial: &CudaSlice<u64>,
    (nq, segments, k): (u32, u32, u32),
    out: &mut CudaSlice<Match>,
) -> Result<()> {
    let (rows, wanted) = (
        nq as usize * k as usize,
        segments as usize * nq as usize * k as usize,
    );
    super::invariant(
        partial.len() >= wanted && out.len() >= rows,
        "kNN merge",
        || {
            format!(
                "buffers of {} and {} for {wanted} and {rows}",
                partial.len(),
                out.len()
            )
        },
    )?;
    let mut launch = stream.launch_builder(dev.kernel(kernels::KNN_MERGE));
    launch
        .arg(partial)
        .arg(&nq)
        .arg(&segments)
        .arg(&k)
        .arg(&mut *out);
    let blocks = (nq as usize).div_ceil(SELECT_THREADS).min(1 << 20) as u32;
    let config = LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (CLATCH_MATCH_SELECT_THREADS, 1, 1),
        shared_mem_bytes: 0,
    };
    // SAFETY: `partial` holds segments * nq * k keys, all written by the kNN kernel queued before
    // (every segment is non-empty), and `out` nq * k matches.
    unsafe { launch.launch(config) }.map_err(driver_error("clatch_knn_merge"))?;
    Ok(())
}

/// The k nearest gallery descriptors of every query (validated sets and `k`, as for
/// [`crate::matching::cpu::knn`]). `k` above [`MAX_K`] is an error.
pub(crate) fn knn(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
) -> Result<KnnMatches> {
    knn_with(dev, query, train, k, None, None)
}

fn knn_with(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
    segment_tiles: Option<usize>,
    kernel: Option<MatchKernel>,
) -> Result<KnnMatches> {
    // The test hooks reach this without the façade: the same checks as `Matcher::knn`.
    crate::matching::check_sets(query, train, k)?;
    check_k(k)?;
    check_rows(query, "query descriptors")?;
    check_rows(train, "gallery descriptors")?;
    if query.is_empty() {
        return Ok(KnnMatches::from_parts(k, Vec::new()));
    }
    let stream = dev.new_stream()?;
    let q = upload(&stream, query, "query descriptor upload")?;
    let t = upload(&stream, train, "gallery descriptor upload")?;
    let shape = (query.len(), train.len(), query.width().words());
    let mut run = KnnRun::new(dev, &stream, shape, (k, false), kernel, segment_tiles)?;
    let mut out = alloc_zeros::<Match>(&stream, query.len() * k, "kNN matches")?;
    run.launch(dev, &stream, &q, &t, &mut out)?;
    let matches = stream.clone_dtoh(&out).map_err(driver_error(
        "clatch_knn (running, or copying matches back)",
    ))?;
    Ok(KnnMatches::from_parts(k, matches))
}

/// The kept best matches in query order, exactly as [`crate::matching::cpu::match_descriptors`]
/// (validated sets and configuration).
pub(crate) fn match_descriptors(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Result<Vec<Match>> {
    check_rows(query, "query descriptors")?;
    check_rows(train, "gallery descriptors")?;
    if query.is_empty() {
        return Ok(Vec::new());
    }
    let mut job = MatchJob::prepare(dev, dev.new_stream()?, query, train, config, None)?;
    job.launch(dev)?;
    job.fetch()
}

/// Everything one `match_descriptors` needs on the device, on its stream.
pub(crate) struct MatchJob {
    stream: Arc<CudaStream>,
    query: CudaSlice<u64>,
    train: CudaSlice<u64>,
    run: KnnRun,
    forward: CudaSlice<Match>,
    keep_bits: CudaSlice<u32>,
    counts: CudaSlice<u32>,
    total: CudaSlice<u32>,
    kept: CudaSlice<Match>,
    nq: usize,
    k: usize,
    config: MatchConfig,
}

impl MatchJob {
    /// Uploads both (non-empty, row-checked) sets and allocates every buffer, on `stream`; `kernel`
    /// overrides the device's choice of kNN kernels.
    pub(crate) fn prepare(
        dev: &GpuDevice,
        stream: Arc<CudaStream>,
        query: &DescriptorSet,
        train: &DescriptorSet,
        config: &MatchConfig,
        kernel: Option<MatchKernel>,
    ) -> Result<Self> {
        let (nq, nt, words) = (query.len(), train.len(), query.width().words());
        let k = config.neighbours_needed();
        let blocks = nq.div_ceil(SELECT_THREADS);
        Ok(Self {
            query: upload(&stream, query, "query descriptor upload")?,
            train: upload(&stream, train, "gallery descriptor upload")?,
            run: KnnRun::new(
                dev,
                &stream,
                (nq, nt, words),
                (k, config.cross_check),
                kernel,
                None,
            )?,
            forward: alloc_zeros(&stream, nq * k, "kNN matches")?,
            keep_bits: alloc_zeros(&stream, blocks * SELECT_THREADS / 32, "match flags")?,
            counts: alloc_zeros(&stream, blocks, "match counts")?,
            total: alloc_zeros(&stream, 1, "match count")?,
            kept: alloc_zeros(&stream, nq, "kept matches")?,
            nq,
            k,
            config: config.clone(),
            stream,
        })
    }

    /// Queues the kNN (fused with the reverse 1-NN when cross-checking), the filter and the
    /// compaction.
    pub(crate) fn launch(&mut self, dev: &GpuDevice) -> Result<()> {
        let stream = &self.stream;
        self.run
            .launch(dev, stream, &self.query, &self.train, &mut self.forward)?;

        let blocks = self.nq.div_ceil(SELECT_THREADS);
        let (n, k, blocks32) = (self.nq as u32, self.k as u32, blocks as u32);
        let use_ratio = self.config.ratio.is_some() as i32;
        let ratio = self.config.ratio.unwrap_or(0.0);
        let cross_check = self.config.cross_check as i32;
        let use_max = self.config.max_distance.is_some() as i32;
        let max_distance = self.config.max_distance.unwrap_or(u32::MAX);
        let shape = |blocks: usize, threads: u32| LaunchConfig {
            grid_dim: (blocks as u32, 1, 1),
            block_dim: (threads, 1, 1),
            shared_mem_bytes: 0,
        };

        let mut launch = stream.launch_builder(dev.kernel(kernels::MATCH_FILTER));
        launch
            .arg(&self.forward)
            .arg(&n)
            .arg(&k)
            .arg(&use_ratio)
            .arg(&ratio)
            .arg(&cross_check)
            .arg(&self.run.reverse)
            .arg(&use_max)
            .arg(&max_distance)
            .arg(&mut self.keep_bits)
            .arg(&mut self.counts);
        // SAFETY: the arguments match clatch_match_filter's signature; `forward` holds nq * k
        // matches, `run.reverse` nt keys with the cross-check (read only then, at train indices
        // < nt), `keep_bits` 8 words and `counts` one word per block.
        unsafe { launch.launch(shape(blocks, CLATCH_MATCH_SELECT_THREADS)) }
            .map_err(driver_error("clatch_match_filter"))?;

        let mut launch = stream.launch_builder(dev.kernel(kernels::MATCH_SCAN));
        launch
            .arg(&mut self.counts)
            .arg(&blocks32)
            .arg(&mut self.total);
        // SAFETY: `counts` holds `blocks` words, `total` one.
        unsafe { launch.launch(shape(1, CLATCH_MATCH_SCAN_THREADS)) }
            .map_err(driver_error("clatch_match_scan"))?;

        let mut launch = stream.launch_builder(dev.kernel(kernels::MATCH_COMPACT));
        launch
            .arg(&self.forward)
            .arg(&n)
            .arg(&k)
            .arg(&self.keep_bits)
            .arg(&self.counts)
            .arg(&mut self.kept);
        // SAFETY: as for the filter; `kept` holds nq matches and every offset plus rank is below
        // the number of kept queries.
        unsafe { launch.launch(shape(blocks, CLATCH_MATCH_SELECT_THREADS)) }
            .map_err(driver_error("clatch_match_compact"))?;
        Ok(())
    }

    /// Waits for the kernels and copies the kept matches back.
    pub(crate) fn fetch(&self) -> Result<Vec<Match>> {
        let count = self.stream.clone_dtoh(&self.total).map_err(driver_error(
            "matching (running, or copying the count back)",
        ))?[0] as usize;
        if count == 0 {
            return Ok(Vec::new());
        }
        self.stream
            .clone_dtoh(&self.kept.slice(0..count.min(self.nq)))
            .map_err(driver_error("copying the kept matches back"))
    }
}

#[cfg(feature = "internals")]
pub mod hooks;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_choice_follows_words_and_k() {
        for words in 1..=8 {
            for k in 1..=MAX_K {
                let len = LIST_LENGTHS.iter().find(|&&len| len >= k).unwrap();
                assert_eq!(
                    knn_kernel(words, k, false).name(),
                    format!("clatch_knn_w{words}_k{len}")
                );
            }
            for k in 1..=2 {
                assert_eq!(
                    knn_kernel(words, k, true).name(),
                    format!("clatch_knn_mutual_w{words}_k{k}")
                );
            }
        }
        assert_eq!(*LIST_LENGTHS.last().unwrap(), MAX_K);
        assert_eq!(kernels::KNN.len(), 8 * KERNELS_PER_WIDTH);
    }

    #[test]
    fn padding_holds_whole_tiles_and_query_blocks() {
        let qpt = CLATCH_MATCH_QUERIES_PER_THREAD as usize;
        assert_eq!(ROW_PAD % TILE, 0);
        assert_eq!(ROW_PAD % (THREADS * qpt), 0);
        assert_eq!(
            ROW_PAD % THREADS,
            0,
            "the variants with one query per thread"
        );
    }
}
