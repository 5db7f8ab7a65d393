//! Test and bench hooks of `cuda/matching/` (the `internals` feature only): not part of the API.

use super::*;
use crate::cuda::device::time_launches;
use cudarc::driver::sys;

/// [`knn`] with the gallery cut into segments of `segment_tiles` tiles of
/// `CLATCH_MATCH_TILE` descriptors (1 = one block per tile, `usize::MAX` = one segment): lets the
/// tests reach both the direct and the merged path at every size.
pub fn knn_segmented(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
    segment_tiles: usize,
) -> Result<KnnMatches> {
    knn_with(dev, query, train, k, Some(segment_tiles.max(1)), None)
}

/// [`knn`] on the kernel family `kernel` (an error where the device or `k` does not allow it), with
/// the gallery segments of [`knn_segmented`] when `segment_tiles` is given (tensor kernels: tiles of
/// `CLATCH_TENSOR_TILE`).
pub fn knn_on(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
    segment_tiles: Option<usize>,
    kernel: MatchKernel,
) -> Result<KnnMatches> {
    knn_with(
        dev,
        query,
        train,
        k,
        segment_tiles.map(|t| t.max(1)),
        Some(kernel),
    )
}

/// [`match_descriptors`] on the kernel family `kernel` (an error where the device does not allow it).
pub fn match_descriptors_on(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
    kernel: MatchKernel,
) -> Result<Vec<Match>> {
    crate::matching::check_sets(query, train, config.neighbours_needed())?;
    check_rows(query, "query descriptors")?;
    check_rows(train, "gallery descriptors")?;
    if query.is_empty() {
        return Ok(Vec::new());
    }
    let mut job = MatchJob::prepare(dev, dev.new_stream()?, query, train, config, Some(kernel))?;
    job.launch(dev)?;
    job.fetch()
}

/// Kernel times in milliseconds of `repeats` runs of everything `match_descriptors` queues on the
/// device (kNN with the fused reverse 1-NN, filter, scan, compaction) after `warmup` runs, measured
/// with CUDA events (uploads and downloads excluded). Validated, non-empty sets.
pub fn time_match_kernels(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
    kernel: Option<MatchKernel>,
    (warmup, repeats): (usize, usize),
) -> Result<Vec<f32>> {
    let k = config.neighbours_needed();
    crate::matching::check_sets(query, train, k)?;
    if !config.can_match(query.len(), train.len()) {
        return Err(Error::InvalidK {
            k,
            gallery: train.len(),
        });
    }
    let mut job = MatchJob::prepare(dev, dev.new_stream()?, query, train, config, kernel)?;
    let stream = job.stream.clone();
    time_launches(dev, &stream, warmup, repeats, || job.launch(dev))
}

/// The device's multiprocessor count and its maximum SM clock in kHz (driver attributes), for the
/// bench's POPC bound.
pub fn multiprocessors_and_clock_khz(dev: &GpuDevice) -> Result<(usize, usize)> {
    let attribute = |a| {
        dev.ctx
            .attribute(a)
            .map_err(driver_error("reading device attributes"))
    };
    let sms = attribute(sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_MULTIPROCESSOR_COUNT)?;
    let clock = attribute(sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_CLOCK_RATE)?;
    Ok((sms.max(0) as usize, clock.max(0) as usize))
}

/// Kernel times in milliseconds of `repeats` kNN runs (the kNN kernel and, when the gallery is split,
/// the merge) after `warmup` runs, measured with CUDA events (uploads and downloads excluded).
pub fn time_knn_kernel(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
    kernel: Option<MatchKernel>,
    (warmup, repeats): (usize, usize),
) -> Result<Vec<f32>> {
    crate::matching::check_sets(query, train, k)?;
    check_k(k)?;
    if query.is_empty() || k == 0 || k > train.len() {
        return Err(Error::InvalidK {
            k,
            gallery: train.len(),
        });
    }
    let stream = dev.new_stream()?;
    let q = upload(&stream, query, "query descriptor upload")?;
    let t = upload(&stream, train, "gallery descriptor upload")?;
    let shape = (query.len(), train.len(), query.width().words());
    let mut run = KnnRun::new(dev, &stream, shape, (k, false), kernel, None)?;
    let mut out = alloc_zeros::<Match>(&stream, query.len() * k, "kNN matches")?;
    time_launches(dev, &stream, warmup, repeats, || {
        run.launch(dev, &stream, &q, &t, &mut out)
    })
}

/// Times every kernel of `kernels/bench_knn_variants.cu` (512-bit sets, k = 2) as [`time_knn_kernel`]
/// does, after checking that each returns exactly the production kernel's matches. Returns
/// `(kernel name, times in ms)`.
pub fn time_knn_variants(
    dev: &GpuDevice,
    query: &DescriptorSet,
    train: &DescriptorSet,
    warmup: usize,
    repeats: usize,
) -> Result<Vec<(&'static str, Vec<f32>)>> {
    dev.load_bench_kernels()?;
    const K: usize = 2;
    crate::matching::check_sets(query, train, K)?;
    if query.width().words() != 8 || train.len() < K {
        return Err(Error::InvalidInput {
            what: "variant sets",
            reason: format!(
                "{} bits, {} gallery rows: the kNN variants are compiled for 512-bit descriptors \
                 and k = 2",
                query.width().bits(),
                train.len()
            ),
        });
    }
    let expected = knn_on(dev, query, train, K, None, MatchKernel::Popcount)?.into_vec();
    let stream = dev.new_stream()?;
    let q = upload(&stream, query, "query descriptor upload")?;
    let t = upload(&stream, train, "gallery descriptor upload")?;
    let mut results = Vec::new();
    for &kernel in crate::cuda::kernels::KNN_VARIANTS {
        let qpt = if kernel.name().contains("_q2_") { 2 } else { 1 };
        let mut run = KnnRun::with_kernel(
            dev,
            &stream,
            kernel,
            qpt,
            (query.len(), train.len()),
            K,
            None,
        )?;
        let mut out = alloc_zeros::<Match>(&stream, query.len() * K, "kNN matches")?;
        run.launch(dev, &stream, &q, &t, &mut out)?;
        let got = stream
            .clone_dtoh(&out)
            .map_err(driver_error("copying variant matches back"))?;
        if got != expected {
            let first = got.iter().zip(&expected).position(|(a, b)| a != b);
            return Err(Error::Internal {
                operation: "kNN variant check",
                message: format!(
                    "{} differs from the production kernel (first at {first:?})",
                    kernel.name()
                ),
            });
        }
        let times = time_launches(dev, &stream, warmup, repeats, || {
            run.launch(dev, &stream, &q, &t, &mut out)
        })?;
        results.push((kernel.name(), times));
    }
    Ok(results)
}
