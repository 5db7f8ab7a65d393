//! GPU pyramid: `kernels/pyramid.cu` builds the levels, the usual detect and describe kernels run on
//! each, reproducing [`crate::pyramid::cpu`] keypoint for keypoint and bit for bit.
//!
//! Everything is queued on one stream. The global top-N over the levels ([`crate::pyramid::select`])
//! runs on the host: the levels' keypoints are read back once, the selection is uploaded per level for
//! description. So this path waits for the device in the middle; the asynchronous extractor does not
//! take a pyramid yet.

use std::sync::Arc;

use cudarc::driver::CudaStream;

use super::describe::{launch_describe, upload_weights};
use super::detect::detect_on_device;
use super::device::{GpuDevice, driver_error};
use super::memory::{alloc_zeros, upload};
use super::texture::DeviceImage;
use crate::describe::DescriptorConfig;
use crate::descriptor::DescriptorSet;
use crate::detect::DetectorConfig;
use crate::error::Result;
use crate::extractor::Features;
use crate::image::GrayView;
use crate::keypoint::KeyPoint;
use crate::pyramid::{self, LevelKeypoint, Plan, Pyramid};

/// The levels on the device and the selected keypoints (level coordinates).
struct Detected {
    stream: Arc<CudaStream>,
    plan: Plan,
    levels: Vec<DeviceImage>,
    selected: Vec<LevelKeypoint>,
}

fn detect_levels(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
    p: &Pyramid,
) -> Result<Detected> {
    let stream = dev.new_stream()?;
    let plan = Plan::new(p, image.width(), image.height(), config.margin());
    let mut levels = vec![DeviceImage::upload(dev, &stream, image)?];
    for &size in &plan.sizes[1..] {
        let next = levels
            .last()
            .expect("level 0 is there")
            .downscale(dev, &stream, plan.step, size)?;
        levels.push(next);
    }
    // Queue every level's detection before reading any back.
    let found = levels
        .iter()
        .map(|level| detect_on_device(dev, &stream, level, config))
        .collect::<Result<Vec<_>>>()?;
    let per_level = found
        .iter()
        .map(|f| f.download(&stream))
        .collect::<Result<Vec<_>>>()?;
    Ok(Detected {
        selected: pyramid::select(&per_level, config.max_keypoints),
        stream,
        plan,
        levels,
    })
}

/// The pyramid levels of `image` for a detector margin of `margin` as the GPU builds them, level 0
/// first, each row-major with stride = width: for comparing with [`crate::pyramid::cpu::build_levels`].
#[doc(hidden)]
pub fn debug_pyramid_levels(
    dev: &GpuDevice,
    image: &GrayView,
    p: &Pyramid,
    margin: usize,
) -> Result<Vec<Vec<u8>>> {
    let stream = dev.new_stream()?;
    let plan = Plan::new(p, image.width(), image.height(), margin);
    let mut level = DeviceImage::upload(dev, &stream, image)?;
    let mut out = vec![level.download(&stream)?];
    for &size in &plan.sizes[1..] {
        level = level.downscale(dev, &stream, plan.step, size)?;
        out.push(level.download(&stream)?);
    }
    Ok(out)
}

/// Multi-scale detection on the GPU: the same list as [`crate::pyramid::cpu::detect`].
pub(crate) fn pyramid_detect(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
    p: &Pyramid,
) -> Result<Vec<KeyPoint>> {
    let d = detect_levels(dev, image, config, p)?;
    Ok(d.selected
        .iter()
        .map(|k| pyramid::report(k, p, d.plan.step))
        .collect())
}

/// Multi-scale detection and description on the GPU: the same features as
/// [`crate::pyramid::cpu::detect_and_describe`].
pub(crate) fn pyramid_detect_and_describe(
    dev: &GpuDevice,
    image: &GrayView,
    detector: &DetectorConfig,
    descriptor: &DescriptorConfig,
    p: &Pyramid,
) -> Result<Features> {
    let mut d = detect_levels(dev, image, detector, p)?;
    let stream = &d.stream;
    let width = descriptor.width;
    let weights = upload_weights(stream, descriptor)?;
    let mut outputs = Vec::with_capacity(d.levels.len());
    for (l, level) in d.levels.iter_mut().enumerate() {
        let keypoints = pyramid::of_level(&d.selected, l);
        if keypoints.is_empty() {
            outputs.push(None);
            continue;
        }
        level.build_quads(dev, stream)?;
        let on_device = upload(stream, &keypoints, "pyramid keypoint upload")?;
        let count = upload(stream, &[keypoints.len() as u32], "pyramid keypoint count")?;
        let mut out = alloc_zeros(
            stream,
            keypoints.len() * width.words(),
            "pyramid descriptors",
        )?;
        // Detection's margin makes every window fit on its level, as on the CPU.
        launch_describe(
            dev,
            stream,
            level,
            (&on_device, &count),
            &weights,
            width.bits() as i32,
            &mut out,
        )?;
        outputs.push(Some(out));
    }
    let per_level = outputs
        .iter()
        .map(|out| match out {
            None => Ok(DescriptorSet::empty(width)),
            Some(out) => {
                let words = stream
                    .clone_dtoh(out)
                    .map_err(driver_error("copying pyramid descriptors back"))?;
                DescriptorSet::from_words(width, words)
            }
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Features {
        keypoints: d
            .selected
            .iter()
            .map(|k| pyramid::report(k, p, d.plan.step))
            .collect(),
        descriptors: pyramid::assemble(&d.selected, &per_level, width)?,
    })
}
