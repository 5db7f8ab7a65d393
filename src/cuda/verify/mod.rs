//! The CUDA twin of [`crate::verify::verify_pairs`]: every pair of a batch verified in one launch of
//! `clatch_verify_pairs` (`kernels/verify.cu`, one warp per pair), which reproduces
//! `verify::two_view::estimate_two_view` bit for bit (the arithmetic of `kernels/verify_math.cuh`,
//! the same operations in the same order; docs/numerics.md, section 7).
//!
//! The host checks (the caller did: `verify::check_pairs`), applies neighbour consistency when it is
//! on (integer rules, on the host's threads), packs the pairs as records (`verify::packed`) and
//! uploads them chunk by chunk: a chunk holds as many pairs as fit in a byte budget of device memory
//! (points, scratch lists and inliers per correspondence; a record and a result per pair), so a batch
//! of any size runs in bounded memory. One pair larger than the budget runs alone.

use std::sync::Arc;

use cudarc::driver::{
    CudaSlice, CudaStream, DeviceRepr, LaunchConfig, PushKernelArg, ValidAsZeroBits,
};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::CLATCH_VERIFY_WARPS;
use super::kernels;
use super::memory::{alloc_zeros, upload};
use crate::error::Result;
use crate::parallel::*;
use crate::verify::packed::{
    LISTS, PackedPairs, PairRecord, PointRecord, ResultRecord, SettingsRecord, correspondences,
    kept_matches,
};
use crate::verify::{TwoViewGeometry, VerifyConfig, ViewPair};

// SAFETY (all seven): #[repr(C)] records of plain f32/f64/u32/u64 fields, the layouts of
// kernels/clatch.h's clatch_verify_* structs (checked against bindgen's in `cuda::tests`); any bit
// pattern is a valid value, so zeroed and device-written memory reads back as a valid record.
unsafe impl DeviceRepr for PointRecord {}
unsafe impl DeviceRepr for PairRecord {}
unsafe impl DeviceRepr for SettingsRecord {}
unsafe impl DeviceRepr for ResultRecord {}
unsafe impl ValidAsZeroBits for ResultRecord {}
unsafe impl ValidAsZeroBits for PointRecord {}
unsafe impl ValidAsZeroBits for PairRecord {}

/// Device memory a chunk may take by default: 256 MiB (about 7 million correspondences).
pub(crate) const CHUNK_BYTES: usize = 256 << 20;

/// Device bytes of a pair with `count` correspondences: its point records, scratch lists and
/// inliers, its pair record and result.
fn pair_bytes(count: usize) -> usize {
    count * (size_of::<PointRecord>() + (LISTS + 1) * size_of::<u32>())
        + size_of::<PairRecord>()
        + size_of::<ResultRecord>()
}

/// [`crate::verify::verify_pairs`] on the device (pairs and configuration checked by the caller).
pub(crate) fn verify_pairs(
    dev: &GpuDevice,
    pairs: &[ViewPair<'_>],
    config: &VerifyConfig,
) -> Result<Vec<TwoViewGeometry>> {
    Ok(verify_in_chunks(dev, pairs, config, CHUNK_BYTES)?.0)
}

/// The geometries and the number of chunks (launches) under a budget of `chunk_bytes`.
fn verify_in_chunks(
    dev: &GpuDevice,
    pairs: &[ViewPair<'_>],
    config: &VerifyConfig,
    chunk_bytes: usize,
) -> Result<(Vec<TwoViewGeometry>, usize)> {
    let kept: Vec<Option<Vec<u32>>> = pairs.par_iter().map(|p| kept_matches(p, config)).collect();
    let sizes: Vec<usize> = pairs
        .iter()
        .zip(&kept)
        .map(|(p, k)| pair_bytes(correspondences(p, k.as_deref())))
        .collect();
    let chunks = chunk_bounds(&sizes, chunk_bytes);
    let stream = dev.new_stream()?;
    let mut geometries = Vec::with_capacity(pairs.len());
    let mut kept = kept.into_iter();
    for range in &chunks {
        let chunk_kept = kept.by_ref().take(range.len()).collect();
        let packed = PackedPairs::new(&pairs[range.clone()], chunk_kept, config);
        geometries.extend(run_chunk(dev, &stream, &packed)?);
    }
    Ok((geometries, chunks.len()))
}

/// Consecutive ranges of pairs, each as long as its bytes stay within `budget` (and at least one
/// pair long).
fn chunk_bounds(sizes: &[usize], budget: usize) -> Vec<std::ops::Range<usize>> {
    let mut chunks = Vec::new();
    let (mut start, mut bytes) = (0, 0usize);
    for (i, &size) in sizes.iter().enumerate() {
        if i > start && bytes.saturating_add(size) > budget {
            chunks.push(start..i);
            (start, bytes) = (i, 0);
        }
        bytes = bytes.saturating_add(size);
    }
    if start < sizes.len() {
        chunks.push(start..sizes.len());
    }
    chunks
}

/// One launch over a packed chunk, its geometries in order.
fn run_chunk(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    packed: &PackedPairs,
) -> Result<Vec<TwoViewGeometry>> {
    let mut chunk = DeviceChunk::upload(stream, packed)?;
    chunk.launch(dev, stream)?;
    chunk.fetch(stream, packed)
}

/// A packed chunk on the device: its inputs, scratch lists and outputs, on one stream.
struct DeviceChunk {
    settings: CudaSlice<SettingsRecord>,
    records: CudaSlice<PairRecord>,
    points: CudaSlice<PointRecord>,
    scratch: CudaSlice<u32>,
    inliers: CudaSlice<u32>,
    results: CudaSlice<ResultRecord>,
    pair_count: u32,
}

impl DeviceChunk {
    fn upload(stream: &Arc<CudaStream>, packed: &PackedPairs) -> Result<Self> {
        let n = packed.points.len();
        let count = packed.pairs.len();
        let pair_count = u32::try_from(count).map_err(|_| crate::error::Error::Internal {
            operation: "clatch_verify_pairs launch",
            message: format!("a chunk of {count} pairs"),
        })?;
        Ok(Self {
            settings: upload(
                stream,
                std::slice::from_ref(&packed.settings),
                "verification settings",
            )?,
            records: if count == 0 {
                alloc_zeros(stream, 1, "verification pair records")?
            } else {
                upload(stream, &packed.pairs, "verification pair records")?
            },
            points: if n == 0 {
                alloc_zeros(stream, 1, "verification points")?
            } else {
                upload(stream, &packed.points, "verification points")?
            },
            scratch: alloc_zeros(stream, LISTS * n, "verification inlier lists")?,
            inliers: alloc_zeros(stream, n, "verification inliers")?,
            results: alloc_zeros(stream, count, "verification results")?,
            pair_count,
        })
    }

    /// Queues the kernel over every pair of the chunk.
    fn launch(&mut self, dev: &GpuDevice, stream: &Arc<CudaStream>) -> Result<()> {
        if self.pair_count == 0 {
            return Ok(());
        }
        let warps = CLATCH_VERIFY_WARPS;
        let config = LaunchConfig {
            grid_dim: (self.pair_count.div_ceil(warps), 1, 1),
            block_dim: (32 * warps, 1, 1),
            shared_mem_bytes: 0,
        };
        let mut launch = stream.launch_builder(dev.kernel(kernels::VERIFY_PAIRS));
        launch
            .arg(&self.settings)
            .arg(&self.records)
            .arg(&self.pair_count)
            .arg(&self.points)
            .arg(&mut self.scratch)
            .arg(&mut self.inliers)
            .arg(&mut self.results);
        // SAFETY: the arguments match the signature of `clatch_verify_pairs` (settings, pairs, pair count,
        // points, scratch, inliers, results); `records` and `results` hold `pair_count` entries and
        // one warp per pair reads and writes only its own; each pair's `first .. first + count` lies
        // within the points and inliers, and its `LISTS` lists within the `LISTS` times larger
        // scratch (PackedPairs lays the pairs back to back). The buffers outlive the work queued on
        // `stream`: `fetch` copies back on the same stream before dropping them.
        unsafe { launch.launch(config) }.map_err(driver_error("clatch_verify_pairs launch"))?;
        Ok(())
    }

    /// The geometries of the chunk (waits for the kernel).
    fn fetch(self, stream: &Arc<CudaStream>, packed: &PackedPairs) -> Result<Vec<TwoViewGeometry>> {
        let results = stream.clone_dtoh(&self.results).map_err(driver_error(
            "clatch_verify_pairs (running, or copying results back)",
        ))?;
        let inliers = stream
            .clone_dtoh(&self.inliers)
            .map_err(driver_error("copying verification inliers back"))?;
        Ok(packed
            .pairs
            .iter()
            .enumerate()
            .map(|(i, pair)| packed.geometry(i, &results[i], &inliers[pair.first as usize..]))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::chunk_bounds;

    #[test]
    fn chunks_stay_within_the_budget_and_keep_every_pair_once() {
        assert_eq!(chunk_bounds(&[], 10), Vec::new());
        assert_eq!(chunk_bounds(&[4, 4, 4, 4, 4], 10), vec![0..2, 2..4, 4..5]);
        // A pair over the budget runs alone.
        assert_eq!(chunk_bounds(&[3, 30, 3, 3], 10), vec![0..1, 1..2, 2..4]);
        assert_eq!(chunk_bounds(&[10, 10], 10), vec![0..1, 1..2]);
    }
}

/// The test suites' and benches' hooks (`internals` feature; not public API).
#[cfg(feature = "internals")]
pub mod hooks {
    use super::*;

    /// [`crate::verify::verify_pairs`] on the device under a chunk budget of `chunk_bytes`: the
    /// geometries and how many launches it took. Checks the pairs as the façade does.
    pub fn verify_pairs_in_chunks(
        dev: &GpuDevice,
        pairs: &[ViewPair<'_>],
        config: &VerifyConfig,
        chunk_bytes: usize,
    ) -> Result<(Vec<TwoViewGeometry>, usize)> {
        crate::verify::check_pairs(pairs, config)?;
        verify_in_chunks(dev, pairs, config, chunk_bytes)
    }

    /// Kernel times in milliseconds (CUDA events around each launch, after `warmup` launches) of
    /// one launch over all of `pairs` (checked; uploaded once, neighbour consistency applied).
    pub fn time_verify_kernel(
        dev: &GpuDevice,
        pairs: &[ViewPair<'_>],
        config: &VerifyConfig,
        warmup: usize,
        repeats: usize,
    ) -> Result<Vec<f32>> {
        crate::verify::check_pairs(pairs, config)?;
        let kept = pairs.iter().map(|p| kept_matches(p, config)).collect();
        let packed = PackedPairs::new(pairs, kept, config);
        let stream = dev.new_stream()?;
        let mut chunk = DeviceChunk::upload(&stream, &packed)?;
        let times = crate::cuda::device::time_launches(dev, &stream, warmup, repeats, || {
            chunk.launch(dev, &stream)
        })?;
        chunk.fetch(&stream, &packed)?;
        Ok(times)
    }
}
