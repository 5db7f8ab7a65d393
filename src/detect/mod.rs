//! Keypoint detection: FAST-9, non-maximum suppression, top-N, orientation by intensity centroid.
//!
//! The CPU module ([`cpu`]) is the reference; every step is integer arithmetic:
//! 1. **FAST-9 score.** For pixel `p` with circle pixels `c[0..16]` (radius-3 Bresenham circle, clockwise
//!    from the top, [`FAST_CIRCLE`]) the score is
//!    `max over k of max(min_{j<9} (c[k+j] - p), min_{j<9} (p - c[k+j]))` (indices mod 16): the largest
//!    `t` for which nine contiguous circle pixels are all brighter than `p + t`, or all darker than `p - t`.
//!    `p` is a corner iff `score > threshold`. Scores are computed only for pixels at least `margin`
//!    from every border; every other pixel, and every non-corner, has score 0.
//! 2. **Non-maximum suppression** over the 3x3 neighbourhood, ties broken by raster order: a corner is
//!    kept iff its score is `>` the score of each neighbour that comes before it in raster order
//!    (the row above, and the left neighbour) and `>=` that of each neighbour after it.
//! 3. **Top-N**: survivors are sorted by score (descending), then `y`, then `x` (ascending), and the first
//!    `max_keypoints` are kept.
//! 4. **Orientation**: integer moments `m10 = Σ dx·I`, `m01 = Σ dy·I` over the disc `dx² + dy² <= 15²`
//!    around the keypoint, binned by [`crate::angle::direction_bin`]; the reported angle is the bin's
//!    angle (a multiple of 1/8 degree, exact in `f32`).
//!
//! 5. **Sub-pixel position** (optional, [`Subpixel::Score`]): per axis, the peak of the parabola
//!    through the FAST scores of the keypoint and its two neighbours, `(l - r) / (2 (l - 2c + r))`
//!    pixels, 0 unless the keypoint's score `c` is strictly above both; computed as a rounded integer in
//!    1/65536 pixel ([`cpu::parabola_offset`], [`cpu::subpixel_offset`]) and mapped to level 0 with the
//!    level position by [`crate::pyramid::to_level0_fixed`]. Only the reported `x`, `y` move:
//!    orientation and descriptor are computed at the whole pixel.
//!
//! Keypoints are reported at integer pixel positions (unless refined) with `size = keypoint_size`,
//! `response = score`, `octave = 0`. The margin is chosen so that every detected keypoint's descriptor window fits in the
//! image at any angle, so detection never produces a keypoint that description skips.

pub mod cpu;
mod rows;

use crate::error::{Error, Result};
use crate::gray_view::GrayView;

/// The 16 offsets of the FAST circle of radius 3, clockwise from the top (x right, y down).
pub const FAST_CIRCLE: [[i32; 2]; 16] = [
    [0, -3],
    [1, -3],
    [2, -2],
    [3, -1],
    [3, 0],
    [3, 1],
    [2, 2],
    [1, 3],
    [0, 3],
    [-1, 3],
    [-2, 2],
    [-3, 1],
    [-3, 0],
    [-3, -1],
    [-2, -2],
    [-1, -3],
];

/// Contiguous circle pixels that must all be brighter (or all darker): FAST-9.
pub const FAST_ARC: usize = 9;

/// Most cells per side of the spreading grid.
pub const MAX_GRID: usize = 64;

/// Radius of the disc the orientation moments are summed over.
pub const ORIENTATION_RADIUS: i32 = 15;

/// Fractional bits of a sub-pixel offset ([`Subpixel`]): offsets are integers in 1/65536 pixel, the
/// 16.16 fixed point of the pyramid's mapping to level 0.
pub const SUBPIXEL_FRAC_BITS: u32 = 16;

/// FAST-9 detector settings: score, non-maximum suppression, top-N, orientation by intensity centroid
/// (every rule: [`crate::numerics`], section 3).
///
/// `#[non_exhaustive]`: start from [`DetectorConfig::default`] and set what differs with the `with_*`
/// methods (or assign the public fields of a value you hold).
///
/// ```
/// use clatch::{DetectorConfig, Ranking, Subpixel};
///
/// let detector = DetectorConfig::default()
///     .with_threshold(30)
///     .with_max_keypoints(2000)
///     .with_ranking(Ranking::Harris)
///     .with_subpixel(Subpixel::None);
/// assert_eq!((detector.threshold, detector.max_keypoints), (30, 2000));
/// assert_eq!(detector.grid, 1); // the default
/// detector.validate()?;
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct DetectorConfig {
    /// FAST threshold: a corner needs nine contiguous circle pixels more than this above or below the
    /// centre. 1..=254. Default 20.
    pub threshold: u8,
    /// Keep at most this many keypoints, the strongest first (on an image larger than
    /// [`DetectorConfig::budget_pixels`], proportionally more: [`DetectorConfig::budget`]). Default
    /// 5000.
    pub max_keypoints: usize,
    /// Budgets that follow the image: `Some(p)` makes `max_keypoints` the budget of an image of up
    /// to `p` pixels and gives a larger image `ceil(max_keypoints · pixels / p)`, at most 4 times
    /// `max_keypoints` ([`DetectorConfig::budget`]); `None` keeps `max_keypoints` for every size.
    /// Default [`DetectorConfig::DEFAULT_BUDGET_PIXELS`] (one megapixel, 2^20 pixels): with the
    /// default 5000, an image of up to 1024x1024 keeps 5000 keypoints, a 1712x1368 one 11,168, one
    /// of 4 megapixels or more 20,000. Measured on large pairs (EVALUATION.md, "Keypoint budgets on
    /// large images"): a fixed budget leaves too few keypoints at full resolution once the levels
    /// share it. [`crate::ExtractorConfig::single_scale`] and the `colmap` settings keep `None`.
    pub budget_pixels: Option<usize>,
    /// `size` given to detected keypoints: the side of their descriptor window in pixels. Default
    /// [`DetectorConfig::DEFAULT_KEYPOINT_SIZE`] (40): with the default pyramid, smaller windows
    /// match more keypoints under viewpoint change than the 64 of [`crate::KeyPoint::DEFAULT_SIZE`]
    /// (EVALUATION.md), which [`crate::ExtractorConfig::single_scale`] keeps.
    pub keypoint_size: f32,
    /// Spreading: the keypoints kept are spread over a `grid` x `grid` division of the image (of each
    /// pyramid level), so that the most textured part of a photo cannot take them all. Each cell first
    /// keeps its strongest `ceil(budget / grid²)`, then the strongest of the rest fill what sparse cells
    /// left. 1 (the default) keeps the plain strongest; at most 64.
    pub grid: usize,
    /// How `max_keypoints` is shared among the levels of a [`crate::Pyramid`]. Default
    /// [`LevelBudget::Geometric`] (ORB's shares).
    pub level_budget: LevelBudget,
    /// Which corners count as the strongest. Default [`Ranking::Fast`].
    pub ranking: Ranking,
    /// How reported positions are refined below a pixel, on every pyramid level. Default
    /// [`Subpixel::Score`] (measured: correct matches within 1 px +46% on the Oxford sequences;
    /// EVALUATION.md); [`crate::ExtractorConfig::single_scale`] keeps whole pixels.
    pub subpixel: Subpixel,
}

/// How a keypoint's reported position is refined below a pixel of its level.
///
/// Only the reported `x`, `y` change: orientation and descriptor are computed at the whole pixel of
/// the keypoint's level, so the descriptors are the same with every setting. The refinement is
/// integer-exact (the same bits on every backend); the rule is in [`crate::numerics`], sections 3
/// and 6.
///
/// ```
/// use clatch::{Backend, DetectorConfig, Extractor, ExtractorConfig, GrayView, Subpixel};
///
/// let pixels = clatch::synthetic::rectangles(320, 240, 1)?;
/// let image = GrayView::new(&pixels, 320, 240, 320)?;
/// let config = |subpixel| {
///     ExtractorConfig::default().with_detector(DetectorConfig::default().with_subpixel(subpixel))
/// };
/// let whole = Extractor::new(Backend::Cpu, config(Subpixel::None))?.detect_and_describe(&image)?;
/// let refined = Extractor::new(Backend::Cpu, config(Subpixel::Score))?.detect_and_describe(&image)?;
/// assert_eq!(whole.descriptors, refined.descriptors);
/// for (w, r) in whole.keypoints.iter().zip(&refined.keypoints) {
///     // Less than half a pixel of the keypoint's level.
///     let level_pixel = 1.2f32.powi(w.octave);
///     assert!((w.x - r.x).abs() <= 0.5 * level_pixel && (w.y - r.y).abs() <= 0.5 * level_pixel);
/// }
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Subpixel {
    /// Whole pixels of the keypoint's level, mapped to level 0.
    None,
    /// Per axis, the peak of the parabola through the FAST scores of the keypoint and its two
    /// neighbours on its level (0 unless the keypoint's score is strictly above both), in 1/65536
    /// pixel, then mapped to level 0 as a whole position would be. The default.
    #[default]
    Score,
}

/// What orders corners when the strongest are kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Ranking {
    /// The FAST score (the detector's `response`).
    #[default]
    Fast,
    /// As ORB ranks: the strongest `2 · max_keypoints` by FAST score are candidates, ordered by their
    /// Harris response (Sobel gradients over a 7x7 block, `k = 0.04`, integer-exact; see
    /// `docs/numerics.md`). The keypoints' `response` stays the FAST score.
    Harris,
}

/// How the keypoint budget is shared among pyramid levels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum LevelBudget {
    /// The strongest keypoints over all levels together: a textured full-resolution level can take
    /// almost all of them.
    Global,
    /// As ORB shares its features: level `l` gets a share proportional to `scale_factor^-l`
    /// (`max_keypoints · (1 - f) / (1 - f^L) · f^l` with `f = 1 / scale_factor`, rounded; the last
    /// level gets the rest), each level keeps its strongest within its share, and what levels short of
    /// keypoints leave goes to the strongest of the others. The default.
    #[default]
    Geometric,
    /// As [`LevelBudget::Geometric`], but each level's share is proportional to its pixel count
    /// (about `scale_factor^-2l`): the same density of keypoints on every level, so full resolution
    /// keeps a larger part (integer shares: `floor(budget · A_l / A) - floor(budget · A_{l-1} / A)`,
    /// `A_l` the pixels of levels `0..=l`, `A` of all).
    Area,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            threshold: 20,
            max_keypoints: 5000,
            budget_pixels: Some(Self::DEFAULT_BUDGET_PIXELS),
            keypoint_size: Self::DEFAULT_KEYPOINT_SIZE,
            grid: 1,
            level_budget: LevelBudget::Geometric,
            ranking: Ranking::Fast,
            subpixel: Subpixel::Score,
        }
    }
}

impl DetectorConfig {
    /// The default `keypoint_size` of detected keypoints.
    pub const DEFAULT_KEYPOINT_SIZE: f32 = 40.0;

    /// The default [`DetectorConfig::budget_pixels`]: one megapixel (1024x1024), so images of up to
    /// that size keep `max_keypoints` as before budgets followed the image.
    pub const DEFAULT_BUDGET_PIXELS: usize = 1 << 20;

    /// The most [`DetectorConfig::budget`] grows a budget: 4 times `max_keypoints`, so that the
    /// matching work (quadratic in the keypoints for brute force) stays within 16 times that of a
    /// small image.
    pub const MAX_BUDGET_GROWTH: usize = 4;

    with_methods! {
        /// The same settings with this FAST threshold ([`DetectorConfig::threshold`]).
        with_threshold => threshold: u8;
        /// The same settings keeping at most this many keypoints
        /// ([`DetectorConfig::max_keypoints`]).
        with_max_keypoints => max_keypoints: usize;
        /// The same settings with budgets that follow the image this way
        /// ([`DetectorConfig::budget_pixels`]).
        with_budget_pixels => budget_pixels: Option<usize>;
        /// The same settings with this window side for detected keypoints
        /// ([`DetectorConfig::keypoint_size`]).
        with_keypoint_size => keypoint_size: f32;
        /// The same settings spreading keypoints over a `grid` x `grid` division
        /// ([`DetectorConfig::grid`]).
        with_grid => grid: usize;
        /// The same settings sharing the keypoints among pyramid levels this way
        /// ([`DetectorConfig::level_budget`]).
        with_level_budget => level_budget: LevelBudget;
        /// The same settings ranking corners this way ([`DetectorConfig::ranking`]).
        with_ranking => ranking: Ranking;
        /// The same settings refining positions this way ([`DetectorConfig::subpixel`]).
        with_subpixel => subpixel: Subpixel;
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        if self.threshold == 0 || self.threshold == 255 {
            return Err(Error::InvalidConfig {
                field: "threshold",
                value: self.threshold.to_string(),
                reason: "must be in 1..=254",
            });
        }
        if self.max_keypoints == 0 {
            return Err(Error::InvalidConfig {
                field: "max_keypoints",
                value: "0".into(),
                reason: "must be at least 1",
            });
        }
        if self.budget_pixels == Some(0) {
            return Err(Error::InvalidConfig {
                field: "budget_pixels",
                value: "0".into(),
                reason: "must be at least 1 pixel",
            });
        }
        if !(1..=MAX_GRID).contains(&self.grid) {
            return Err(Error::InvalidConfig {
                field: "grid",
                value: self.grid.to_string(),
                reason: "must be in 1..=64",
            });
        }
        crate::describe::check_size(self.keypoint_size).map_err(|reason| Error::InvalidConfig {
            field: "keypoint_size",
            value: self.keypoint_size.to_string(),
            reason,
        })
    }

    /// The keypoint budget of a `width` x `height` image: `max_keypoints`, or on an image of more than
    /// [`DetectorConfig::budget_pixels`] pixels `ceil(max_keypoints · width · height /
    /// budget_pixels)`, at most [`DetectorConfig::MAX_BUDGET_GROWTH`] times `max_keypoints`. Integer
    /// arithmetic on the host: every backend keeps the same number.
    ///
    /// ```
    /// use clatch::DetectorConfig;
    ///
    /// let config = DetectorConfig::default(); // 5000 keypoints up to 2^20 pixels
    /// assert_eq!(config.budget(1024, 1024), 5000); // one megapixel: max_keypoints
    /// assert_eq!(config.budget(640, 480), 5000); // smaller images keep max_keypoints
    /// assert_eq!(config.budget(2048, 1024), 10000);
    /// assert_eq!(config.budget(1712, 1368), 11168); // ceil(5000 · 2342016 / 1048576) = ceil(11167.6)
    /// assert_eq!(config.budget(5616, 3744), 20000); // 20 megapixels: 4 x max_keypoints
    /// assert_eq!(config.with_budget_pixels(None).budget(5616, 3744), 5000);
    /// ```
    pub fn budget(&self, width: usize, height: usize) -> usize {
        let pixels = width as u128 * height as u128;
        match self.budget_pixels {
            Some(p) if p > 0 && pixels > p as u128 => {
                let grown = (self.max_keypoints as u128 * pixels).div_ceil(p as u128);
                let most = self.max_keypoints.saturating_mul(Self::MAX_BUDGET_GROWTH);
                usize::try_from(grown).map_or(most, |g| g.min(most))
            }
            _ => self.max_keypoints,
        }
    }

    /// These settings for a `width` x `height` image: `max_keypoints` replaced by
    /// [`DetectorConfig::budget`], so that both backends detect and select with one number.
    pub(crate) fn for_image(&self, width: usize, height: usize) -> DetectorConfig {
        DetectorConfig {
            max_keypoints: self.budget(width, height),
            budget_pixels: None,
            ..self.clone()
        }
    }

    /// Whether keypoints are chosen by more than the plain top-N, or their positions refined (then
    /// extraction goes through the selection and reporting of [`crate::pyramid`], with a one-level
    /// pyramid when none is configured).
    pub(crate) fn selects(&self) -> bool {
        self.grid > 1
            || self.level_budget != LevelBudget::Global
            || self.ranking != Ranking::Fast
            || self.subpixel != Subpixel::None
    }

    /// The settings each level is detected with before selection: with spreading every corner is a
    /// candidate (the grid chooses), otherwise a level never contributes more than the whole budget.
    pub(crate) fn candidates(&self) -> DetectorConfig {
        DetectorConfig {
            max_keypoints: if self.grid > 1 {
                usize::MAX
            } else if self.ranking == Ranking::Harris {
                self.max_keypoints.saturating_mul(2)
            } else {
                self.max_keypoints
            },
            ..self.clone()
        }
    }

    /// Pixels left free at each border: the rotated window (half-diagonal `size / sqrt 2`) plus one pixel
    /// for bilinear interpolation and one for fixed-point rounding; never less than the orientation disc.
    pub fn margin(&self) -> usize {
        let half_diagonal = self.keypoint_size as f64 * std::f64::consts::FRAC_1_SQRT_2;
        // `as` saturates, so an absurd (unvalidated) size gives a huge margin, never an overflow.
        (half_diagonal.ceil() as usize)
            .saturating_add(2)
            .max(ORIENTATION_RADIUS as usize + 1)
    }
}

/// The FAST-9 score of pixel `(x, y)`: over the 16 arcs of nine contiguous pixels of the circle of
/// radius 3, the largest of the smallest brightness difference to the centre, on the brighter or the
/// darker side (a pixel is a FAST corner at threshold `t` iff its score exceeds `t`). `None` when the circle leaves the
/// image (`x` or `y` within 3 pixels of a border). Detected keypoints carry it as `response`.
///
/// ```
/// use clatch::{GrayView, fast_score};
///
/// let mut pixels = vec![0u8; 16 * 16];
/// pixels[8 * 16 + 8] = 200; // one bright pixel: every circle pixel is 200 darker
/// let image = GrayView::new(&pixels, 16, 16, 16)?;
/// assert_eq!(fast_score(&image, 8, 8), Some(200));
/// assert_eq!(fast_score(&image, 2, 8), None);
/// # Ok::<(), clatch::Error>(())
/// ```
pub fn fast_score(image: &GrayView, x: usize, y: usize) -> Option<i32> {
    // Subtracted, not added: a coordinate near `usize::MAX` must not wrap round into the image.
    let inside = x >= 3
        && y >= 3
        && x < image.width().saturating_sub(3)
        && y < image.height().saturating_sub(3);
    inside.then(|| cpu::fast_score(image, x, y))
}

