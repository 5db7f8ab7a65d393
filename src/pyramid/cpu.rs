//! The reference pyramid (see the parent module for the numeric contract).

use crate::parallel::*;

use super::along_x::ColumnPlan;
use super::{LevelKeypoint, Plan, Pyramid, STEP_FRAC_BITS, downscaled, source_position};
use crate::describe::{self, DescriptorConfig};
use crate::detect::{self, DetectorConfig, Ranking, Subpixel};
use crate::error::Result;
use crate::features::Features;
use crate::gray_view::GrayView;

/// Where one output coordinate reads: the lower neighbour, the upper one (clamped to the last pixel)
/// and the 8-bit weight of the upper one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Tap {
    pub(super) low: usize,
    pub(super) high: usize,
    pub(super) weight: i32,
}

/// The taps of the `n` output coordinates of a side of `source` pixels.
pub(super) fn taps(n: usize, source: usize, step: i64) -> Vec<Tap> {
    (0..n)
        .map(|i| {
            let p8 = (source_position(i, step) + 128) >> 8;
            let low = (p8 >> 8) as usize;
            Tap {
                low,
                high: (low + 1).min(source - 1),
                weight: (p8 & 255) as i32,
            }
        })
        .collect()
}

/// Output rows per parallel task of [`downscale`]: within a band, source rows interpolated along
/// `x` are reused by the next output row.
const BAND: usize = 16;

/// One level down: `floor(W · 2^16 / step)` x `floor(H · 2^16 / step)` pixels, each the bilinear sample
/// (description's rule) of `img` at its source position. Returns the pixels (stride = width), width
/// and height.
///
/// Computed in two passes with the same integers: each source row is interpolated along `x` first,
/// `p[low] (256 - fx) + p[high] fx` (at most `255 · 256`, exact in `u16`; the reference's `upper` and
/// `lower`; 8 columns at a time with AVX2, `pyramid/along_x.rs`), then each output row combines two such rows, `(upper (256 - fy) + lower fy + 2^15) >> 16`
/// (vectorised). Consecutive output rows often share a source row, which is then interpolated once.
pub fn downscale(img: &GrayView, step: i64) -> (Vec<u8>, usize, usize) {
    debug_assert!(step > 1 << STEP_FRAC_BITS && step <= 2 << STEP_FRAC_BITS);
    let (w, h) = (
        downscaled(img.width(), step),
        downscaled(img.height(), step),
    );
    let columns = taps(w, img.width(), step);
    let rows = taps(h, img.height(), step);
    let mut out = vec![0u8; w * h];
    if w == 0 {
        return (out, w, h);
    }
    let plan = ColumnPlan::new(&columns, img.width());
    let along_x = |source: usize, line: &mut [u16]| plan.interpolate(img.row(source), line);
    out.par_chunks_mut(w * BAND)
        .zip(rows.par_chunks(BAND))
        .for_each(|(lines, band)| {
            // Two interpolated source rows and their indices: [0] the upper, [1] the lower one.
            let mut held = [(usize::MAX, vec![0u16; w]), (usize::MAX, vec![0u16; w])];
            for (line, row) in lines.chunks_mut(w).zip(band) {
                if held[0].0 != row.low {
                    if held[1].0 == row.low {
                        held.swap(0, 1);
                    } else {
                        along_x(row.low, &mut held[0].1);
                        held[0].0 = row.low;
                    }
                }
                if held[1].0 != row.high {
                    along_x(row.high, &mut held[1].1);
                    held[1].0 = row.high;
                }
                let fy = row.weight as u32;
                let (upper, lower) = (&held[0].1[..w], &held[1].1[..w]);
                for ((pixel, &u), &l) in line.iter_mut().zip(upper).zip(lower) {
                    *pixel = ((u as u32 * (256 - fy) + l as u32 * fy + (1 << 15)) >> 16) as u8;
                }
            }
        });
    (out, w, h)
}

/// Levels `1..` of the plan (level 0 is the input), each downscaled from the one before.
pub fn build_levels(img: &GrayView, plan: &Plan) -> Vec<Vec<u8>> {
    let mut levels: Vec<Vec<u8>> = Vec::with_capacity(plan.sizes.len().saturating_sub(1));
    for l in 1..plan.sizes.len() {
        let (pw, ph) = plan.sizes[l - 1];
        let previous = match levels.last() {
            Some(pixels) => GrayView::new(pixels, pw, ph, pw).expect("level geometry"),
            None => *img,
        };
        let (pixels, w, h) = downscale(&previous, plan.step);
        debug_assert_eq!((w, h), plan.sizes[l]);
        levels.push(pixels);
    }
    levels
}

/// Level `l` of `img` with its `levels` from [`build_levels`].
fn level_view<'a>(
    img: &GrayView<'a>,
    levels: &'a [Vec<u8>],
    plan: &Plan,
    l: usize,
) -> GrayView<'a> {
    if l == 0 {
        return *img;
    }
    let (w, h) = plan.sizes[l];
    GrayView::new(&levels[l - 1], w, h, w).expect("level geometry")
}

/// Detects on every level and keeps the strongest `max_keypoints` over all (level coordinates), with
/// their sub-pixel offsets ([`DetectorConfig::subpixel`]).
fn detect_levels(
    img: &GrayView,
    levels: &[Vec<u8>],
    plan: &Plan,
    config: &DetectorConfig,
) -> Vec<LevelKeypoint> {
    let candidates = config.candidates();
    let views: Vec<GrayView> = (0..plan.sizes.len())
        .map(|l| level_view(img, levels, plan, l))
        .collect();
    // Orientation does not take part in the selection: only the kept keypoints are oriented.
    // The levels are independent: detected side by side (each also in parallel over its rows), so
    // that the small levels and each level's sort keep the threads busy.
    let per_level: Vec<_> = views
        .par_iter()
        .map(|view| detect::cpu::detect_unoriented(view, &candidates))
        .collect();
    let rank = |level: usize, k: &crate::keypoint::KeyPoint| match config.ranking {
        Ranking::Fast => super::fast_rank(level, k),
        Ranking::Harris => detect::cpu::harris_response(&views[level], k.x as usize, k.y as usize),
    };
    let mut selected = super::select(&per_level, &plan.sizes, plan.scale_factor(), config, &rank);
    let subpixel = config.subpixel == Subpixel::Score;
    // In raster order of each level, so that the discs of neighbouring keypoints, which share most
    // of their rows, are read while those rows are in the cache; then back to selection order.
    let mut order: Vec<(usize, u32, u32, usize)> = selected
        .iter()
        .enumerate()
        .map(|(i, k)| (k.level, k.keypoint.y as u32, k.keypoint.x as u32, i))
        .collect();
    order.sort_unstable();
    let found: Vec<(f32, [i32; 2])> = order
        .par_iter()
        .map(|&(level, y, x, _)| {
            let (view, x, y) = (&views[level], x as usize, y as usize);
            let angle = detect::cpu::orientation(view, x, y);
            let offset = if subpixel { detect::cpu::subpixel_offset(view, x, y) } else { [0, 0] };
            (angle, offset)
        })
        .collect();
    for (&(.., i), (angle, offset)) in order.iter().zip(found) {
        selected[i].keypoint.angle = angle;
        selected[i].offset = offset;
    }
    selected
}

/// Multi-scale detection on the CPU: keypoints in level-0 coordinates, strongest first.
pub fn detect(
    img: &GrayView,
    config: &DetectorConfig,
    pyramid: &Pyramid,
) -> Vec<crate::keypoint::KeyPoint> {
    let plan = Plan::new(pyramid, img.width(), img.height(), config.margin());
    let levels = build_levels(img, &plan);
    detect_levels(img, &levels, &plan, config)
        .iter()
        .map(|k| super::report(k, pyramid, plan.step))
        .collect()
}

/// Multi-scale detection and description on the CPU: each keypoint described on its own level.
pub fn detect_and_describe(
    img: &GrayView,
    detector: &DetectorConfig,
    descriptor: &DescriptorConfig,
    pyramid: &Pyramid,
) -> Result<Features> {
    let plan = Plan::new(pyramid, img.width(), img.height(), detector.margin());
    let levels = build_levels(img, &plan);
    let selected = detect_levels(img, &levels, &plan, detector);
    // Each level's keypoints are described on their level, the levels side by side.
    let per_level: Vec<_> = (0..plan.sizes.len())
        .into_par_iter()
        .map(|l| {
            let view = level_view(img, &levels, &plan, l);
            let described =
                describe::cpu::describe(&view, &super::of_level(&selected, l), descriptor);
            // The detector's margin makes every window fit on its level.
            debug_assert!(described.skipped.is_empty());
            described.descriptors
        })
        .collect();
    Ok(Features::all(
        selected
            .iter()
            .map(|k| super::report(k, pyramid, plan.step))
            .collect(),
        super::assemble(&selected, &per_level, descriptor.width)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subpixel_moves_only_the_reported_positions() {
        // Multi-scale and single-scale extraction with and without Subpixel::Score: the same keypoints
        // in the same order, the same descriptors, sizes, angles and responses; each refined position
        // is the whole one's level position plus the level's parabola offset, mapped by the same
        // chain, so within half a level pixel of the whole one.
        let pixels = crate::synthetic::rectangles(400, 300, 5).expect("synthetic image");
        let img = GrayView::new(&pixels, 400, 300, 400).unwrap();
        for pyramid in [
            Pyramid { levels: 4, scale_factor: 1.5 },
            Pyramid { levels: 1, scale_factor: 2.0 },
        ] {
            let whole_config = DetectorConfig { subpixel: Subpixel::None, ..DetectorConfig::default() };
            let refined_config = DetectorConfig { subpixel: Subpixel::Score, ..whole_config.clone() };
            let descriptor = DescriptorConfig::default();
            let whole = detect_and_describe(&img, &whole_config, &descriptor, &pyramid).unwrap();
            let refined = detect_and_describe(&img, &refined_config, &descriptor, &pyramid).unwrap();
            assert_eq!(detect(&img, &refined_config, &pyramid), refined.keypoints);
            assert_eq!(whole.descriptors, refined.descriptors);
            assert_eq!(whole.keypoints.len(), refined.keypoints.len());
            let plan = Plan::new(&pyramid, 400, 300, whole_config.margin());
            let levels = build_levels(&img, &plan);
            let mut moved = 0;
            for (w, r) in whole.keypoints.iter().zip(&refined.keypoints) {
                assert_eq!((w.size, w.angle, w.response, w.octave), (r.size, r.angle, r.response, r.octave));
                let level = w.octave as usize;
                let view = level_view(&img, &levels, &plan, level);
                // The level position of the whole keypoint, found back from its level-0 coordinate.
                let (lx, ly) = (0..plan.sizes[level].0)
                    .flat_map(|x| (0..plan.sizes[level].1).map(move |y| (x, y)))
                    .find(|&(x, y)| {
                        super::super::to_level0_fixed((x as i64) << 16, level, plan.step) == w.x
                            && super::super::to_level0_fixed((y as i64) << 16, level, plan.step) == w.y
                    })
                    .expect("a whole level position");
                let [dx, dy] = detect::cpu::subpixel_offset(&view, lx, ly);
                let expected = |whole: usize, offset: i32| {
                    super::super::to_level0_fixed(((whole as i64) << 16) + offset as i64, level, plan.step)
                };
                assert_eq!((r.x, r.y), (expected(lx, dx), expected(ly, dy)));
                let half = 0.5 * plan.scale_factor().powi(level as i32) + 1.0 / 256.0;
                assert!((r.x - w.x).abs() as f64 <= half && (r.y - w.y).abs() as f64 <= half);
                moved += usize::from((r.x, r.y) != (w.x, w.y));
            }
            assert!(moved > whole.keypoints.len() / 4, "{moved} of {} moved", whole.keypoints.len());
        }
    }

    #[test]
    fn factor_two_is_the_rounded_2x2_mean() {
        // 5x3 -> 2x1. Block (0..2, 0..2) = 10, 11, 20, 22: 63 / 4 = 15.75 -> 16; block (2..4, 0..2)
        // = 1, 2, 3, 4: 10 / 4 = 2.5 -> 3 (half up). Column 4 and row 2 are dropped.
        let pixels = [
            10, 11, 1, 2, 99, //
            20, 22, 3, 4, 99, //
            99, 99, 99, 99, 99,
        ];
        let img = GrayView::new(&pixels, 5, 3, 5).unwrap();
        assert_eq!(downscale(&img, 131_072), (vec![16, 3], 2, 1));
    }

    #[test]
    fn factor_one_point_two_worked_by_hand() {
        // 7x1 image of 0, 40, ..., 240; step 78643: width floor(7 · 65536 / 78643) = 5. Source
        // positions (16.16) of X = 0..4: 6553, 85196, 163839, 242482, 321125; 24.8: (p + 128) >> 8 =
        // 26, 333, 640, 947, 1254, i.e. (low, weight) = (0, 26), (1, 77), (2, 128), (3, 179),
        // (4, 230). Value 40 low + 40 weight / 256 = 4.06, 52.03, 100, 147.97, 195.94, rounded.
        // Two equal rows: height floor(2 · 65536 / 78643) = 1, whatever the row weight.
        let pixels: Vec<u8> = (0..14).map(|i| 40 * (i % 7)).collect();
        let img = GrayView::new(&pixels, 7, 2, 7).unwrap();
        assert_eq!(downscale(&img, 78_643), (vec![4, 52, 100, 148, 196], 5, 1));
    }

    #[test]
    fn factor_one_point_five_worked_by_hand() {
        // 3x3 at factor 1.5 (step 98304): width 2, X = 1 samples (3 · 98304 - 65536) >> 1 = 114688
        // = 1.75 px: pixels 1 and 2 with weight 192. Every row 0, 64, 128.
        let pixels = [0, 64, 128, 0, 64, 128, 0, 64, 128];
        let img = GrayView::new(&pixels, 3, 3, 3).unwrap();
        // X = 0: (98304 - 65536) >> 1 = 16384 = 0.25 px -> 64 · 64 / 256 = 16. X = 1: 64 + 64 · 0.75 = 112.
        assert_eq!(downscale(&img, 98_304), (vec![16, 112, 16, 112], 2, 2));
    }
}
