//! GPU detection: `kernels/detect.cu`, reproducing [`crate::detect::cpu::detect`] keypoint for keypoint
//! (position, score, angle and order, ties included).
//!
//! All stages run on one stream with no host round trip between them: score + suppression (kept map and
//! per-(score, row) survivor counts), an exclusive scan of the counts in (score descending, row
//! ascending) order, which gives every (score, row) its first output position, a scatter that ranks
//! equal scores within a row left to right, and the orientation of the kept keypoints. The output stays
//! on the device ([`DeviceKeypoints`]) until the caller reads it back, so a GPU `detect_and_describe`
//! can hand it to the describe kernel together with the same [`DeviceImage`]. An image large enough
//! to be uploaded in bands on its lane's copy stream ([`DeviceImage::arrivals`]) is suppressed band by
//! band as the bands arrive, so the copy of the rest overlaps the suppression of the first rows; the
//! stages after suppression wait for the whole image.

use std::sync::Arc;

use cudarc::driver::{
    CudaEvent, CudaStream, CudaView, CudaViewMut, DeviceRepr, LaunchConfig, PushKernelArg,
    ValidAsZeroBits,
};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::{
    CLATCH_DETECT_ROW_ALIGN, CLATCH_DETECT_TILE_X, CLATCH_DETECT_TILE_Y, CLATCH_DETECT_WARPS,
    CLATCH_MAX_LEVELS, CLATCH_SCAN_CHUNK, CLATCH_SCAN_THREADS, CLATCH_SCAN_TOP_THREADS,
    clatch_levels,
};
use super::image::{DeviceImage, ImageLife};
use super::kernels;
use super::memory::arena::{Lane, Leased, Scratch, settled};
use crate::detect::DetectorConfig;
use crate::error::Result;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;

// SAFETY: KeyPoint is #[repr(C)] f32s and an i32; all-zero bits are a valid value.
unsafe impl ValidAsZeroBits for KeyPoint {}

/// Rows `clatch_detect_nms` reads past a tile on each side (`kernels/detect.cu`: IMAGE_H is
/// TILE_Y + 8, from 4 rows above the tile): a tile row can be scored once its rows and this many more
/// have arrived.
const NMS_HALO: usize = 4;

/// Distinct scores a survivor can have (1..=255): the counts have this many rows per image row.
const SCORES: usize = 255;
/// Orientation blocks per multiprocessor (grid-stride over the keypoints).
const ORIENT_BLOCKS_PER_SM: usize = 8;

/// Detected keypoints on the device.
#[derive(Debug)]
pub(crate) struct DeviceKeypoints {
    /// `capacity` records (at least one); the first `min(total, capacity)` are the result, in the
    /// CPU's order.
    pub(crate) keypoints: Scratch<KeyPoint>,
    /// One value: how many corners survived suppression (before the top-N cut).
    pub(crate) total: Scratch<u32>,
    /// `min(max_keypoints, the most survivors the image can have)`.
    pub(crate) capacity: usize,
}

impl DeviceKeypoints {
    /// The `capacity` output records.
    pub(crate) fn records(&self) -> CudaView<'_, KeyPoint> {
        self.keypoints.whole().slice(..self.capacity.max(1))
    }

    /// Copies the result to the host through `lane`'s pinned buffers (waits for the stream twice:
    /// the count, then the records).
    pub(crate) fn download(&self, lane: &Lane) -> Result<Vec<KeyPoint>> {
        let count = download_counts(lane, &[self])?[0];
        let mut host = lane.pinned::<KeyPoint>(self.capacity, "keypoint read-back buffer")?;
        host.queue_download(0, &self.records().slice(..count))?;
        Ok(host.wait(count)?.to_vec())
    }
}

/// How many keypoints each of `found` holds, `min(total, capacity)`, read back through one pinned
/// buffer with one wait for the stream.
pub(crate) fn download_counts(lane: &Lane, found: &[&DeviceKeypoints]) -> Result<Vec<usize>> {
    let mut totals = lane.pinned::<u32>(found.len(), "count read-back buffer")?;
    for (i, f) in found.iter().enumerate() {
        totals.queue_download(i, &f.total.view())?;
    }
    let totals = totals.wait(found.len())?;
    Ok(found
        .iter()
        .zip(totals)
        .map(|(f, &t)| (t as usize).min(f.capacity))
        .collect())
}

/// Launch geometry of one image size and configuration.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    width: usize,
    height: usize,
    margin: usize,
    /// Row pitch of the kept map (a multiple of CLATCH_DETECT_ROW_ALIGN).
    pitch: usize,
    capacity: usize,
    /// Rows that can hold a corner: `margin .. height - margin`.
    inner_rows: usize,
}

impl Geometry {
    fn new(width: usize, height: usize, config: &DetectorConfig) -> Self {
        let margin = config.margin();
        let inner_cols = width.saturating_sub(2 * margin);
        let inner_rows = height.saturating_sub(2 * margin);
        // Two survivors are never 8-neighbours (each would have to beat the other), so every 2x2 block
        // of the scored area holds at most one.
        let most = inner_cols.div_ceil(2) * inner_rows.div_ceil(2);
        let align = CLATCH_DETECT_ROW_ALIGN as usize;
        Self {
            width,
            height,
            margin,
            pitch: width.div_ceil(align) * align,
            capacity: config.max_keypoints.min(most),
            inner_rows,
        }
    }

    fn counts(&self) -> usize {
        SCORES * self.height
    }

    fn scan_blocks(&self) -> usize {
        self.counts().div_ceil(CLATCH_SCAN_CHUNK as usize)
    }
}

/// The detector's stages, in launch order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    Suppress,
    Scan,
    Scatter,
    Orient,
}

/// The device buffers of one detection, and the launches that fill them.
struct DetectJob {
    geometry: Geometry,
    threshold: i32,
    size: f32,
    kept: Scratch<u8>,
    counts: Scratch<u32>,
    partials: Scratch<u32>,
    output: DeviceKeypoints,
}

impl DetectJob {
    /// Takes everything for an image of `width` x `height` from `lane`'s arena.
    fn new(lane: &Lane, width: usize, height: usize, config: &DetectorConfig) -> Result<Self> {
        let geometry = Geometry::new(width, height, config);
        Ok(Self {
            threshold: config.threshold as i32,
            size: config.keypoint_size,
            kept: lane.scratch(geometry.pitch * height, "detection: kept map")?,
            counts: lane.scratch(geometry.counts(), "detection: survivor counts")?,
            partials: lane.scratch(geometry.scan_blocks(), "detection: scan partials")?,
            output: DeviceKeypoints {
                keypoints: lane.scratch(geometry.capacity.max(1), "detection: keypoint output")?,
                total: lane.scratch(1, "detection: survivor total")?,
                capacity: geometry.capacity,
            },
            geometry,
        })
    }

    /// Queues the whole detector on `stream` (no synchronisation, no host round trip).
    fn launch(
        &mut self,
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        image: &DeviceImage,
    ) -> Result<()> {
        self.launch_stages(dev, stream, image, Stage::Orient)
    }

    /// Queues the stages up to and including `last`.
    fn launch_stages(
        &mut self,
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        image: &DeviceImage,
        last: Stage,
    ) -> Result<()> {
        let g = self.geometry;
        super::invariant(
            (image.width(), image.height()) == (g.width, g.height),
            "detection",
            || {
                format!(
                    "a {}x{} image for {}x{} buffers",
                    image.width(),
                    image.height(),
                    g.width,
                    g.height
                )
            },
        )?;
        let texture = image.texture();
        let (width, height, margin) = (g.width as i32, g.height as i32, g.margin as i32);
        let pitch = g.pitch as i32;
        let counts_len = g.counts() as u32;
        let scan_blocks = g.scan_blocks() as u32;
        let capacity = g.capacity as u32;

        // Only the first `counts()` are used: clear those (the buffer may be larger, and holds the
        // last call's offsets).
        stream
            .memset_zeros(&mut self.counts.view_mut())
            .map_err(driver_error("detection: clearing the counts"))?;

        let tile = (CLATCH_DETECT_TILE_X as usize, CLATCH_DETECT_TILE_Y as usize);
        let tile_rows = g.height.div_ceil(tile.1);
        // One launch per band of the image as it arrives (one launch when it is all there): a tile row
        // is scored once every row it reads, NMS_HALO past its own, has arrived.
        let arrivals = image.arrivals();
        let steps: Vec<(usize, Option<&CudaEvent>)> = if arrivals.is_empty() {
            vec![(g.height, None)]
        } else {
            arrivals.iter().map(|(rows, e)| (*rows, Some(e))).collect()
        };
        let mut done = 0usize;
        for (rows, arrived) in steps {
            if let Some(event) = arrived {
                stream
                    .wait(event)
                    .map_err(driver_error("detection: waiting for a band of the image"))?;
            }
            let ready = if rows >= g.height {
                tile_rows
            } else {
                (rows.saturating_sub(NMS_HALO) / tile.1).min(tile_rows)
            };
            if ready <= done {
                continue;
            }
            let first_tile_row = done as i32;
            let mut nms = stream.launch_builder(dev.kernel(kernels::DETECT_NMS));
            nms.arg(&texture)
                .arg(&width)
                .arg(&height)
                .arg(&margin)
                .arg(&self.threshold)
                .arg(self.kept.whole_mut())
                .arg(&pitch)
                .arg(self.counts.whole_mut())
                .arg(&first_tile_row);
            let config = LaunchConfig {
                grid_dim: ((g.pitch / tile.0) as u32, (ready - done) as u32, 1),
                block_dim: (tile.0 as u32, tile.1 as u32, 1),
                shared_mem_bytes: 0,
            };
            // SAFETY: arguments match the kernel's signature; the launches together cover exactly
            // `pitch` x `height` once (tile rows `done..ready` here; rows past the image return) and
            // write every byte of it, within `kept` (at least that size: a reused buffer's stale bytes
            // are all overwritten); counts holds at least 255 x height. The texels these tile rows
            // read (their rows and NMS_HALO below, clamped at the image) have arrived: the stream
            // waited for their band above.
            unsafe { nms.launch(config) }.map_err(driver_error("launching clatch_detect_nms"))?;
            done = ready;
        }
        super::invariant(done == tile_rows, "detection", || {
            format!("{done} of {tile_rows} tile rows suppressed")
        })?;
        if last == Stage::Suppress {
            return Ok(());
        }

        let scan = |blocks: u32, threads: u32| LaunchConfig {
            grid_dim: (blocks, 1, 1),
            block_dim: (threads, 1, 1),
            shared_mem_bytes: 0,
        };
        let mut reduce = stream.launch_builder(dev.kernel(kernels::SCAN_REDUCE));
        reduce
            .arg(self.counts.whole())
            .arg(&counts_len)
            .arg(self.partials.whole_mut());
        // SAFETY: one partial per block of CLATCH_SCAN_CHUNK counts (partials holds at least
        // scan_blocks); reads are bounded by counts_len, at most the counts buffer's length.
        unsafe { reduce.launch(scan(scan_blocks, CLATCH_SCAN_THREADS)) }
            .map_err(driver_error("launching clatch_scan_reduce"))?;

        let mut partials = stream.launch_builder(dev.kernel(kernels::SCAN_PARTIALS));
        partials
            .arg(self.partials.whole_mut())
            .arg(&scan_blocks)
            .arg(self.output.total.whole_mut());
        // SAFETY: one block scans the scan_blocks partials in place and writes the one total.
        unsafe { partials.launch(scan(1, CLATCH_SCAN_TOP_THREADS)) }
            .map_err(driver_error("launching clatch_scan_partials"))?;

        let mut apply = stream.launch_builder(dev.kernel(kernels::SCAN_APPLY));
        apply
            .arg(self.counts.whole_mut())
            .arg(&counts_len)
            .arg(self.partials.whole());
        // SAFETY: as clatch_scan_reduce.
        unsafe { apply.launch(scan(scan_blocks, CLATCH_SCAN_THREADS)) }
            .map_err(driver_error("launching clatch_scan_apply"))?;
        if last == Stage::Scan {
            return Ok(());
        }

        let warps = CLATCH_DETECT_WARPS as usize;
        let mut scatter = stream.launch_builder(dev.kernel(kernels::DETECT_SCATTER));
        scatter
            .arg(self.kept.whole())
            .arg(&pitch)
            .arg(&height)
            .arg(&margin)
            .arg(self.counts.whole_mut())
            .arg(&capacity)
            .arg(&self.size)
            .arg(self.output.keypoints.whole_mut());
        // SAFETY: one warp per row of the scored area (extra warps return); rows are `pitch` bytes, a
        // multiple of 128, all written by clatch_detect_nms above; writes go only to positions below
        // capacity, within the output (at least capacity records).
        unsafe {
            scatter.launch(scan(
                g.inner_rows.div_ceil(warps).max(1) as u32,
                (warps * 32) as u32,
            ))
        }
        .map_err(driver_error("launching clatch_detect_scatter"))?;
        if last == Stage::Scatter {
            return Ok(());
        }

        let orient_blocks = g
            .capacity
            .div_ceil(warps)
            .clamp(1, dev.multiprocessors * ORIENT_BLOCKS_PER_SM);
        let mut orient = stream.launch_builder(dev.kernel(kernels::DETECT_ORIENT));
        orient
            .arg(&texture)
            .arg(self.output.total.whole())
            .arg(&capacity)
            .arg(&dev.boundaries)
            .arg(self.output.keypoints.whole_mut());
        // SAFETY: reads and writes the first min(total, capacity) records; the boundary table holds
        // 720 (x, y) pairs.
        unsafe { orient.launch(scan(orient_blocks as u32, (warps * 32) as u32)) }
            .map_err(driver_error("launching clatch_detect_orient"))?;
        Ok(())
    }
}

/// Runs the detector on an image already on the device; the result stays there. Everything is queued
/// on `lane` (the one `image` was uploaded on).
pub(crate) fn detect_on_device(
    dev: &GpuDevice,
    lane: &Lane,
    image: &DeviceImage,
    config: &DetectorConfig,
) -> Result<DeviceKeypoints> {
    let mut job = DetectJob::new(lane, image.width(), image.height(), config)?;
    job.launch(dev, lane, image)?;
    // The scratch buffers go back to the arena now: their next user queues on this stream, after the
    // launches that use them.
    Ok(job.output)
}

/// [`detect_on_device`] without the orientation (every `angle` 0), as
/// [`crate::detect::cpu::detect_unoriented`]: for the pyramid, which orients only the keypoints its
/// selection keeps ([`launch_orient_refine`]).
pub(crate) fn detect_unoriented_on_device(
    dev: &GpuDevice,
    lane: &Lane,
    image: &DeviceImage,
    config: &DetectorConfig,
) -> Result<DeviceKeypoints> {
    let mut job = DetectJob::new(lane, image.width(), image.height(), config)?;
    job.launch_stages(dev, lane, image, Stage::Scatter)?;
    Ok(job.output)
}

// SAFETY: clatch_levels is bindgen's #[repr(C)] copy of the C struct (u64, i32 and u32 arrays and an
// i32: 648 bytes, no padding), passed by value as a kernel parameter.
unsafe impl DeviceRepr for clatch_levels {}

/// Queues `kernels/detect.cu`'s `clatch_orient_refine` on `stream`: for the keypoints of `levels`
/// (each level's image and how many of `keypoints`, one level after the other, are on it; whole
/// positions on their level), the orientation, reproducing [`crate::detect::cpu::orientation`]
/// (written into their `angle`, which the describe kernel reads, and as the bin of
/// [`crate::angle::bin_degrees`] into `bins`, for the host), and with `offsets` the sub-pixel offset
/// `[dx, dy]` (1/65536 pixel) of each, reproducing [`crate::detect::cpu::subpixel_offset`]. One launch
/// for every level.
pub(crate) fn launch_orient_refine(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    levels: &[(&DeviceImage, usize)],
    keypoints: &mut CudaViewMut<'_, KeyPoint>,
    bins: &mut CudaViewMut<'_, i32>,
    offsets: Option<&mut CudaViewMut<'_, i32>>,
) -> Result<()> {
    let total: usize = levels.iter().map(|&(_, n)| n).sum();
    let offsets_len = offsets.as_ref().map_or(usize::MAX, |o| o.len());
    super::invariant(
        levels.len() <= CLATCH_MAX_LEVELS as usize
            && total <= keypoints.len()
            && total <= bins.len()
            && total.saturating_mul(2) <= offsets_len
            && total <= u32::MAX as usize,
        "orientation",
        || {
            format!(
                "{} levels, {total} keypoints for buffers of {} keypoints and {} bins",
                levels.len(),
                keypoints.len(),
                bins.len()
            )
        },
    )?;
    if total == 0 {
        return Ok(());
    }
    let mut table = clatch_levels {
        textures: [0; CLATCH_MAX_LEVELS as usize],
        widths: [0; CLATCH_MAX_LEVELS as usize],
        heights: [0; CLATCH_MAX_LEVELS as usize],
        starts: [0; CLATCH_MAX_LEVELS as usize + 1],
        count: levels.len() as i32,
    };
    let mut at = 0;
    for (l, &(image, n)) in levels.iter().enumerate() {
        image.arrived(stream)?;
        table.textures[l] = image.texture();
        table.widths[l] = image.width() as i32;
        table.heights[l] = image.height() as i32;
        table.starts[l] = at as u32;
        at += n;
        table.starts[l + 1] = at as u32;
    }
    let warps = CLATCH_DETECT_WARPS as usize;
    let blocks = total
        .div_ceil(warps)
        .clamp(1, dev.multiprocessors * ORIENT_BLOCKS_PER_SM);
    let no_offsets: u64 = 0;
    let mut launch = stream.launch_builder(dev.kernel(kernels::ORIENT_REFINE));
    launch
        .arg(&table)
        .arg(&dev.boundaries)
        .arg(keypoints)
        .arg(bins);
    match offsets {
        Some(offsets) => launch.arg(offsets),
        // A null pointer: the kernel then only orients.
        None => launch.arg(&no_offsets),
    };
    let config = LaunchConfig {
        grid_dim: (blocks as u32, 1, 1),
        block_dim: ((warps * 32) as u32, 1, 1),
        shared_mem_bytes: 0,
    };
    // SAFETY: arguments match the kernel's signature (the table by value, then four pointers, the
    // last null when not refining); one warp per keypoint k < total (grid-stride) reads and writes
    // record k and writes bin k and offsets 2k, 2k + 1, all within their buffers (checked above); the
    // boundary table holds 720 (x, y) pairs; every texture in the table is a level's, alive until
    // the caller's images drop, after the stream's work (their owner's contract).
    unsafe { launch.launch(config) }.map_err(driver_error("launching clatch_orient_refine"))?;
    Ok(())
}

/// Detects keypoints on the GPU: the same list as [`crate::detect::cpu::detect`]. The image must be
/// at least one descriptor window in each direction (checked by the caller).
pub(crate) fn detect(
    dev: &GpuDevice,
    image: &GrayView,
    config: &DetectorConfig,
) -> Result<Vec<KeyPoint>> {
    let lane = Leased::take(dev)?;
    let result = DeviceImage::upload(dev, &lane, image, ImageLife::Work).and_then(|device_image| {
        detect_on_device(dev, &lane, &device_image, config)?.download(&lane)
    });
    settled(&lane, result)
}

#[cfg(feature = "internals")]
pub mod hooks;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::cpu::{detect, suppress_non_maxima};
    use crate::synthetic::{SplitMix64, noise};

    #[test]
    fn survivors_are_never_neighbours_so_the_capacity_bound_holds() {
        // Score maps of few distinct values (many ties); the border ring is 0 as outside a margin.
        let mut rng = SplitMix64::new(7);
        for (w, h) in [(5usize, 5usize), (8, 8), (33, 17), (64, 4), (9, 40)] {
            for _ in 0..300 {
                let mut scores = vec![0u8; w * h];
                for y in 1..h - 1 {
                    for x in 1..w - 1 {
                        scores[y * w + x] = rng.below(4) as u8;
                    }
                }
                let kept = suppress_non_maxima(&scores, w, h);
                assert!(kept.len() <= (w - 2).div_ceil(2) * (h - 2).div_ceil(2));
                for (i, a) in kept.iter().enumerate() {
                    for b in &kept[i + 1..] {
                        assert!(
                            a.0.abs_diff(b.0) > 1 || a.1.abs_diff(b.1) > 1,
                            "{a:?} {b:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn capacity_covers_every_survivor_of_noise() {
        for (w, h) in [(64usize, 64usize), (97, 99), (120, 101), (200, 150)] {
            let pixels = noise(w, h, (w * h) as u64).expect("synthetic image");
            let image = GrayView::new(&pixels, w, h, w).unwrap();
            let config = DetectorConfig {
                threshold: 1,
                max_keypoints: usize::MAX,
                keypoint_size: 16.0,
                ..DetectorConfig::default()
            };
            let geometry = Geometry::new(w, h, &config);
            assert!(detect(&image, &config).len() <= geometry.capacity);
            assert_eq!(geometry.pitch % CLATCH_DETECT_ROW_ALIGN as usize, 0);
        }
    }
}
