//! Test and bench hooks of `cuda/describe.rs` (the `internals` feature only): not part of the API.

use super::*;
use crate::cuda::device::time_launches;

/// Kernel times in milliseconds of `repeats` launches after `warmup` launches, measured with CUDA
/// events on the job's stream (upload and download excluded). Keypoints must all fit.
pub fn time_describe_kernel(
    dev: &GpuDevice,
    image: &GrayView,
    keypoints: &[KeyPoint],
    config: &DescriptorConfig,
    warmup: usize,
    repeats: usize,
) -> Result<Vec<f32>> {
    let mut job = Job::prepare(dev, image, keypoints, config)?;
    let stream = job.stream.clone();
    time_launches(dev, &stream, warmup, repeats, || job.launch(dev))
}
