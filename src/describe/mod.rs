//! CLATCH description: a rotated, scaled 64x64 window sampled around each keypoint, 512 learned patch
//! triplets compared by weighted sums of squared differences.
//!
//! The numeric contract (every backend reproduces it bit for bit; `docs/numerics.md` has the whole
//! pipeline):
//! 0. **Smoothing** (optional, [`DescriptorConfig::smoothing`]): the image the windows sample is
//!    first replaced by its integer binomial smoothing ([`Smoothing`], [`cpu::smooth`]); everything
//!    below reads that image. Detection never does.
//! 1. **Frame.** `angle` → bin `k` ([`crate::angle::angle_bin`]); `(C, S)` = rotation table entry `k`
//!    (16 fractional bits). `q = round_half_even(size · 256)`. Window steps in 16.16 pixels:
//!    `eu = ((q·C + 2^13) >> 14, (q·S + 2^13) >> 14)` along the window's rows, `ev = (-eu.y, eu.x)`
//!    down its columns. Origin `o = (round_half_even(x · 65536), round_half_even(y · 65536))`.
//! 2. **Sample position** of window pixel `(u, v)`, `u, v` in `0..64`:
//!    `P = o + (u - 32)·eu + (v - 32)·ev` (16.16), then `P8 = (P + 128) >> 8` (24.8, `>>` is a floor).
//! 3. **Fit.** The keypoint is described iff the four corner samples (`u, v` in {0, 63}) satisfy
//!    `0 <= P8 <= 256·(W - 1)` and likewise for y (the samples are affine in `u, v`, so then all do).
//!    Otherwise it is reported in [`crate::Features::skipped`].
//! 4. **Bilinear**: `i = P8 >> 8`, `f = P8 & 255` per axis; neighbours past the last row or column are
//!    clamped (the texture unit's clamp mode); the sample is
//!    `((p00·(256-fx) + p01·fx)·(256-fy) + (p10·(256-fx) + p11·fx)·fy + 2^15) >> 16`, a `u8`.
//! 5. **Bits**: triplet `t` has 8x8 patches with top-left corners `a, b, c` ([`triplets::TRIPLETS`]);
//!    `d = Σ w[r·8+s] · ((A - B)² - (C - B)²)` over the patch pixels in `i32`; bit `t = (d < 0)`,
//!    stored at word `t / 64`, bit `t % 64` (least significant first).

pub mod cpu;
pub mod opencv;
pub mod triplets;

use crate::angle::{angle_bin, rotation_table};
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::error::{Error, Result};
use crate::keypoint::KeyPoint;

/// Side of the sampled window.
pub const WINDOW: usize = 64;
/// Side of a patch.
pub const PATCH: usize = 8;
/// Number of learned triplets.
pub const TRIPLET_COUNT: usize = 512;
/// Smallest and largest keypoint `size` accepted (pixels).
pub const MIN_SIZE: f32 = 1.0;
/// See [`MIN_SIZE`].
pub const MAX_SIZE: f32 = 1024.0;
/// Largest sum of weights: `sum · 255²` must fit the `i32` accumulator.
pub const MAX_WEIGHT_SUM: u64 = i32::MAX as u64 / (255 * 255);

/// Per-pixel weights of the 8x8 patches, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PatchWeights([u32; PATCH * PATCH]);

impl PatchWeights {
    /// Checks the length (64) and that the weighted SSD cannot overflow `i32`.
    pub fn new(weights: &[u32]) -> Result<Self> {
        let array: [u32; PATCH * PATCH] = weights.try_into().map_err(|_| Error::WeightsLength {
            expected: PATCH * PATCH,
            got: weights.len(),
        })?;
        let sum: u64 = array.iter().map(|&w| w as u64).sum();
        if sum > MAX_WEIGHT_SUM {
            return Err(Error::WeightsOverflow {
                sum,
                max: MAX_WEIGHT_SUM,
            });
        }
        if sum == 0 {
            return Err(Error::WeightsAllZero);
        }
        Ok(Self(array))
    }

    /// LATCH's 7x7 patch: weight 1, except row 0 and column 0 which get 0. With `size = 64`, angle 0 and
    /// an integer position this compares exactly OpenCV LATCH's 7x7 patches (without its blur).
    pub fn latch_7x7() -> Self {
        let mut w = [1u32; PATCH * PATCH];
        for i in 0..PATCH {
            w[i] = 0;
            w[i * PATCH] = 0;
        }
        Self(w)
    }

    /// Every pixel weight 1: the plain 8x8 SSD of the original CUDA LATCH.
    pub fn uniform() -> Self {
        Self([1; PATCH * PATCH])
    }

    /// True when every weight is 0 or 1 (a pixel mask): the GPU then uses byte-wise dot products.
    pub fn is_binary(&self) -> bool {
        self.0.iter().all(|&w| w <= 1)
    }

    /// The 64 weights, row-major.
    pub fn as_array(&self) -> &[u32; PATCH * PATCH] {
        &self.0
    }
}

impl Default for PatchWeights {
    fn default() -> Self {
        Self::latch_7x7()
    }
}

/// CLATCH descriptor settings: a rotated, scaled 64x64 window sampled around each keypoint, 512 learned
/// patch triplets compared by weighted sums of squared differences (every rule: [`crate::numerics`],
/// section 4).
///
/// `#[non_exhaustive]`: start from [`DescriptorConfig::default`] and set what differs with the
/// `with_*` methods (or assign the public fields of a value you hold).
///
/// ```
/// use clatch::{DescriptorConfig, DescriptorWidth, PatchWeights, Smoothing};
///
/// let descriptor = DescriptorConfig::default()
///     .with_width(DescriptorWidth::from_bits(256)?)
///     .with_weights(PatchWeights::uniform())
///     .with_smoothing(Smoothing::Binomial5);
/// assert_eq!(descriptor.width.bytes(), 32);
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq, Default)]
#[non_exhaustive]
pub struct DescriptorConfig {
    /// Number of bits (the first `bits` triplets). Default 512.
    pub width: DescriptorWidth,
    /// Patch weights. Default [`PatchWeights::latch_7x7`].
    pub weights: PatchWeights,
    /// Integer smoothing of the image the windows are sampled from (with a pyramid: of each level
    /// before its keypoints are described); detection and orientation always see the unsmoothed
    /// image. Default [`Smoothing::None`].
    pub smoothing: Smoothing,
}

impl DescriptorConfig {
    with_methods! {
        /// The same settings with descriptors of this width ([`DescriptorConfig::width`]).
        with_width => width: DescriptorWidth;
        /// The same settings with these patch weights ([`DescriptorConfig::weights`]).
        with_weights => weights: PatchWeights;
        /// The same settings with this smoothing before sampling ([`DescriptorConfig::smoothing`]).
        with_smoothing => smoothing: Smoothing;
    }
}

/// An integer low-pass filter applied to the image before description samples it
/// ([`crate::numerics`], section 4, step 0).
///
/// Each is a separable binomial kernel `k` of `2r + 1` taps summing to `2^(2r)`; pixel `(x, y)` becomes
/// `(Σ_{i,j} k[i] k[j] I(clamp(x + j - r), clamp(y + i - r)) + 2^(4r - 1)) >> 4r`: one rounding, half
/// up, of the exact sum; coordinates past an edge are clamped to it (the edge pixel is repeated).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Smoothing {
    /// No smoothing: windows sample the image itself.
    #[default]
    None,
    /// `[1 2 1] / 4` on both axes (3x3, `r = 1`, `(Σ + 8) >> 4`).
    Binomial3,
    /// `[1 4 6 4 1] / 16` on both axes (5x5, `r = 2`, `(Σ + 128) >> 8`), close to a Gaussian of
    /// σ = 1 pixel.
    Binomial5,
}

impl Smoothing {
    /// The one-dimensional kernel: binomial coefficients, `2r + 1` taps summing to `2^(2r)` (empty for
    /// [`Smoothing::None`]).
    pub fn taps(self) -> &'static [u16] {
        match self {
            Smoothing::None => &[],
            Smoothing::Binomial3 => &[1, 2, 1],
            Smoothing::Binomial5 => &[1, 4, 6, 4, 1],
        }
    }

    /// The kernel radius `r` (0 for [`Smoothing::None`]).
    pub fn radius(self) -> usize {
        self.taps().len() / 2
    }
}

/// Why a keypoint got no descriptor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SkipReason {
    /// Part of its rotated, scaled window lies outside the image.
    WindowOutsideImage,
    /// OpenCV-compatible LATCH: OpenCV drops it too (its rounded position is within
    /// `24 + half_ssd_size` pixels of an edge; see [`crate::opencv_compat`]).
    OpencvBorder,
    /// OpenCV-compatible LATCH: OpenCV keeps it but reads pixels outside the image for it (`x` or `y`
    /// exactly `k + 0.5` next to the border; see [`crate::opencv_compat`]), so its OpenCV descriptor is undefined.
    OpencvReadsOutsideImage,
}

/// A keypoint that got no descriptor, and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Skipped {
    /// Index into the keypoints passed in.
    pub keypoint: usize,
    /// Why.
    pub reason: SkipReason,
}

/// What a backend's description of a list of keypoints gives, before the façade pairs it with the
/// keypoints as [`crate::Features`].
///
/// Row `i` of `descriptors` belongs to input keypoint `keypoint_index[i]`; every input keypoint appears
/// exactly once, either in `keypoint_index` or in `skipped`. Both lists are in input order.
#[derive(Clone, Debug, PartialEq)]
pub struct Described {
    /// One descriptor per described keypoint.
    pub descriptors: DescriptorSet,
    /// For each descriptor row, the index of its keypoint in the input.
    pub keypoint_index: Vec<usize>,
    /// Keypoints without a descriptor.
    pub skipped: Vec<Skipped>,
}

/// Where a keypoint's window lies in the image, in fixed point (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplingFrame {
    /// Keypoint position, 16.16 fixed point.
    pub origin: [i64; 2],
    /// Step between neighbouring samples of a window row, 16.16.
    pub step_u: [i64; 2],
    /// Step between neighbouring window rows, 16.16.
    pub step_v: [i64; 2],
}

impl SamplingFrame {
    /// The frame of a (validated) keypoint.
    pub fn of(kp: &KeyPoint) -> Self {
        let [c, s] = rotation_table()[angle_bin(kp.angle)];
        let q = (kp.size * 256.0).round_ties_even() as i64;
        let ux = (q * c as i64 + (1 << 13)) >> 14;
        let uy = (q * s as i64 + (1 << 13)) >> 14;
        Self {
            origin: [
                (kp.x * 65536.0).round_ties_even() as i64,
                (kp.y * 65536.0).round_ties_even() as i64,
            ],
            step_u: [ux, uy],
            step_v: [-uy, ux],
        }
    }

    /// Sample position of window pixel `(u, v)` in 24.8 fixed point.
    #[inline]
    pub fn sample_position(&self, u: usize, v: usize) -> [i64; 2] {
        let du = u as i64 - (WINDOW as i64 / 2);
        let dv = v as i64 - (WINDOW as i64 / 2);
        let at = |axis: usize| {
            (self.origin[axis] + du * self.step_u[axis] + dv * self.step_v[axis] + 128) >> 8
        };
        [at(0), at(1)]
    }

    /// True iff every sample lies inside a `width` x `height` image.
    pub fn fits(&self, width: usize, height: usize) -> bool {
        let last = (WINDOW - 1, WINDOW - 1);
        [(0, 0), (last.0, 0), (0, last.1), last]
            .iter()
            .all(|&(u, v)| {
                let [x, y] = self.sample_position(u, v);
                (0..=256 * (width as i64 - 1)).contains(&x)
                    && (0..=256 * (height as i64 - 1)).contains(&y)
            })
    }
}

/// Checks a keypoint size; the error is the reason.
pub(crate) fn check_size(size: f32) -> std::result::Result<(), &'static str> {
    if !size.is_finite() {
        return Err("must be finite");
    }
    if !(MIN_SIZE..=MAX_SIZE).contains(&size) {
        return Err("must be between 1 and 1024 pixels");
    }
    Ok(())
}

/// Checks that every keypoint is finite, inside the image and of a supported size.
pub fn validate_keypoints(keypoints: &[KeyPoint], width: usize, height: usize) -> Result<()> {
    for (index, kp) in keypoints.iter().enumerate() {
        let bad = |field, value, reason| Error::InvalidKeyPoint {
            index,
            field,
            value,
            reason,
        };
        for (field, value, limit) in [("x", kp.x, width), ("y", kp.y, height)] {
            if !value.is_finite() {
                return Err(bad(field, value, "must be finite"));
            }
            if value < 0.0 || value > (limit - 1) as f32 {
                return Err(bad(field, value, "must lie inside the image"));
            }
        }
        check_size(kp.size).map_err(|reason| bad("size", kp.size, reason))?;
        if !kp.angle.is_finite() {
            return Err(bad("angle", kp.angle, "must be finite"));
        }
    }
    Ok(())
}
