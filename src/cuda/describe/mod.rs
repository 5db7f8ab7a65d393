//! GPU description: `kernels/describe.cu`, reproducing [`crate::describe::cpu::describe`].

use std::sync::Arc;

use cudarc::driver::{
    CudaSlice, CudaStream, CudaView, CudaViewMut, DeviceRepr, LaunchConfig, PushKernelArg,
};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::{CLATCH_DESCRIBE_WARPS, CLATCH_GATHER_THREADS};
use super::image::{DeviceImage, ImageLife};
use super::kernels;
use super::memory::arena::{Lane, Leased, PinnedScratch, Scratch, settled};
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
    let lane = Leased::take(dev)?;
    let result = Job::prepare(dev, &lane, image, &selected, config).and_then(|mut job| {
        job.launch(dev)?;
        let words = selected.len() * width.words();
        let mut host = lane.pinned::<u64>(words, "descriptor read-back buffer")?;
        host.queue_download(0, &job.out.view())?;
        Ok(host.wait(words)?.to_vec())
    });
    let words = settled(&lane, result)?;
    Ok(Described {
        descriptors: DescriptorSet::from_words(width, words)?,
        keypoint_index,
        skipped,
    })
}

/// Everything one launch of `clatch_describe` on host-supplied keypoints needs, on the device.
struct Job {
    image: DeviceImage,
    keypoints: Scratch<KeyPoint>,
    count: Scratch<u32>,
    weights: DeviceWeights,
    out: Scratch<u64>,
    bits: i32,
    lane: Lane,
}

impl Job {
    /// Uploads the image and keypoints (all of which must fit) on `lane`. The image must stay valid
    /// until the work queued on `lane` has run ([`ImageLife::Work`]).
    fn prepare(
        dev: &GpuDevice,
        lane: &Lane,
        image: &GrayView,
        keypoints: &[KeyPoint],
        config: &DescriptorConfig,
    ) -> Result<Self> {
        let lane = lane.clone();
        let mut device_image = DeviceImage::upload(dev, &lane, image, ImageLife::Work)?;
        device_image.build_quads(dev, &lane, config.smoothing)?;
        let n = keypoints.len();
        let mut staged = lane.pinned::<KeyPoint>(n, "keypoint staging buffer")?;
        staged.host()?[..n].copy_from_slice(keypoints);
        let mut on_device = lane.scratch::<KeyPoint>(n, "keypoint upload")?;
        staged.queue_upload(0, &mut on_device.view_mut())?;
        let count = upload_counts(&lane, &[n])?;
        Ok(Self {
            keypoints: on_device,
            count,
            weights: weights(dev, config)?,
            out: lane.scratch(n * config.width.words(), "descriptor allocation")?,
            image: device_image,
            bits: config.width.bits() as i32,
            lane,
        })
    }

    /// Queues the kernel on the job's stream.
    fn launch(&mut self, dev: &GpuDevice) -> Result<()> {
        launch_describe(
            dev,
            &self.lane,
            &self.image,
            (&self.keypoints.view(), &self.count.view()),
            &self.weights,
            self.bits,
            &mut self.out.view_mut(),
        )
    }
}

/// `counts` as a device buffer of u32 on `lane`, through a pinned buffer (the copy is queued; the
/// pinned buffer goes back to the arena with its event, so its next user waits for the copy).
pub(crate) fn upload_counts(
    lane: &super::memory::arena::Lane,
    counts: &[usize],
) -> Result<Scratch<u32>> {
    let mut staged: PinnedScratch<u32> = lane.pinned(counts.len(), "count staging buffer")?;
    for (slot, &n) in staged.host()?.iter_mut().zip(counts) {
        *slot = n as u32;
    }
    let mut on_device = lane.scratch::<u32>(counts.len(), "keypoint count upload")?;
    staged.queue_upload(0, &mut on_device.view_mut())?;
    Ok(on_device)
}

/// The patch weights on the device, and which kernel they call for.
pub(crate) struct DeviceWeights {
    values: Arc<CudaSlice<i32>>,
    /// Every weight 0 or 1: `clatch_describe_binary` (byte masks and dp4a) applies.
    binary: bool,
}

/// The patch weights as the kernels read them: uploaded once per device and weight table
/// ([`GpuDevice::weights`]), then shared by every stream.
pub(crate) fn weights(dev: &GpuDevice, config: &DescriptorConfig) -> Result<DeviceWeights> {
    let weights: Vec<i32> = config
        .weights
        .as_array()
        .iter()
        .map(|&w| w as i32)
        .collect();
    Ok(DeviceWeights {
        values: dev.weights(weights)?,
        binary: config.weights.is_binary(),
    })
}

/// Queues `clatch_describe` on `lane`: describes the first `min(*count, keypoints.len())` keypoints
/// (all of which must fit) into `out` (at least `keypoints.len()` rows of the width's words). The
/// lane keeps the weight table alive until the kernel has run.
pub(crate) fn launch_describe(
    dev: &GpuDevice,
    lane: &Lane,
    image: &DeviceImage,
    (keypoints, count): (&CudaView<'_, KeyPoint>, &CudaView<'_, u32>),
    weights: &DeviceWeights,
    bits: i32,
    out: &mut CudaViewMut<'_, u64>,
) -> Result<()> {
    let words = (bits as usize).div_ceil(64);
    super::invariant(
        !count.is_empty() && out.len() >= keypoints.len() * words,
        "describe",
        || {
            format!(
                "{} keypoints, {} counts, {} output words of {words} per row",
                keypoints.len(),
                count.len(),
                out.len()
            )
        },
    )?;
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
        kernels::DESCRIBE_BINARY
    } else {
        kernels::DESCRIBE
    };
    let mut launch = lane.launch_builder(dev.kernel(kernel));
    launch
        .arg(&texture)
        .arg(&width)
        .arg(&height)
        .arg(keypoints)
        .arg(count)
        .arg(&capacity)
        .arg(&dev.rotation)
        .arg(&dev.triplets)
        .arg(&*weights.values)
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
    unsafe { launch.launch(config) }.map_err(driver_error(kernel.name()))?;
    lane.keep_until_passed(&weights.values)
}

/// Queues `clatch_gather_rows` on `stream`: row `r` of `dst` (`rows` rows of `words` words) becomes
/// row `source[r]` of `src`. Every source index must lie in `src` (the caller's invariant).
pub(crate) fn gather_rows(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    (src, source): (&CudaView<'_, u64>, &CudaView<'_, i32>),
    (rows, words): (usize, usize),
    dst: &mut CudaViewMut<'_, u64>,
) -> Result<()> {
    super::invariant(
        source.len() >= rows && src.len() >= rows * words && dst.len() >= rows * words,
        "gather rows",
        || {
            format!(
                "{rows} rows of {words} words from {} words by {} indices into {} words",
                src.len(),
                source.len(),
                dst.len()
            )
        },
    )?;
    if rows == 0 {
        return Ok(());
    }
    let (rows_arg, words_arg) = (rows as i32, words as i32);
    let threads = CLATCH_GATHER_THREADS as usize;
    let blocks = (rows * words)
        .div_ceil(threads)
        .min(dev.multiprocessors * BLOCKS_PER_SM) as u32;
    let mut launch = stream.launch_builder(dev.kernel(kernels::GATHER_ROWS));
    launch
        .arg(src)
        .arg(source)
        .arg(&rows_arg)
        .arg(&words_arg)
        .arg(dst);
    let config = LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (CLATCH_GATHER_THREADS, 1, 1),
        shared_mem_bytes: 0,
    };
    // SAFETY: the argument list matches clatch_gather_rows' signature; `dst` holds rows * words words
    // and `source` rows indices (checked above), each index a row of `src` (the caller's invariant:
    // a permutation of the rows it described).
    unsafe { launch.launch(config) }.map_err(driver_error("clatch_gather_rows"))?;
    Ok(())
}

#[cfg(feature = "internals")]
pub mod hooks;
