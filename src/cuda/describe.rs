//! GPU description: `kernels/describe.cu`, reproducing [`crate::describe::cpu::describe`].

use std::sync::Arc;

use cudarc::driver::{CudaSlice, CudaStream, DeviceRepr, LaunchConfig, PushKernelArg};

use super::device::{GpuDevice, driver_error};
use super::header::CLATCH_DESCRIBE_WARPS;
use super::memory::{alloc_zeros, upload};
use super::texture::DeviceImage;
use crate::describe::{Described, DescriptorConfig, SamplingFrame, SkipReason, Skipped};
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;

// SAFETY: KeyPoint is #[repr(C)] plain old data with the layout of clatch_keypoint (checked in tests).
unsafe impl DeviceRepr for KeyPoint {}

/// Blocks per multiprocessor: enough resident warps to hide texture latency.
const BLOCKS_PER_SM: usize = 8;

/// Describes validated keypoints on the GPU. Which keypoints fit is decided on the host with the same
/// [`SamplingFrame::fits`] the CPU uses; the kernel computes the frames itself.
pub(crate) fn describe(
    dev: &GpuDevice,
    image: &GrayView,
    keypoints: &[KeyPoint],
    config: &DescriptorConfig,
) -> Result<Described> {
    let (mut keypoint_index, mut skipped) = (Vec::new(), Vec::new());
    for (i, kp) in keypoints.iter().enumerate() {
        if SamplingFrame::of(kp).fits(image.width(), image.height()) {
            keypoint_index.push(i);
        } else {
            skipped.push(Skipped {
                keypoint: i,
                reason: SkipReason::WindowOutsideImage,
            });
        }
    }
    let width = config.width;
    if keypoint_index.is_empty() {
        return Ok(Described {
            descriptors: DescriptorSet::empty(width),
            keypoint_index,
            skipped,
        });
    }
    let selected: Vec<KeyPoint> = keypoint_index.iter().map(|&i| keypoints[i]).collect();
    let mut job = Job::prepare(dev, image, &selected, config)?;
    job.launch(dev)?;
    let words = job.stream.clone_dtoh(&job.out).map_err(driver_error(
        "clatch_describe (running, or copying descriptors back)",
    ))?;
    Ok(Described {
        descriptors: DescriptorSet::from_words(width, words)?,
        keypoint_index,
        skipped,
    })
}

/// Everything one launch of `clatch_describe` on host-supplied keypoints needs, on the device.
struct Job {
    stream: Arc<CudaStream>,
    image: DeviceImage,
    keypoints: CudaSlice<KeyPoint>,
    count: CudaSlice<u32>,
    weights: DeviceWeights,
    out: CudaSlice<u64>,
    bits: i32,
}

impl Job {
    /// Uploads the image and keypoints (all of which must fit) on a new stream.
    fn prepare(
        dev: &GpuDevice,
        image: &GrayView,
        keypoints: &[KeyPoint],
        config: &DescriptorConfig,
    ) -> Result<Self> {
        let stream = dev.new_stream()?;
        let mut device_image = DeviceImage::upload(dev, &stream, image)?;
        device_image.build_quads(dev, &stream, config.smoothing)?;
        Ok(Self {
            keypoints: upload(&stream, keypoints, "keypoint upload")?,
            count: upload(&stream, &[keypoints.len() as u32], "keypoint count upload")?,
            weights: upload_weights(&stream, config)?,
            out: alloc_zeros(
                &stream,
                keypoints.len() * config.width.words(),
                "descriptor allocation",
            )?,
            image: device_image,
            bits: config.width.bits() as i32,
            stream,
        })
    }

    /// Queues the kernel on the job's stream.
    fn launch(&mut self, dev: &GpuDevice) -> Result<()> {
        launch_describe(
            dev,
            &self.stream,
            &self.image,
            (&self.keypoints, &self.count),
            &self.weights,
            self.bits,
            &mut self.out,
        )
    }
}

/// The patch weights on the device, and which kernel they call for.
pub(crate) struct DeviceWeights {
    values: CudaSlice<i32>,
    /// Every weight 0 or 1: `clatch_describe_binary` (byte masks and dp4a) applies.
    binary: bool,
}

/// The patch weights as the kernels read them.
pub(crate) fn upload_weights(
    stream: &Arc<CudaStream>,
    config: &DescriptorConfig,
) -> Result<DeviceWeights> {
    let weights: Vec<i32> = config
        .weights
        .as_array()
        .iter()
        .map(|&w| w as i32)
        .collect();
    Ok(DeviceWeights {
        values: upload(stream, &weights, "weight upload")?,
        binary: config.weights.is_binary(),
    })
}

/// Queues `clatch_describe` on `stream`: describes the first `min(*count, keypoints.len())` keypoints
/// (all of which must fit) into `out` (`keypoints.len()` rows of the width's words).
pub(crate) fn launch_describe(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    image: &DeviceImage,
    (keypoints, count): (&CudaSlice<KeyPoint>, &CudaSlice<u32>),
    weights: &DeviceWeights,
    bits: i32,
    out: &mut CudaSlice<u64>,
) -> Result<()> {
    let capacity = keypoints.len() as i32;
    let texture = image.quads().ok_or_else(|| Error::Internal {
        operation: "describe",
        message: "the image's quad texture was not built".into(),
    })?;
    let (width, height) = (image.width() as i32, image.height() as i32);
    let blocks = keypoints
        .len()
        .clamp(1, dev.multiprocessors * BLOCKS_PER_SM) as u32;
    let kernel = if weights.binary {
        "clatch_describe_binary"
    } else {
        "clatch_describe"
    };
    let mut launch = stream.launch_builder(dev.kernel(kernel));
    launch
        .arg(&texture)
        .arg(&width)
        .arg(&height)
        .arg(keypoints)
        .arg(count)
        .arg(&capacity)
        .arg(&dev.rotation)
        .arg(&dev.triplets)
        .arg(&weights.values)
        .arg(&bits)
        .arg(out);
    let config = LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (CLATCH_DESCRIBE_WARPS * 32, 1, 1),
        shared_mem_bytes: 0,
    };
    // SAFETY: the argument list matches clatch_describe's signature; every buffer holds what the
    // kernel indexes (capacity keypoints, one count, 2880 rotations, 512 triplets, 64 weights,
    // capacity * words outputs).
    unsafe { launch.launch(config) }.map_err(driver_error(kernel))?;
    Ok(())
}

#[cfg(feature = "internals")]
pub mod hooks;
