//! Multi-scale detection: FAST over an image pyramid, each keypoint described on its own level.
//!
//! FAST and the 64x64 window alone give no scale invariance. With [`Pyramid`] set in
//! [`crate::ExtractorConfig::pyramid`] the extractor builds levels `1..levels`, each a downscale of the
//! one before by `scale_factor`, detects on every level with the usual detector, keeps the strongest
//! `max_keypoints` over all levels, and describes each keypoint **on its own level** with the level's
//! window (so a level-`l` keypoint's descriptor sees `scale_factor^l` times more of the scene, from an
//! image that was averaged down rather than sampled sparsely). Keypoints are reported in level-0
//! coordinates with `octave = level` and `size = keypoint_size · scale_factor^level`.
//!
//! Every rule is integer arithmetic (docs/numerics.md, section 6):
//! - **Step**: `step = round_half_even(scale_factor · 2^16)`, `2^16 < step ≤ 2^17`.
//! - **Level size**: `W_l = floor(W_{l-1} · 2^16 / step)`, likewise `H_l`. A level is used only if it
//!   has a pixel the detector can score (`W_l, H_l > 2 · margin`); the levels stop at the first that
//!   has none.
//! - **Downscale** ([`cpu::downscale`]): level pixel `X` samples the previous level at
//!   `sx = ((2X + 1) · step - 2^16) >> 1` (16.16, the pixel-centre rule `(X + 1/2) f - 1/2`), then the
//!   bilinear rule of description (24.8 position `(sx + 128) >> 8`, clamped neighbours, rounded
//!   `>> 16`). For `scale_factor = 2` this is exactly the 2x2 mean rounded half up.
//! - **Selection** ([`select()`], in `select.rs`): all levels' keypoints sorted by (score descending, level, y, x
//!   ascending, in level coordinates), the first `max_keypoints` kept.
//! - **Back to level 0** ([`to_level0_fixed`]): `p = X · 2^16 + offset`, then `level` times
//!   `p = (((p + 2^15) · step) >> 16) - 2^15`, then `x = ((p + 128) >> 8) / 256` (exact in `f32`).
//!   `offset` is 0, or with [`crate::Subpixel::Score`] the keypoint's sub-pixel offset on its level in
//!   1/65536 pixel ([`crate::detect::cpu::subpixel_offset`], integer-exact), found after selection for
//!   the kept keypoints only; orientation and descriptor stay those of the whole pixel `X`.

mod along_x;
pub mod cpu;
mod select;

pub use select::{LevelKeypoint, fast_rank, of_level, select};
#[cfg(feature = "internals")]
pub use select::{area_shares, level_shares};

use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::error::{Error, Result};
use crate::keypoint::KeyPoint;

/// Fractional bits of the scale step.
pub const STEP_FRAC_BITS: u32 = 16;
/// Most levels a pyramid may have.
pub const MAX_LEVELS: usize = 32;

/// Multi-scale detection: FAST over an image pyramid, each keypoint described on its own level.
///
/// FAST and the 64x64 window alone give no scale invariance. With a `Pyramid` in
/// [`crate::ExtractorConfig::pyramid`] the extractor builds levels `1..levels`, each a downscale of the
/// one before by `scale_factor`, detects on every level with the usual detector, keeps the strongest
/// `max_keypoints` over all levels, and describes each keypoint **on its own level** with the level's
/// window (so a level-`l` keypoint's descriptor sees `scale_factor^l` times more of the scene, from an
/// image that was averaged down rather than sampled sparsely). Keypoints are reported in level-0
/// coordinates with `octave = level` and `size = keypoint_size · scale_factor^level`. Every rule is
/// integer arithmetic: [`crate::numerics`], section 6.
///
/// ```
/// use clatch::{Backend, Extractor, ExtractorConfig, GrayView, Pyramid};
///
/// let pixels = clatch::synthetic::rectangles(640, 480, 1)?;
/// let image = GrayView::new(&pixels, 640, 480, 640)?;
/// let config = ExtractorConfig::default().with_pyramid(Some(Pyramid::new(3, 2.0)));
/// let features = Extractor::new(Backend::Cpu, config)?.detect_and_describe(&image)?;
/// assert!(features.keypoints.iter().any(|k| k.octave == 1 && k.size == 80.0)); // 40 x 2
/// # Ok::<(), clatch::Error>(())
/// ```
///
/// `#[non_exhaustive]`: built with [`Pyramid::new`], or from [`Pyramid::DEFAULT`] with the `with_*`
/// methods.
///
/// ```
/// use clatch::Pyramid;
///
/// assert_eq!(Pyramid::DEFAULT.with_levels(4), Pyramid::new(4, 1.2));
/// assert_eq!(Pyramid::default(), Pyramid::DEFAULT);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Pyramid {
    /// Levels including the full-resolution image (1 = no downscaling). 1..=32, and the top level's
    /// keypoint size must stay within 1024 pixels.
    pub levels: usize,
    /// Ratio of the sizes of consecutive levels, in (1, 2] (used as 16.16 fixed point,
    /// `round_half_even(scale_factor · 2^16)`).
    pub scale_factor: f32,
}

impl Pyramid {
    /// The default pyramid: 8 levels, each 1.2 times smaller than the one before (as ORB's).
    pub const DEFAULT: Pyramid = Pyramid::new(8, 1.2);

    /// A pyramid of `levels` levels (the full-resolution image included), each `scale_factor` times
    /// smaller than the one before. The ranges are checked when an extractor is made with it
    /// ([`Pyramid::validate`]).
    pub const fn new(levels: usize, scale_factor: f32) -> Self {
        Self {
            levels,
            scale_factor,
        }
    }

    with_methods! {
        /// The same pyramid with this many levels ([`Pyramid::levels`]).
        with_levels => levels: usize;
        /// The same pyramid with this ratio between the sizes of consecutive levels
        /// ([`Pyramid::scale_factor`]).
        with_scale_factor => scale_factor: f32;
    }

    /// The scale factor in 16.16 fixed point: `round_half_even(scale_factor · 2^16)`.
    pub(crate) fn step(&self) -> i64 {
        (self.scale_factor as f64 * (1u64 << STEP_FRAC_BITS) as f64).round_ties_even() as i64
    }

    /// `keypoint_size · (step / 2^16)^level`: `level` successive `f64` products, rounded to `f32`
    /// (computed on the host for every backend).
    pub(crate) fn level_size(&self, keypoint_size: f32, level: usize) -> f32 {
        let factor = self.step() as f64 / (1u64 << STEP_FRAC_BITS) as f64;
        (0..level).fold(keypoint_size as f64, |s, _| s * factor) as f32
    }

    /// Checks the ranges (the sizes of all levels' keypoints must be valid keypoint sizes).
    pub fn validate(&self, keypoint_size: f32) -> Result<()> {
        if !(1..=MAX_LEVELS).contains(&self.levels) {
            return Err(Error::InvalidConfig {
                field: "pyramid.levels",
                value: self.levels.to_string(),
                reason: "must be in 1..=32",
            });
        }
        let one = 1i64 << STEP_FRAC_BITS;
        let finite = self.scale_factor.is_finite();
        if !finite || !(one + 1..=2 * one).contains(&self.step()) {
            return Err(Error::InvalidConfig {
                field: "pyramid.scale_factor",
                value: self.scale_factor.to_string(),
                reason: "must be in (1, 2] (at 1/65536 precision)",
            });
        }
        let top = self.level_size(keypoint_size, self.levels - 1);
        crate::describe::check_size(top).map_err(|_| Error::InvalidConfig {
            field: "pyramid.levels",
            value: self.levels.to_string(),
            reason: "the top level's keypoint size (keypoint_size x scale_factor^(levels - 1)) \
                     must stay within 1024 pixels",
        })
    }
}

/// [`Pyramid::DEFAULT`].
impl Default for Pyramid {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The levels one image gets: their sizes, level 0 first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    /// The 16.16 step between levels.
    pub step: i64,
    /// `(width, height)` of each used level; level 0 is the input.
    pub sizes: Vec<(usize, usize)>,
}

impl Plan {
    /// The scale factor the levels really have: `step / 2^16` (exact in `f64`).
    pub fn scale_factor(&self) -> f64 {
        self.step as f64 / (1u64 << STEP_FRAC_BITS) as f64
    }

    /// The levels of a `width` x `height` image for a detector margin of `margin` pixels.
    pub fn new(pyramid: &Pyramid, width: usize, height: usize, margin: usize) -> Self {
        let step = pyramid.step();
        let mut sizes = vec![(width, height)];
        while sizes.len() < pyramid.levels {
            let (w, h) = *sizes.last().expect("level 0 is there");
            let next = (downscaled(w, step), downscaled(h, step));
            if next.0 <= 2 * margin || next.1 <= 2 * margin {
                break;
            }
            sizes.push(next);
        }
        Self { step, sizes }
    }
}

/// `floor(n · 2^16 / step)`: a level's side from the previous level's (0 for a step that is not
/// positive: validated configurations never have one).
pub fn downscaled(n: usize, step: i64) -> usize {
    match usize::try_from(step) {
        Ok(step) if step > 0 => (n << STEP_FRAC_BITS) / step,
        _ => 0,
    }
}

/// Where level pixel `index` samples the previous level, 16.16: `((2 index + 1) · step - 2^16) >> 1`.
pub fn source_position(index: usize, step: i64) -> i64 {
    ((2 * index as i64 + 1) * step - (1 << STEP_FRAC_BITS)) >> 1
}

// Sub-pixel offsets are added to 16.16 level positions as they are.
const _: () = assert!(crate::detect::SUBPIXEL_FRAC_BITS == STEP_FRAC_BITS);

/// The level-0 coordinate of the 16.16 fixed-point coordinate `position` on `level`: `level` times
/// `p = (((p + 2^15) · step) >> 16) - 2^15` (the inverse of the downscale's pixel-centre rule,
/// floored; `>>` floors), then `((p + 128) >> 8) / 256`, a 24.8 value exact in `f32` (level-0
/// coordinates are below 2^15). Integer arithmetic throughout; the one `f32` division by 256 is exact.
pub fn to_level0_fixed(position: i64, level: usize, step: i64) -> f32 {
    let half = 1i64 << (STEP_FRAC_BITS - 1);
    let mut p = position;
    for _ in 0..level {
        p = (((p + half) * step) >> STEP_FRAC_BITS) - half;
    }
    ((p + 128) >> 8) as f32 / 256.0
}

/// The reported keypoint: level-0 position (whole level position plus its sub-pixel offset, by
/// [`to_level0_fixed`]), `size = level_size`, `octave = level`.
pub fn report(k: &LevelKeypoint, pyramid: &Pyramid, step: i64) -> KeyPoint {
    let fixed = |whole: f32, offset: i32| ((whole as i64) << STEP_FRAC_BITS) + offset as i64;
    KeyPoint {
        x: to_level0_fixed(fixed(k.keypoint.x, k.offset[0]), k.level, step),
        y: to_level0_fixed(fixed(k.keypoint.y, k.offset[1]), k.level, step),
        size: pyramid.level_size(k.keypoint.size, k.level),
        octave: k.level as i32,
        ..k.keypoint
    }
}

/// Descriptor rows in selection order, from each level's descriptors of [`of_level`]'s keypoints.
pub fn assemble(
    selected: &[LevelKeypoint],
    per_level: &[DescriptorSet],
    width: DescriptorWidth,
) -> Result<DescriptorSet> {
    let mut next = vec![0usize; per_level.len()];
    let mut words = Vec::with_capacity(selected.len() * width.words());
    for k in selected {
        let row = per_level[k.level]
            .get(next[k.level])
            .expect("one descriptor per selected keypoint of the level");
        next[k.level] += 1;
        words.extend_from_slice(row);
    }
    DescriptorSet::from_words(width, words)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pyramid(levels: usize, scale_factor: f32) -> Pyramid {
        Pyramid {
            levels,
            scale_factor,
        }
    }

    #[test]
    fn steps_and_sizes_worked_by_hand() {
        assert_eq!(pyramid(2, 2.0).step(), 131_072);
        // 1.2 · 65536 = 78643.2 -> 78643.
        assert_eq!(pyramid(2, 1.2).step(), 78_643);
        // 640 · 65536 / 78643 = 533.33 -> 533; 533 · 65536 / 78643 = 444.17 -> 444.
        assert_eq!(downscaled(640, 78_643), 533);
        assert_eq!(downscaled(533, 78_643), 444);
        assert_eq!(downscaled(641, 131_072), 320);
        assert_eq!(pyramid(5, 2.0).level_size(64.0, 4), 1024.0);
        assert_eq!(pyramid(3, 1.5).level_size(64.0, 2), 144.0);
    }

    #[test]
    fn plan_stops_at_the_first_level_without_a_scorable_pixel() {
        // Margin 48: a level needs both sides > 96. 640x480 -> 320x240 -> 160x120 -> 80x60 (stop).
        let plan = Plan::new(&pyramid(8, 2.0), 640, 480, 48);
        assert_eq!(plan.sizes, vec![(640, 480), (320, 240), (160, 120)]);
        assert_eq!(Plan::new(&pyramid(2, 2.0), 640, 480, 48).sizes.len(), 2);
        assert_eq!(Plan::new(&pyramid(1, 2.0), 640, 480, 48).sizes.len(), 1);
    }

    #[test]
    fn source_positions_worked_by_hand() {
        // Factor 2: pixel X samples 2X + 1/2, i.e. the middle of pixels 2X and 2X + 1.
        assert_eq!(source_position(0, 131_072), 32_768);
        assert_eq!(source_position(7, 131_072), 14 * 65_536 + 32_768);
        // Factor 1.2 (step 78643): X = 0 -> (78643 - 65536) >> 1 = 6553 (0.09999 px);
        // X = 10 -> (21 · 78643 - 65536) >> 1 = 1585967 >> 1 = 792983 (12.1 px).
        assert_eq!(source_position(0, 78_643), 6_553);
        assert_eq!(source_position(10, 78_643), 792_983);
    }

    #[test]
    fn level0_coordinates_worked_by_hand() {
        let to_level0 = |x: usize, level, step| to_level0_fixed((x as i64) << 16, level, step);
        // Factor 2: level 1 pixel X is at 2X + 0.5; level 2 at 2(2X + 0.5) + 0.5 = 4X + 1.5; level 3
        // at 8X + 3.5.
        for x in [0usize, 1, 17, 400] {
            assert_eq!(to_level0(x, 0, 131_072), x as f32);
            assert_eq!(to_level0(x, 1, 131_072), 2.0 * x as f32 + 0.5);
            assert_eq!(to_level0(x, 2, 131_072), 4.0 * x as f32 + 1.5);
            assert_eq!(to_level0(x, 3, 131_072), 8.0 * x as f32 + 3.5);
        }
        // Factor 1.2, X = 10 on level 1: 792983 / 65536 = 12.09996 -> (792983 + 128) >> 8 = 3098
        // -> 3098 / 256 = 12.1015625. On level 2: p = ((792983 + 32768) · 78643 >> 16) - 32768
        // = 990898 - 32768 = 958130 -> (958130 + 128) >> 8 = 3743 -> 14.62109375.
        assert_eq!(to_level0(10, 1, 78_643), 12.101_562_5);
        assert_eq!(to_level0(10, 2, 78_643), 14.621_094);
    }

    #[test]
    fn subpixel_positions_on_levels_worked_by_hand() {
        // Factor 2, X = 10 + 1/4 on level 1: p = 671744; ((671744 + 32768) · 131072 >> 16) - 32768
        // = 1376256 = 21 px exactly, as (10.25 + 0.5) · 2 - 0.5. On level 2: 42.5.
        assert_eq!(to_level0_fixed(10 * 65_536 + 16_384, 1, 131_072), 21.0);
        assert_eq!(to_level0_fixed(10 * 65_536 + 16_384, 2, 131_072), 42.5);
        // Level 0, X = 100 - 21845/65536 (-1/3 px): (6553600 - 21845 + 128) >> 8 = 25515
        // -> 25515 / 256 = 99.66796875 (24.8, the nearest to 99.6667 but for the floor's 1/512).
        assert_eq!(to_level0_fixed(100 * 65_536 - 21_845, 0, 78_643), 25_515.0 / 256.0);
        // Factor 1.2, level 1, X = 10 - 1/2: p = 622592; (655360 · 78643) >> 16 = 786430 - 32768
        // = 753662 -> (753662 + 128) >> 8 = 2944 -> 11.5 (real: 10 · 1.2 - 0.5 = 11.5).
        assert_eq!(to_level0_fixed(10 * 65_536 - 32_768, 1, 78_643), 11.5);
    }

    #[test]
    fn subpixel_positions_on_levels_agree_with_the_real_mapping() {
        // The integer chain against the real-valued inverse of the pixel-centre rule computed in f64,
        // u -> (u + 1/2) f^l - 1/2 with f = step / 2^16 exactly: each level's floor loses less than
        // 2^-16 px (then scaled by the later levels), the final 24.8 rounding at most 1/512.
        let mut rng = crate::synthetic::SplitMix64::new(11);
        for step in [78_643i64, 98_304, 131_072, 131_071, 65_537, 91_750] {
            let f = step as f64 / 65_536.0;
            for level in 0..8 {
                // Level-0 coordinates stay below 2^15 (images are at most 32767 pixels wide).
                let widest = (30_000.0 / f.powi(level as i32)) as u64;
                for _ in 0..500 {
                    let whole = 16 + rng.below(widest) as i64;
                    let offset = rng.below(65_535) as i64 - 32_767;
                    let got = to_level0_fixed((whole << 16) + offset, level, step);
                    let u = whole as f64 + offset as f64 / 65_536.0;
                    let real = (u + 0.5) * f.powi(level as i32) - 0.5;
                    let floors: f64 = (0..level).map(|l| f.powi(l as i32) / 65_536.0).sum();
                    let err = got as f64 - real;
                    assert!(
                        err <= 1.0 / 512.0 && err >= -(1.0 / 512.0 + floors),
                        "step {step} level {level} {whole} {offset}: {got} vs {real}"
                    );
                    // A 24.8 value: exact in f32.
                    assert_eq!((got * 256.0).fract(), 0.0);
                }
            }
        }
    }

    #[test]
    fn reported_positions_carry_the_offsets() {
        let k = LevelKeypoint {
            level: 1,
            keypoint: KeyPoint::new(10.0, 20.0),
            rank: 50,
            offset: [16_384, -16_384],
        };
        let reported = report(&k, &pyramid(3, 2.0), 131_072);
        // (10.25 + 0.5) · 2 - 0.5 = 21, (19.75 + 0.5) · 2 - 0.5 = 40.
        assert_eq!((reported.x, reported.y, reported.octave), (21.0, 40.0, 1));
        let whole = report(&LevelKeypoint { offset: [0, 0], ..k }, &pyramid(3, 2.0), 131_072);
        assert_eq!((whole.x, whole.y), (20.5, 40.5));
        assert_eq!((whole.size, whole.angle), (reported.size, reported.angle));
    }

    #[test]
    fn validation_rejects_each_bad_field() {
        assert!(pyramid(5, 2.0).validate(64.0).is_ok());
        assert!(pyramid(8, 1.2).validate(64.0).is_ok());
        for bad in [
            pyramid(0, 2.0),
            pyramid(33, 1.01),
            pyramid(6, 2.0),
            pyramid(3, 1.0),
            pyramid(3, 1.000_001),
            pyramid(3, 2.01),
            pyramid(3, f32::NAN),
            pyramid(3, f32::INFINITY),
        ] {
            assert!(
                matches!(bad.validate(64.0), Err(Error::InvalidConfig { .. })),
                "{bad:?}"
            );
        }
    }
}
