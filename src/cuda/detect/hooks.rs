//! Test and bench hooks of `cuda/detect/` (the `internals` feature only): not part of the API.

use super::*;
use crate::cuda::device::time_launches;
use crate::cuda::image::ImageLife;

/// Times the detector: `repeats` runs of all its launches after `warmup` runs, each measured with CUDA
/// events on its stream (image upload, allocation and read-back excluded). Returns the times in
/// milliseconds and the keypoints of the last run.
pub fn time_detect(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
    warmup: usize,
    repeats: usize,
) -> Result<(Vec<f32>, Vec<KeyPoint>)> {
    let stream = Leased::take(dev)?;
    let device_image = DeviceImage::upload(dev, &stream, image, ImageLife::Call)?;
    let mut job = DetectJob::new(&stream, image.width(), image.height(), config)?;
    let times = time_launches(dev, &stream, warmup, repeats, || {
        job.launch(dev, &stream, &device_image)
    })?;
    let keypoints = job.output.download(&stream)?;
    Ok((times, keypoints))
}

/// Intermediate results of one detection, for diagnosing a difference from the CPU.
#[derive(Clone, Debug)]
pub struct DetectStages {
    /// Every texel as the texture returns it, `width x height`.
    pub texture: Vec<u8>,
    /// Row pitch of `kept`.
    pub pitch: usize,
    /// Suppression's output: the score of each survivor, 0 elsewhere (`pitch x height`).
    pub kept: Vec<u8>,
    /// The scanned counts: `offsets[(255 - s) * height + y]` = first output position of score `s`, row
    /// `y`.
    pub offsets: Vec<u32>,
    /// Survivors in all.
    pub total: u32,
    /// The scatter's records (angle still 0), then the final keypoints.
    pub scattered: Vec<KeyPoint>,
    /// The final keypoints.
    pub keypoints: Vec<KeyPoint>,
}

/// Runs the detector stage by stage and reads every intermediate buffer back.
pub fn debug_detect_stages(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
) -> Result<DetectStages> {
    dev.load_bench_kernels()?;
    let stream = Leased::take(dev)?;
    let device_image = DeviceImage::upload(dev, &stream, image, ImageLife::Call)?;
    let (width, height) = (image.width(), image.height());
    let mut texels =
        crate::cuda::memory::alloc_zeros::<u8>(&stream, width * height, "debug texels")?;
    device_image.arrived(&stream)?;
    let mut read = stream.launch_builder(dev.kernel(crate::cuda::kernels::DEBUG_READ_TEXTURE));
    let texture = device_image.texture();
    let (w, h) = (width as i32, height as i32);
    read.arg(&texture).arg(&w).arg(&h).arg(&mut texels);
    // SAFETY: one thread per texel of the width x height output.
    unsafe {
        read.launch(LaunchConfig {
            grid_dim: (width.div_ceil(128) as u32, height as u32, 1),
            block_dim: (128, 1, 1),
            shared_mem_bytes: 0,
        })
    }
    .map_err(driver_error("launching clatch_debug_read_texture"))?;
    let texture = stream
        .clone_dtoh(&texels)
        .map_err(driver_error("debug texels"))?;
    let mut job = DetectJob::new(&stream, width, height, config)?;
    job.launch_stages(dev, &stream, &device_image, Stage::Suppress)?;
    let kept = stream
        .clone_dtoh(&job.kept.view())
        .map_err(driver_error("debug kept map"))?;
    let mut job = DetectJob::new(&stream, width, height, config)?;
    job.launch_stages(dev, &stream, &device_image, Stage::Scan)?;
    let offsets = stream
        .clone_dtoh(&job.counts.view())
        .map_err(driver_error("debug offsets"))?;
    let total = stream
        .clone_dtoh(&job.output.total.view())
        .map_err(driver_error("debug total"))?[0];
    let mut job = DetectJob::new(&stream, width, height, config)?;
    job.launch_stages(dev, &stream, &device_image, Stage::Scatter)?;
    let scattered = job.output.download(&stream)?;
    let mut job = DetectJob::new(&stream, width, height, config)?;
    job.launch(dev, &stream, &device_image)?;
    let keypoints = job.output.download(&stream)?;
    Ok(DetectStages {
        texture,
        pitch: job.geometry.pitch,
        kept,
        offsets,
        total,
        scattered,
        keypoints,
    })
}

/// The sub-pixel offsets `[dx, dy]` (1/65536 pixel) the GPU gives `keypoints` (whole positions) on
/// `image`: for comparing with [`crate::detect::cpu::subpixel_offset`].
pub fn debug_subpixel_offsets(
    dev: &GpuDevice,
    image: &GrayView,
    keypoints: &[KeyPoint],
) -> Result<Vec<[i32; 2]>> {
    if keypoints.is_empty() {
        return Ok(Vec::new());
    }
    let stream = Leased::take(dev)?;
    let device_image = DeviceImage::upload(dev, &stream, image, ImageLife::Call)?;
    let mut on_device = super::super::memory::upload(&stream, keypoints, "debug keypoint upload")?;
    let n = keypoints.len();
    let mut bins = crate::cuda::memory::alloc_zeros::<i32>(&stream, n, "debug orientation bins")?;
    let mut offsets =
        crate::cuda::memory::alloc_zeros::<i32>(&stream, 2 * n, "debug sub-pixel offsets")?;
    // The pyramid's kernel, with one level: it orients them too.
    launch_orient_refine(
        dev,
        &stream,
        &[(&device_image, n)],
        &mut on_device.as_view_mut(),
        &mut bins.as_view_mut(),
        Some(&mut offsets.as_view_mut()),
    )?;
    let flat = stream
        .clone_dtoh(&offsets)
        .map_err(driver_error("copying sub-pixel offsets back"))?;
    Ok(flat.chunks_exact(2).map(|p| [p[0], p[1]]).collect())
}
