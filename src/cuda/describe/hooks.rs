//! Test and bench hooks of `cuda/describe/` (the `internals` feature only): not part of the API.

use super::*;
use crate::cuda::device::time_launches;
use crate::cuda::image::ImageLife;

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
    let lane = Leased::take(dev)?;
    let result = Job::prepare(dev, &lane, image, keypoints, config)
        .and_then(|mut job| time_launches(dev, &lane, warmup, repeats, || job.launch(dev)));
    settled(&lane, result)
}

/// `image` smoothed by `smoothing` as the GPU smooths it before description
/// (`clatch_smooth_binomial*`; `Smoothing::None`: the uploaded pixels), row-major with
/// stride = width: for comparing with [`crate::describe::cpu::smooth`].
pub fn debug_smoothed(
    dev: &GpuDevice,
    image: &GrayView,
    smoothing: crate::describe::Smoothing,
) -> Result<Vec<u8>> {
    let lane = Leased::take(dev)?;
    let device_image = DeviceImage::upload(dev, &lane, image, ImageLife::Call)?;
    match device_image.smoothed(dev, &lane, smoothing)? {
        Some(smoothed) => device_image.download_like(&lane, &smoothed),
        None => device_image.download(&lane),
    }
}
