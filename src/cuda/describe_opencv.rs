//! GPU OpenCV-compatible LATCH: `kernels/describe_opencv.cu`, reproducing
//! [`crate::describe::opencv::cpu`].
//!
//! The host keeps every decision a float or a rule could make differently: the caller
//! ([`crate::OpencvLatch::describe`]) applied the border rule and computed each keypoint's
//! [`Placement`] (rounded position, `f64` cos/sin rounded to `f32`), and the blur runs here on the host
//! with the CPU's own fixed-point code (a 3x3 pass is cheap next to the descriptors; one implementation
//! of it cannot disagree with itself). The device rotates the centres and compares the SSDs.

use std::borrow::Cow;

use cudarc::driver::{DeviceRepr, LaunchConfig, PushKernelArg};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::CLATCH_OPENCV_THREADS;
use super::kernels;
use super::memory::{alloc_zeros, upload};
use crate::describe::Described;
use crate::describe::opencv::{OpencvLatch, Placed, Placement};
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::gray_view::GrayView;

// SAFETY: Placement is #[repr(C)] plain old data with the layout of clatch_opencv_placement (checked in
// tests).
unsafe impl DeviceRepr for Placement {}

/// Describes placed keypoints (all inside OpenCV's safe border) on the GPU.
pub(crate) fn describe_opencv(
    dev: &GpuDevice,
    image: &GrayView,
    latch: &OpencvLatch,
    placed: Placed,
) -> Result<Described> {
    let Placed {
        keypoint_index,
        skipped,
        placements,
    } = placed;
    let width = latch.width();
    if placements.is_empty() {
        return Ok(Described {
            descriptors: DescriptorSet::empty(width),
            keypoint_index,
            skipped,
        });
    }
    // Rows packed `width` apart (the blur's output already is): the kernel's row arithmetic then
    // stays within `MAX_IMAGE_SIDE²` whatever the caller's stride.
    let (w, h) = (image.width(), image.height());
    let packed: Cow<[u8]> = match latch.blurred(image) {
        Some(blurred) => Cow::Owned(blurred),
        None if image.stride() == w => Cow::Borrowed(&image.data()[..w * h]),
        None => Cow::Owned((0..h).flat_map(|y| image.row(y).iter().copied()).collect()),
    };
    let count = placements.len();
    let chunks = width.bits().div_ceil(32);
    let blocks = count
        .checked_mul(chunks * 32)
        .and_then(|t| u32::try_from(t.div_ceil(CLATCH_OPENCV_THREADS as usize)).ok())
        .filter(|_| i32::try_from(count).is_ok())
        .ok_or_else(|| Error::InvalidInput {
            what: "keypoints",
            reason: format!("{count} keypoints are too many for one launch"),
        })?;
    let stream = dev.new_stream()?;
    let device_image = upload(&stream, &packed, "image upload")?;
    let device_placements = upload(&stream, &placements, "keypoint placement upload")?;
    let mut out = alloc_zeros::<u32>(&stream, count * chunks, "descriptor allocation")?;
    let (stride, count_arg) = (w as i32, count as i32);
    let (half, bits) = (latch.half_ssd_size() as i32, width.bits() as i32);
    let kernel = kernels::DESCRIBE_OPENCV;
    let mut launch = stream.launch_builder(dev.kernel(kernel));
    launch
        .arg(&device_image)
        .arg(&stride)
        .arg(&device_placements)
        .arg(&count_arg)
        .arg(&dev.triplets)
        .arg(&half)
        .arg(&bits)
        .arg(&mut out);
    let config = LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (CLATCH_OPENCV_THREADS, 1, 1),
        shared_mem_bytes: 0,
    };
    // SAFETY: the argument list matches clatch_describe_opencv's signature; the image holds every pixel
    // the placements' patches touch (the border rule), the table 512 triplets, `out` count * chunks
    // words.
    unsafe { launch.launch(config) }.map_err(driver_error(kernel.name()))?;
    let halves = stream.clone_dtoh(&out).map_err(driver_error(
        "clatch_describe_opencv (running, or copying descriptors back)",
    ))?;
    // Triplet t is bit t % 32 of 32-bit word t / 32: the low and high halves of our 64-bit words.
    let per = width.words();
    let mut words = vec![0u64; count * per];
    for (k, row) in halves.chunks_exact(chunks).enumerate() {
        for (c, &half_word) in row.iter().enumerate() {
            words[k * per + c / 2] |= u64::from(half_word) << (32 * (c % 2));
        }
    }
    Ok(Described {
        descriptors: DescriptorSet::from_words(width, words)?,
        keypoint_index,
        skipped,
    })
}
