//! GPU pyramid: `kernels/pyramid.cu` builds the levels, the usual detect and describe kernels run on
//! each, reproducing [`crate::pyramid::cpu`] keypoint for keypoint and bit for bit.
//!
//! Everything is queued on one stream, every buffer from its arena ([`super::arena`]). The global
//! top-N over the levels ([`crate::pyramid::select`]) runs on the host: the levels' counts, then their
//! (unoriented) keypoints, are read back through pinned buffers (two waits for the stream), the
//! selection of every level is uploaded at once, oriented and, with [`crate::Subpixel::Score`], refined
//! (`clatch_orient_refine`, `kernels/detect.cu`: one launch for every level, and only what is kept, as
//! [`crate::pyramid::cpu`]), then described; the orientation bins and offsets are read back with the
//! descriptors (a third wait) and mapped to level 0 on the host ([`crate::pyramid::report`]). So the
//! asynchronous extractor queues the levels and their detection at once and does the rest in `wait`.

use cudarc::driver::CudaView;

use super::collection::DeviceCollection;
use super::describe::{gather_rows, launch_describe, upload_counts, weights};
use super::detect::{
    DeviceKeypoints, detect_unoriented_on_device, download_counts, launch_orient_refine,
};
use super::device::GpuDevice;
use super::image::{DeviceImage, ImageLife};
use super::memory::arena::{Lane, Leased, PinnedScratch, Scratch, settled};
use super::spans::Span;
use crate::describe::DescriptorConfig;
use crate::descriptor::DescriptorSet;
use crate::detect::{DetectorConfig, Ranking, Subpixel};
use crate::error::Result;
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;
use crate::pyramid::{self, LevelKeypoint, Plan, Pyramid};

/// The most candidates (records) whose read-back buffer is sized by the pyramid's bound (6 MiB); a
/// larger bound (a grid's: every survivor) sizes it by the count found.
const READ_BACK_BY_BOUND: usize = 1 << 18;

/// A pyramid queued on a stream: levels built and every level's detection launched, nothing read back.
#[derive(Debug)]
pub(crate) struct QueuedPyramid {
    plan: Plan,
    pyramid: Pyramid,
    config: DetectorConfig,
    levels: Vec<DeviceImage>,
    found: Vec<DeviceKeypoints>,
    lane: Lane,
}

/// Queues the levels of `image` and the detection on each on `lane` (no synchronisation); `life`
/// says how long `image` stays valid.
pub(crate) fn queue(
    dev: &GpuDevice,
    lane: &Lane,
    image: &GrayView,
    config: &DetectorConfig,
    p: &Pyramid,
    life: ImageLife,
) -> Result<QueuedPyramid> {
    let _span = Span::open(lane);
    let plan = Plan::new(p, image.width(), image.height(), config.margin());
    let candidates = config.candidates();
    // Level 0 is detected first, band by band as it arrives (a large image's copy overlaps its
    // suppression), then each level is built from the one before and detected. The order of launches
    // on the stream changes no result.
    let mut levels = vec![DeviceImage::upload(dev, lane, image, life)?];
    // Unoriented: only the selection's keypoints are oriented ([`QueuedPyramid::queue_orient_refine`]).
    let mut found = vec![detect_unoriented_on_device(
        dev,
        lane,
        &levels[0],
        &candidates,
    )?];
    for &size in &plan.sizes[1..] {
        let next = levels
            .last()
            .expect("level 0 is there")
            .downscale(dev, lane, plan.step, size)?;
        found.push(detect_unoriented_on_device(dev, lane, &next, &candidates)?);
        levels.push(next);
    }
    Ok(QueuedPyramid {
        lane: lane.clone(),
        plan,
        pyramid: *p,
        config: config.clone(),
        levels,
        found,
    })
}

/// The selected keypoints of every level on the device, one level after the other in selection order
/// ([`pyramid::of_level`]), with each level's count.
struct Selection {
    keypoints: Scratch<KeyPoint>,
    counts: Scratch<u32>,
    /// Per level: its first keypoint and how many.
    ranges: Vec<(usize, usize)>,
    total: usize,
}

impl Selection {
    /// Uploads `selected` (of `levels` levels, at most `bound` keypoints) at once through a pinned
    /// buffer.
    fn upload(
        lane: &Lane,
        selected: &[LevelKeypoint],
        levels: usize,
        bound: usize,
    ) -> Result<Self> {
        let per_level: Vec<Vec<KeyPoint>> = (0..levels)
            .map(|l| pyramid::of_level(selected, l))
            .collect();
        let total: usize = per_level.iter().map(Vec::len).sum();
        super::invariant(total <= bound, "pyramid selection", || {
            format!("{total} keypoints selected of at most {bound} found")
        })?;
        let mut staged = lane.pinned::<KeyPoint>(bound, "keypoint staging buffer")?;
        let host = staged.host()?;
        let mut ranges = Vec::with_capacity(levels);
        let mut at = 0;
        for keypoints in &per_level {
            host[at..at + keypoints.len()].copy_from_slice(keypoints);
            ranges.push((at, keypoints.len()));
            at += keypoints.len();
        }
        let mut keypoints = lane.scratch::<KeyPoint>(bound, "pyramid keypoint upload")?;
        staged.queue_upload(0, &mut keypoints.whole_mut().slice_mut(..total))?;
        let counts: Vec<usize> = ranges.iter().map(|&(_, n)| n).collect();
        Ok(Self {
            keypoints,
            counts: upload_counts(lane, &counts)?,
            ranges,
            total,
        })
    }

    /// Level `l`'s keypoints on the device.
    fn of_level(&self, l: usize) -> CudaView<'_, KeyPoint> {
        let (at, n) = self.ranges[l];
        self.keypoints.whole().slice(at..at + n)
    }
}

impl QueuedPyramid {
    /// The most keypoints the levels can hold together: what buffers whose need depends on the image's
    /// content are sized by, so that images of one size and configuration reuse them whatever they
    /// show.
    fn bound(&self) -> usize {
        self.found.iter().map(|f| f.capacity).sum()
    }

    /// The most keypoints a selection holds: [`Self::bound`], or the budget when smaller (it always is
    /// with [`DetectorConfig::grid`], whose candidates are every survivor: up to a quarter of each
    /// level's pixels). What the selection's buffers (descriptors, offsets) are sized by, so that
    /// they stay those of the budget, not hundreds of megabytes a photo.
    fn selection_bound(&self) -> usize {
        self.bound().min(self.config.max_keypoints)
    }

    /// Reads every level's keypoints back (waits for the stream) and keeps the strongest over all.
    fn select(&self) -> Result<Vec<LevelKeypoint>> {
        let found: Vec<&DeviceKeypoints> = self.found.iter().collect();
        let counts = download_counts(&self.lane, &found)?;
        let total = counts.iter().sum();
        // Sized by `bound()`, so that images of one size and configuration reuse it whatever they
        // show, unless that is large: with a grid every survivor is a candidate and the bound is a
        // quarter of the pixels (about 100 MB of page-locked memory for a 6-megapixel photo, whose
        // allocation cost more than the photo's detection). Then by what was found: the arena rounds
        // the size up, so photos of similar content reuse it.
        let capacity = if self.bound() <= READ_BACK_BY_BOUND {
            self.bound()
        } else {
            total
        };
        let mut host = self
            .lane
            .pinned::<KeyPoint>(capacity, "keypoint read-back buffer")?;
        let mut at = 0;
        for (f, &n) in self.found.iter().zip(&counts) {
            host.queue_download(at, &f.records().slice(..n))?;
            at += n;
        }
        let all = host.wait(total)?;
        let mut per_level = Vec::with_capacity(counts.len());
        let mut at = 0;
        for &n in &counts {
            per_level.push(all[at..at + n].to_vec());
            at += n;
        }
        // Harris ranking reads the levels' pixels: computed on the host from the levels read back,
        // by the CPU's own function, so both backends rank alike. (A kernel would save the copy.)
        let pixels = match self.config.ranking {
            Ranking::Fast => Vec::new(),
            Ranking::Harris => self
                .levels
                .iter()
                .map(|level| level.download(&self.lane))
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

    /// Queues, in one launch for every level (`clatch_orient_refine` through
    /// [`launch_orient_refine`]), the orientation of every level's selected keypoints, reproducing
    /// [`crate::detect::cpu::orientation`], which [`crate::pyramid::cpu`] applies after selection:
    /// into the selection's records, for the describe kernel, and as bins, in selection order, for the
    /// host; and when [`DetectorConfig::subpixel`] refines positions, their sub-pixel offsets,
    /// reproducing [`crate::detect::cpu::subpixel_offset`]: `[dx, dy]` per keypoint, in selection
    /// order. Orientation and descriptor stay those of the whole pixel; only the position moves.
    fn queue_orient_refine(
        &self,
        dev: &GpuDevice,
        selection: &mut Selection,
    ) -> Result<(Scratch<i32>, Option<Scratch<i32>>)> {
        let bound = self.selection_bound();
        let mut bins = self.lane.scratch::<i32>(bound, "orientation bins")?;
        let mut offsets = match self.config.subpixel {
            Subpixel::None => None,
            _ => Some(self.lane.scratch::<i32>(2 * bound, "sub-pixel offsets")?),
        };
        let levels: Vec<(&DeviceImage, usize)> = self
            .levels
            .iter()
            .zip(&selection.ranges)
            .map(|(level, &(_, n))| (level, n))
            .collect();
        let total = selection.total;
        launch_orient_refine(
            dev,
            &self.lane,
            &levels,
            &mut selection.keypoints.whole_mut().slice_mut(..total),
            &mut bins.whole_mut().slice_mut(..total),
            offsets
                .as_mut()
                .map(|o| o.whole_mut().slice_mut(..2 * total))
                .as_mut(),
        )?;
        Ok((bins, offsets))
    }

    /// Queues the read-back of the orientation bins and, when refining, the offsets, through pinned
    /// buffers of the lane (the offsets last: waiting for them waits for everything before).
    fn queue_readback(
        &self,
        selection: &Selection,
        bins: &Scratch<i32>,
        offsets: Option<&Scratch<i32>>,
    ) -> Result<ReadBack> {
        let total = selection.total;
        let bound = self.selection_bound();
        let mut host_bins = self
            .lane
            .pinned::<i32>(bound, "orientation read-back buffer")?;
        host_bins.queue_download(0, &bins.whole().slice(..total))?;
        let host_offsets = match offsets {
            Some(offsets) => {
                let mut host = self
                    .lane
                    .pinned::<i32>(2 * bound, "offset read-back buffer")?;
                host.queue_download(0, &offsets.whole().slice(..2 * total))?;
                Some(host)
            }
            None => None,
        };
        Ok(ReadBack {
            bins: host_bins,
            offsets: host_offsets,
        })
    }

    /// The selected keypoints in level-0 coordinates, oriented and refined by
    /// [`DetectorConfig::subpixel`] (waits for the stream).
    pub(crate) fn keypoints(self, dev: &GpuDevice) -> Result<Vec<KeyPoint>> {
        let mut selected = self.select()?;
        let mut selection = Selection::upload(
            &self.lane,
            &selected,
            self.levels.len(),
            self.selection_bound(),
        )?;
        let (bins, offsets) = self.queue_orient_refine(dev, &mut selection)?;
        self.queue_readback(&selection, &bins, offsets.as_ref())?
            .apply(&mut selected, &selection)?;
        Ok(self.report(&selected))
    }

    /// Queues the description of `selected` on every level, then their sub-pixel offsets: where both
    /// ends, [`QueuedPyramid::features`] (to the host) and [`QueuedPyramid::features_into`] (into a
    /// device collection), start. Nothing is waited for.
    fn describe(
        &mut self,
        dev: &GpuDevice,
        descriptor: &DescriptorConfig,
        selected: Vec<LevelKeypoint>,
    ) -> Result<Described> {
        let lane = self.lane.clone();
        let words = descriptor.width.words();
        let weights = weights(dev, descriptor)?;
        let bound = self.selection_bound();
        let mut selection = Selection::upload(&lane, &selected, self.levels.len(), bound)?;
        // Oriented before they are described (same stream).
        let (bins, offsets) = self.queue_orient_refine(dev, &mut selection)?;
        let mut out = lane.scratch::<u64>(bound * words, "pyramid descriptors")?;
        for (l, level) in self.levels.iter_mut().enumerate() {
            // Every level's quad texture, even one without selected keypoints: the buffers a call
            // takes then depend on the image's size, not on what it shows, so a warm stream serves
            // every image of that size without allocating.
            level.build_quads(dev, &lane, descriptor.smoothing)?;
            let (at, n) = selection.ranges[l];
            if n == 0 {
                continue;
            }
            // Detection's margin makes every window fit on its level, as on the CPU.
            launch_describe(
                dev,
                &lane,
                level,
                (
                    &selection.of_level(l),
                    &selection.counts.whole().slice(l..l + 1),
                ),
                &weights,
                descriptor.width.bits() as i32,
                &mut out.whole_mut().slice_mut(at * words..(at + n) * words),
            )?;
        }
        Ok(Described {
            selected,
            selection,
            out,
            bins,
            offsets,
        })
    }

    /// [`Self::queue_readback`] of what `described` computed.
    fn queue_described_readback(&self, described: &Described) -> Result<ReadBack> {
        self.queue_readback(
            &described.selection,
            &described.bins,
            described.offsets.as_ref(),
        )
    }

    /// Describes the selected keypoints on their levels and reads everything back (waits for the
    /// stream once more).
    pub(crate) fn features(
        mut self,
        dev: &GpuDevice,
        descriptor: &DescriptorConfig,
    ) -> Result<Features> {
        let selected = self.select()?;
        let lane = self.lane.clone();
        let width = descriptor.width;
        let words = width.words();
        // The device works from here to the read-backs without waiting for the host.
        let span = Span::open(&lane);
        let described = self.describe(dev, descriptor, selected)?;
        let total = described.selection.total;
        let mut host_words = lane.pinned::<u64>(
            self.selection_bound() * words,
            "descriptor read-back buffer",
        )?;
        host_words.queue_download(0, &described.out.whole().slice(..total * words))?;
        let readback = self.queue_described_readback(&described)?;
        drop(span);
        let Described {
            mut selected,
            selection,
            ..
        } = described;
        // One wait: the bins and offsets were queued last, so waiting for them waits for everything.
        readback.apply(&mut selected, &selection)?;
        let all_words = host_words.wait(total * words)?;
        let per_level = selection
            .ranges
            .iter()
            .map(|&(at, n)| {
                if n == 0 {
                    Ok(DescriptorSet::empty(width))
                } else {
                    DescriptorSet::from_words(
                        width,
                        all_words[at * words..(at + n) * words].to_vec(),
                    )
                }
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Features::all(
            self.report(&selected),
            pyramid::assemble(&selected, &per_level, width)?,
        ))
    }

    /// Describes the selected keypoints on their levels and puts the descriptors, in the reported
    /// keypoint order ([`pyramid::assemble`]'s), into `collection` as its next set without a host
    /// copy: `clatch_gather_rows` writes them from this stream straight into the collection's buffer,
    /// ordered against the collection's stream by events. Returns the keypoints (waits for the
    /// stream once more when refining positions, to read the offsets back).
    pub(crate) fn features_into(
        mut self,
        dev: &GpuDevice,
        descriptor: &DescriptorConfig,
        collection: &mut DeviceCollection,
    ) -> Result<Vec<KeyPoint>> {
        let selected = self.select()?;
        let lane = self.lane.clone();
        let words = descriptor.width.words();
        let span = Span::open(&lane);
        let described = self.describe(dev, descriptor, selected)?;
        let total = described.selection.total;
        // Row r of the set is the next row of its keypoint's level, as `assemble` takes them.
        let mut next: Vec<usize> = described.selection.ranges.iter().map(|r| r.0).collect();
        let mut staged =
            lane.pinned::<i32>(self.selection_bound().max(1), "row order staging buffer")?;
        for (slot, k) in staged.host()?.iter_mut().zip(&described.selected) {
            *slot = next[k.level] as i32;
            next[k.level] += 1;
        }
        let mut order = lane.scratch::<i32>(self.selection_bound().max(1), "row order upload")?;
        staged.queue_upload(0, &mut order.whole_mut().slice_mut(..total))?;
        collection.append_rows(&lane, total, |target| {
            gather_rows(
                dev,
                &lane,
                (&described.out.whole().slice(..total * words), &order.view()),
                (total, words),
                target,
            )
        })?;
        let readback = self.queue_described_readback(&described)?;
        drop(span);
        let Described {
            mut selected,
            selection,
            ..
        } = described;
        readback.apply(&mut selected, &selection)?;
        Ok(self.report(&selected))
    }
}

/// The selected keypoints of a queued pyramid, their description and sub-pixel offsets queued.
struct Described {
    selected: Vec<LevelKeypoint>,
    selection: Selection,
    /// The descriptors in selection order, level after level (`selection.ranges`).
    out: Scratch<u64>,
    /// The orientation bins, in the same order.
    bins: Scratch<i32>,
    offsets: Option<Scratch<i32>>,
}

/// The orientation bins and (when refining) sub-pixel offsets of a selection, being copied back.
struct ReadBack {
    bins: PinnedScratch<i32>,
    offsets: Option<PinnedScratch<i32>>,
}

impl ReadBack {
    /// Waits for the copies and gives each selected keypoint its angle and offset.
    fn apply(mut self, selected: &mut [LevelKeypoint], selection: &Selection) -> Result<()> {
        let total = selection.total;
        // The offsets were queued last: waiting for them first waits for both.
        if let Some(host) = &mut self.offsets {
            per_selected(selected, selection, host.wait(2 * total)?, 2, |k, pair| {
                k.offset = [pair[0], pair[1]];
            });
        }
        per_selected(selected, selection, self.bins.wait(total)?, 1, |k, bin| {
            k.keypoint.angle = crate::angle::bin_degrees(bin[0] as usize);
        });
        Ok(())
    }
}

/// Hands each level's values (`flat`: `per` values per keypoint of `selection`, level after level) to
/// that level's selected keypoints, in selection order (the order they were uploaded in).
fn per_selected(
    selected: &mut [LevelKeypoint],
    selection: &Selection,
    flat: &[i32],
    per: usize,
    mut set: impl FnMut(&mut LevelKeypoint, &[i32]),
) {
    for (l, &(at, n)) in selection.ranges.iter().enumerate() {
        let of_level = selected.iter_mut().filter(|k| k.level == l);
        for (k, values) in of_level.zip(flat[per * at..per * (at + n)].chunks_exact(per)) {
            set(k, values);
        }
    }
}

/// Multi-scale detection on the GPU: the same list as [`crate::pyramid::cpu::detect`].
pub(crate) fn pyramid_detect(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
    p: &Pyramid,
) -> Result<Vec<KeyPoint>> {
    let lane = Leased::take(dev)?;
    let result = queue(dev, &lane, image, config, p, ImageLife::Work)
        .and_then(|queued| queued.keypoints(dev));
    settled(&lane, result)
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
    let lane = Leased::take(dev)?;
    let result = queue(dev, &lane, image, detector, p, ImageLife::Work)
        .and_then(|queued| queued.features(dev, descriptor));
    settled(&lane, result)
}

#[cfg(feature = "internals")]
pub mod hooks;
