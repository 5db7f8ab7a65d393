//! GPU pyramid: `kernels/pyramid.cu` builds the levels, the usual detect and describe kernels run on
//! each, reproducing [`crate::pyramid::cpu`] keypoint for keypoint and bit for bit.
//!
//! Everything is queued on one stream. The global top-N over the levels ([`crate::pyramid::select`])
//! runs on the host: the levels' keypoints are read back once, the selection is uploaded per level for
//! description and, with [`crate::Subpixel::Score`], for `clatch_subpixel` (`kernels/detect.cu`),
//! whose offsets are read back with the descriptors and mapped to level 0 on the host
//! ([`crate::pyramid::report`]). So the asynchronous extractor queues the levels and their detection at
//! once and does the rest in `wait`.

use std::sync::Arc;

use cudarc::driver::{CudaSlice, CudaStream};

use super::describe::{launch_describe, upload_weights};
use super::detect::{DeviceKeypoints, detect_on_device, launch_subpixel};
use super::device::{GpuDevice, driver_error};
use super::memory::{alloc_zeros, upload};
use super::texture::DeviceImage;
use crate::describe::DescriptorConfig;
use crate::descriptor::DescriptorSet;
use crate::detect::{DetectorConfig, Ranking, Subpixel};
use crate::error::Result;
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;
use crate::pyramid::{self, LevelKeypoint, Plan, Pyramid};

/// A pyramid queued on a stream: levels built and every level's detection launched, nothing read back.
#[derive(Debug)]
pub(crate) struct QueuedPyramid {
    stream: Arc<CudaStream>,
    plan: Plan,
    pyramid: Pyramid,
    config: DetectorConfig,
    levels: Vec<DeviceImage>,
    found: Vec<DeviceKeypoints>,
}

/// Queues the levels of `image` and the detection on each on `stream` (no synchronisation).
pub(crate) fn queue(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    image: &GrayView,
    config: &DetectorConfig,
    p: &Pyramid,
) -> Result<QueuedPyramid> {
    let plan = Plan::new(p, image.width(), image.height(), config.margin());
    let mut levels = vec![DeviceImage::upload(dev, stream, image)?];
    for &size in &plan.sizes[1..] {
        let next = levels
            .last()
            .expect("level 0 is there")
            .downscale(dev, stream, plan.step, size)?;
        levels.push(next);
    }
    let candidates = config.candidates();
    let found = levels
        .iter()
        .map(|level| detect_on_device(dev, stream, level, &candidates))
        .collect::<Result<Vec<_>>>()?;
    Ok(QueuedPyramid {
        stream: stream.clone(),
        plan,
        pyramid: *p,
        config: config.clone(),
        levels,
        found,
    })
}

impl QueuedPyramid {
    /// Reads every level's keypoints back (waits for the stream) and keeps the strongest over all.
    fn select(&self) -> Result<Vec<LevelKeypoint>> {
        let per_level = self
            .found
            .iter()
            .map(|f| f.download(&self.stream))
            .collect::<Result<Vec<_>>>()?;
        // Harris ranking reads the levels' pixels: computed on the host from the levels read back,
        // by the CPU's own function, so both backends rank alike. (A kernel would save the copy.)
        let pixels = match self.config.ranking {
            Ranking::Fast => Vec::new(),
            Ranking::Harris => self
                .levels
                .iter()
                .map(|level| level.download(&self.stream))
                .collect::<Result<Vec<_>>>()?,
        };
        let views = pixels
            .iter()
            .zip(&self.plan.sizes)
            .map(|(p, &(w, h))| GrayView::new(p, w, h, w))
            .collect::<Result<Vec<_>>>()?;
        let rank = |level: usize, k: &KeyPoint| match self.config.ranking {
            Ranking::Fast => pyramid::fast_rank(level, k),
            Ranking::Harris => {
                crate::detect::cpu::harris_response(&views[level], k.x as usize, k.y as usize)
            }
        };
        Ok(pyramid::select(
            &per_level,
            &self.plan.sizes,
            self.plan.scale_factor(),
            &self.config,
            &rank,
        ))
    }

    fn report(&self, selected: &[LevelKeypoint]) -> Vec<KeyPoint> {
        selected
            .iter()
            .map(|k| pyramid::report(k, &self.pyramid, self.plan.step))
            .collect()
    }

    /// The selected keypoints in level-0 coordinates, refined by [`DetectorConfig::subpixel`] (waits
    /// for the stream).
    pub(crate) fn keypoints(self, dev: &GpuDevice) -> Result<Vec<KeyPoint>> {
        let mut selected = self.select()?;
        if self.config.subpixel != Subpixel::None {
            let mut offsets = Vec::with_capacity(self.levels.len());
            for (l, level) in self.levels.iter().enumerate() {
                let keypoints = pyramid::of_level(&selected, l);
                if keypoints.is_empty() {
                    offsets.push(None);
                    continue;
                }
                let on_device = upload(&self.stream, &keypoints, "pyramid keypoint upload")?;
                offsets.push(queue_offsets(
                    dev,
                    &self.stream,
                    level,
                    self.config.subpixel,
                    (&on_device, keypoints.len()),
                )?);
            }
            apply_offsets(&self.stream, &mut selected, &offsets)?;
        }
        Ok(self.report(&selected))
    }

    /// Describes the selected keypoints on their levels and reads everything back.
    pub(crate) fn features(
        mut self,
        dev: &GpuDevice,
        descriptor: &DescriptorConfig,
    ) -> Result<Features> {
        let mut selected = self.select()?;
        let stream = &self.stream;
        let width = descriptor.width;
        let weights = upload_weights(stream, descriptor)?;
        let mut outputs = Vec::with_capacity(self.levels.len());
        let mut offsets = Vec::with_capacity(self.levels.len());
        for (l, level) in self.levels.iter_mut().enumerate() {
            let keypoints = pyramid::of_level(&selected, l);
            if keypoints.is_empty() {
                outputs.push(None);
                offsets.push(None);
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
            // Orientation and descriptor stay those of the whole pixel; only the position moves.
            offsets.push(queue_offsets(
                dev,
                stream,
                level,
                self.config.subpixel,
                (&on_device, keypoints.len()),
            )?);
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
        apply_offsets(stream, &mut selected, &offsets)?;
        Ok(Features::all(
            self.report(&selected),
            pyramid::assemble(&selected, &per_level, width)?,
        ))
    }
}

/// Queues the sub-pixel offsets of one level's selected keypoints (`count` of them, already on the
/// device) when `subpixel` refines positions: `clatch_subpixel` through
/// [`launch_subpixel`], which reproduces [`crate::detect::cpu::subpixel_offset`], as
/// [`crate::pyramid::cpu`] applies it after selection.
fn queue_offsets(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    level: &DeviceImage,
    subpixel: Subpixel,
    (keypoints, count): (&CudaSlice<KeyPoint>, usize),
) -> Result<Option<CudaSlice<i32>>> {
    if subpixel == Subpixel::None || count == 0 {
        return Ok(None);
    }
    let mut offsets = alloc_zeros(stream, 2 * count, "sub-pixel offsets")?;
    launch_subpixel(dev, stream, level, keypoints, count, &mut offsets)?;
    Ok(Some(offsets))
}

/// Reads each level's offsets back (waits for the stream) and gives them to that level's selected
/// keypoints, in selection order (the order they were uploaded in, [`pyramid::of_level`]).
fn apply_offsets(
    stream: &Arc<CudaStream>,
    selected: &mut [LevelKeypoint],
    per_level: &[Option<CudaSlice<i32>>],
) -> Result<()> {
    for (l, offsets) in per_level.iter().enumerate() {
        let Some(offsets) = offsets else {
            continue;
        };
        let flat = stream
            .clone_dtoh(offsets)
            .map_err(driver_error("copying sub-pixel offsets back"))?;
        let of_level = selected.iter_mut().filter(|k| k.level == l);
        for (k, pair) in of_level.zip(flat.chunks_exact(2)) {
            k.offset = [pair[0], pair[1]];
        }
    }
    Ok(())
}

/// Multi-scale detection on the GPU: the same list as [`crate::pyramid::cpu::detect`].
pub(crate) fn pyramid_detect(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
    p: &Pyramid,
) -> Result<Vec<KeyPoint>> {
    queue(dev, &dev.new_stream()?, image, config, p)?.keypoints(dev)
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
    queue(dev, &dev.new_stream()?, image, detector, p)?.features(dev, descriptor)
}

#[cfg(feature = "internals")]
pub mod hooks;
