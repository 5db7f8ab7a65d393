//! GPU description: `kernels/describe.cu`, reproducing [`crate::describe::cpu::describe`].

use cudarc::driver::{DeviceRepr, LaunchConfig, PushKernelArg};

use super::device::{GpuDevice, driver_error};
use super::header::CLATCH_DESCRIBE_WARPS;
use super::texture::DeviceImage;
use crate::describe::{Described, DescriptorConfig, SamplingFrame, SkipReason, Skipped};
use crate::descriptor::DescriptorSet;
use crate::error::Result;
use crate::image::GrayView;
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
    let weights: Vec<i32> = config
        .weights
        .as_array()
        .iter()
        .map(|&w| w as i32)
        .collect();

    let stream = dev.new_stream()?;
    let device_image = DeviceImage::upload(dev, &stream, image)?;
    let d_keypoints = stream
        .clone_htod(&selected)
        .map_err(driver_error("keypoint upload"))?;
    let d_weights = stream
        .clone_htod(&weights)
        .map_err(driver_error("weight upload"))?;
    let mut d_out = stream
        .alloc_zeros::<u64>(selected.len() * width.words())
        .map_err(driver_error("descriptor allocation"))?;

    let count = selected.len() as i32;
    let (w, h) = (image.width() as i32, image.height() as i32);
    let bits = width.bits() as i32;
    let texture = device_image.texture();
    let blocks = selected.len().min(dev.multiprocessors * BLOCKS_PER_SM) as u32;
    let mut launch = stream.launch_builder(&dev.describe);
    launch
        .arg(&texture)
        .arg(&w)
        .arg(&h)
        .arg(&d_keypoints)
        .arg(&count)
        .arg(&dev.rotation)
        .arg(&dev.triplets)
        .arg(&d_weights)
        .arg(&bits)
        .arg(&mut d_out);
    let config = LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (CLATCH_DESCRIBE_WARPS * 32, 1, 1),
        shared_mem_bytes: 0,
    };
    // SAFETY: the argument list matches clatch_describe's signature; every buffer holds what the
    // kernel indexes (count keypoints, 2880 rotations, 512 triplets, 64 weights, count * words outputs).
    unsafe { launch.launch(config) }.map_err(driver_error("launching clatch_describe"))?;
    let words = stream.clone_dtoh(&d_out).map_err(driver_error(
        "clatch_describe (running, or copying descriptors back)",
    ))?;
    drop(device_image);
    Ok(Described {
        descriptors: DescriptorSet::from_words(width, words)?,
        keypoint_index,
        skipped,
    })
}
