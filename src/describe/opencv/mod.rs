//! OpenCV-compatible LATCH: the descriptor of `cv::xfeatures2d::LATCH` (opencv_contrib), bit for bit,
//! on the CPU and on the GPU. `docs/opencv_compat.md` lists how it differs from CLATCH.
//!
//! The numeric contract (OpenCV contrib `modules/xfeatures2d/src/latch.cpp`, commit 2a5154a; checked
//! against `cv2.xfeatures2d.LATCH_create` by `tests/opencv_latch.rs`):
//! 1. **Blur.** If `sigma != 0` the image is blurred by OpenCV's fixed-point 3x3 Gaussian
//!    ([`blur`]); `sigma = 0` uses it as it is.
//! 2. **Border.** With `b = 24 + half_ssd_size`, OpenCV keeps a keypoint iff
//!    `b <= cvRound(x) < W - b` and the same for `y` (`cvRound`: round half to even). We skip those
//!    ([`SkipReason::OpencvBorder`]) and, as a deliberate deviation, also the keypoints OpenCV keeps but
//!    then reads outside the image for (`x = k + 0.5` with `k = W - b - 1` even, whose
//!    `(int)(x + 0.5) = W - b`): [`SkipReason::OpencvReadsOutsideImage`].
//! 3. **Angle.** `r = angle · (f32)(π / 180)` in `f32`; `cos θ = (f32) cos((f64) r)`, likewise `sin`
//!    (OpenCV assigns the `double` `cos` of the promoted angle to a `float`; verified against cv2 on
//!    546 angles where this and `cosf` give different descriptors). A keypoint without orientation
//!    (FAST's `-1`) is rotated by -1 degree, as in OpenCV.
//! 4. **Centres.** Triplet `t` has patch centres `a, b, c` ([`OPENCV_CENTRES`], offsets in [-24, 24]).
//!    With rotation, each centre `(x, y)` becomes `(trunc(x·cos - y·sin), trunc(x·sin + y·cos))` in
//!    `f32` (two products, one difference, no fused multiply-add), clamped to [-24, 24]; the patches stay
//!    axis-aligned. Then `(int)(x + 0.5)`, `(int)(y + 0.5)` (in `f64`) is added.
//! 5. **Bits.** `(2h + 1)²` patches (`h = half_ssd_size`); bit `t` = `SSD(a, b) < SSD(c, b)` (strict),
//!    integer sums. Bit `t` is stored as everywhere in clatch (word `t / 64`, bit `t % 64`);
//!    [`crate::DescriptorSet::to_opencv_bytes`] gives OpenCV's rows (byte `t / 8`, bit `7 - t % 8`).

pub mod blur;
pub mod cpu;

use super::triplets::TRIPLETS;
use super::{SkipReason, Skipped, TRIPLET_COUNT};
use crate::descriptor::DescriptorWidth;
use crate::error::{Error, Result};
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;

/// OpenCV's `PATCH_SIZE / 2`: the largest centre offset.
pub const MAX_OFFSET: i32 = 24;
/// Largest `half_ssd_size` accepted: patches no wider than OpenCV's 48-pixel sampling area (+1).
pub const MAX_HALF_SSD_SIZE: usize = 24;
/// The `bytes` values OpenCV accepts.
pub const OPENCV_BYTES: [usize; 7] = [1, 2, 4, 8, 16, 32, 64];
/// `(float)(CV_PI / 180.f)`: the double quotient rounded to `f32`.
pub const DEGREES_TO_RADIANS: f32 = (std::f64::consts::PI / 180.0) as f32;

/// Offset of our window-corner triplet table from OpenCV's centre offsets.
const WINDOW_TO_CENTRE: i8 = 28;

/// The 512 triplets as OpenCV's patch-centre offsets `[ax, ay, bx, by, cx, cy]` (b is the anchor),
/// in OpenCV's order: [`TRIPLETS`] minus 28.
pub const OPENCV_CENTRES: [[i8; 6]; TRIPLET_COUNT] = {
    let mut out = [[0i8; 6]; TRIPLET_COUNT];
    let mut t = 0;
    while t < TRIPLET_COUNT {
        let mut i = 0;
        while i < 6 {
            out[t][i] = TRIPLETS[t][i] as i8 - WINDOW_TO_CENTRE;
            i += 1;
        }
        t += 1;
    }
    out
};

/// Settings of OpenCV's LATCH, `cv::xfeatures2d::LATCH::create(bytes, rotationInvariance,
/// half_ssd_size, sigma)`, validated. [`crate::Extractor::describe_opencv`] describes with them.
///
/// ```
/// use clatch::OpencvLatch;
///
/// let latch = OpencvLatch::new(32, true, 3, 2.0)?; // OpenCV's defaults
/// assert_eq!(latch.width().bits(), 256);
/// assert!(OpencvLatch::new(3, true, 3, 2.0).is_err()); // OpenCV accepts 1, 2, 4, ..., 64 bytes
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct OpencvLatch {
    width: DescriptorWidth,
    rotation_invariance: bool,
    half_ssd_size: usize,
    sigma: f64,
    /// Outer weight of the blur kernel; `None` when `sigma = 0` (no blur).
    blur_weight: Option<u32>,
}

impl OpencvLatch {
    /// Checks the settings: `bytes` in {1, 2, 4, 8, 16, 32, 64}, `half_ssd_size` at most
    /// 24 (`MAX_HALF_SSD_SIZE`), `sigma` finite (0: no blur; negative: OpenCV's binomial blur) and not one of
    /// the (never seen) values whose fixed-point kernel lies at a rounding tie.
    pub fn new(
        bytes: usize,
        rotation_invariance: bool,
        half_ssd_size: usize,
        sigma: f64,
    ) -> Result<Self> {
        if !OPENCV_BYTES.contains(&bytes) {
            return Err(Error::InvalidConfig {
                field: "bytes",
                value: bytes.to_string(),
                reason: "OpenCV's LATCH takes 1, 2, 4, 8, 16, 32 or 64 bytes",
            });
        }
        if half_ssd_size > MAX_HALF_SSD_SIZE {
            return Err(Error::InvalidConfig {
                field: "half_ssd_size",
                value: half_ssd_size.to_string(),
                reason: "patches may be at most 49x49 pixels (half_ssd_size <= 24)",
            });
        }
        let blur_weight = if sigma == 0.0 {
            None
        } else {
            Some(blur::outer_weight(sigma)?)
        };
        Ok(Self {
            width: DescriptorWidth::from_bytes(bytes)?,
            rotation_invariance,
            half_ssd_size,
            sigma,
            blur_weight,
        })
    }

    /// Descriptor length in bytes.
    pub fn bytes(&self) -> usize {
        self.width.bytes()
    }

    /// Descriptor width (`8 · bytes` bits: the first `8 · bytes` triplets).
    pub fn width(&self) -> DescriptorWidth {
        self.width
    }

    /// Whether patch centres are rotated by the keypoint angle.
    pub fn rotation_invariance(&self) -> bool {
        self.rotation_invariance
    }

    /// Half the side of a patch: patches are `(2h + 1)²` pixels.
    pub fn half_ssd_size(&self) -> usize {
        self.half_ssd_size
    }

    /// The pre-blur's sigma (0: none).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// OpenCV's border: keypoints whose rounded position is closer to an edge are dropped.
    pub fn border(&self) -> usize {
        MAX_OFFSET as usize + self.half_ssd_size
    }

    /// The image the patches are read from: blurred by OpenCV's fixed-point kernel, or `None` when
    /// `sigma = 0` (the input is used as it is).
    pub(crate) fn blurred(&self, image: &GrayView) -> Option<Vec<u8>> {
        self.blur_weight.map(|k| blur::blur3x3(image, k))
    }

    /// Validates the keypoints and splits them into described (with their placement) and skipped.
    pub(crate) fn place(&self, image: &GrayView, keypoints: &[KeyPoint]) -> Result<Placed> {
        let (mut index, mut skipped, mut placements) = (Vec::new(), Vec::new(), Vec::new());
        for (i, kp) in keypoints.iter().enumerate() {
            for (field, value) in [("x", kp.x), ("y", kp.y), ("angle", kp.angle)] {
                if !value.is_finite() {
                    return Err(Error::InvalidKeyPoint {
                        index: i,
                        field,
                        value,
                        reason: "must be finite",
                    });
                }
            }
            match self.border_rule(kp, image.width(), image.height()) {
                Ok(()) => {
                    index.push(i);
                    placements.push(Placement::of(kp, self.rotation_invariance));
                }
                Err(reason) => skipped.push(Skipped {
                    keypoint: i,
                    reason,
                }),
            }
        }
        Ok(Placed {
            keypoint_index: index,
            skipped,
            placements,
        })
    }

    /// OpenCV's border test, made safe (module docs, step 2).
    pub(crate) fn border_rule(
        &self,
        kp: &KeyPoint,
        width: usize,
        height: usize,
    ) -> std::result::Result<(), SkipReason> {
        let b = self.border() as i64;
        for (value, len) in [(kp.x, width as i64), (kp.y, height as i64)] {
            let rounded = value.round_ties_even() as i64;
            if rounded < b || rounded >= len - b {
                return Err(SkipReason::OpencvBorder);
            }
        }
        for (value, len) in [(kp.x, width as i64), (kp.y, height as i64)] {
            if Placement::round(value) as i64 > len - 1 - b {
                return Err(SkipReason::OpencvReadsOutsideImage);
            }
        }
        Ok(())
    }
}

/// Keypoints split by OpenCV's border rule: those described, with their placement, and the skipped.
#[derive(Debug)]
pub struct Placed {
    /// Input index of each described keypoint.
    pub keypoint_index: Vec<usize>,
    /// Keypoints OpenCV would not describe.
    pub skipped: Vec<Skipped>,
    /// Where each described keypoint's patches lie.
    pub placements: Vec<Placement>,
}

impl Default for OpencvLatch {
    /// OpenCV's defaults: `LATCH::create(32, true, 3, 2.0)`.
    fn default() -> Self {
        Self::new(32, true, 3, 2.0).expect("OpenCV's defaults are valid")
    }
}

/// Where a described keypoint's patches go: its rounded position and the rotation (computed on the host
/// for both backends; `cos = 1, sin = 0` without rotation invariance).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Placement {
    /// `(int)(x + 0.5)`.
    pub x: i32,
    /// `(int)(y + 0.5)`.
    pub y: i32,
    /// `cos θ` as OpenCV computes it (module docs, step 3).
    pub cos: f32,
    /// `sin θ`.
    pub sin: f32,
}

impl Placement {
    /// The placement of a keypoint that passed [`OpencvLatch::border_rule`].
    pub fn of(kp: &KeyPoint, rotation_invariance: bool) -> Self {
        let (cos, sin) = if rotation_invariance {
            cos_sin(kp.angle)
        } else {
            (1.0, 0.0)
        };
        Self {
            x: Self::round(kp.x),
            y: Self::round(kp.y),
            cos,
            sin,
        }
    }

    /// `(int)(v + 0.5)` with the sum in `f64` (C++'s `float + double`), truncated toward zero.
    pub fn round(v: f32) -> i32 {
        (v as f64 + 0.5) as i32
    }

    /// Centre `(x, y)` rotated as OpenCV does (module docs, step 4), relative to the keypoint.
    #[inline]
    pub fn rotate(&self, x: i8, y: i8) -> (i32, i32) {
        let (x, y) = (x as f32, y as f32);
        let rx = (x * self.cos - y * self.sin) as i32;
        let ry = (x * self.sin + y * self.cos) as i32;
        (
            rx.clamp(-MAX_OFFSET, MAX_OFFSET),
            ry.clamp(-MAX_OFFSET, MAX_OFFSET),
        )
    }
}

/// OpenCV's `cos θ`, `sin θ` of an angle in degrees: the `f32` radians, `cos`/`sin` in `f64`, rounded to
/// `f32`. `libm`'s (a portable port of musl) rather than the platform's, so every machine gets the
/// same values; they equal glibc's after rounding to `f32` (checked for every `f32` radian in
/// [0, 12.6], i.e. angles within ±720 degrees).
pub fn cos_sin(angle_degrees: f32) -> (f32, f32) {
    let r = (angle_degrees * DEGREES_TO_RADIANS) as f64;
    (libm::cos(r) as f32, libm::sin(r) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_are_validated() {
        for bytes in OPENCV_BYTES {
            assert!(OpencvLatch::new(bytes, true, 3, 2.0).is_ok());
        }
        for bytes in [0, 3, 12, 33, 128] {
            assert!(matches!(
                OpencvLatch::new(bytes, true, 3, 2.0),
                Err(Error::InvalidConfig { field: "bytes", .. })
            ));
        }
        assert!(OpencvLatch::new(32, true, MAX_HALF_SSD_SIZE, 0.0).is_ok());
        assert!(matches!(
            OpencvLatch::new(32, true, MAX_HALF_SSD_SIZE + 1, 0.0),
            Err(Error::InvalidConfig {
                field: "half_ssd_size",
                ..
            })
        ));
        for sigma in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(matches!(
                OpencvLatch::new(32, true, 3, sigma),
                Err(Error::InvalidConfig { field: "sigma", .. })
            ));
        }
        assert_eq!(
            OpencvLatch::default(),
            OpencvLatch::new(32, true, 3, 2.0).unwrap()
        );
    }

    #[test]
    fn centres_are_opencvs_first_rows() {
        // OpenCV's sampling_points_arr starts 13, -6, 19, 19, 23, -4 / 4, 16, 24, -11, 4, -21.
        assert_eq!(OPENCV_CENTRES[0], [13, -6, 19, 19, 23, -4]);
        assert_eq!(OPENCV_CENTRES[1], [4, 16, 24, -11, 4, -21]);
        let all = OPENCV_CENTRES.iter().flatten();
        assert_eq!(all.clone().min(), Some(&-24));
        assert_eq!(all.max(), Some(&24));
    }

    #[test]
    fn border_rule_rounds_half_to_even_and_refuses_reads_outside() {
        // W = 1024, border 27: cvRound keeps 27 ..= 996. x = 26.5 rounds to 26 (dropped), 996.5 to 996
        // (kept by OpenCV, but (int)(996.5 + 0.5) = 997 reads column 1024), 995.5 to 996 (fine: reads
        // up to 996 + 27 = 1023), 996.6 to 997 (dropped).
        let latch = OpencvLatch::default();
        let rule = |x: f32| latch.border_rule(&KeyPoint::new(x, 100.0), 1024, 200);
        assert_eq!(rule(26.5), Err(SkipReason::OpencvBorder));
        assert_eq!(rule(27.5), Ok(()));
        assert_eq!(rule(27.0), Ok(()));
        assert_eq!(rule(995.5), Ok(()));
        assert_eq!(rule(996.4), Ok(()));
        assert_eq!(rule(996.5), Err(SkipReason::OpencvReadsOutsideImage));
        assert_eq!(rule(996.6), Err(SkipReason::OpencvBorder));
        assert_eq!(rule(-3.0), Err(SkipReason::OpencvBorder));
        let column = |y: f32| latch.border_rule(&KeyPoint::new(100.0, y), 1024, 200);
        assert_eq!(column(172.5), Err(SkipReason::OpencvReadsOutsideImage));
        assert_eq!(column(172.4), Ok(()));
    }

    /// `f32(libm cos/sin)` against `f32(platform cos/sin)` (glibc on Linux, what cv2 calls) for the
    /// `f32` radians in `[0, bound]` whose bit patterns are `step` apart.
    fn libm_matches_the_platform(bound: f32, step: u32) -> (u64, u64) {
        let (mut checked, mut differ) = (0, 0);
        let mut bits = 0u32;
        while f32::from_bits(bits) <= bound {
            let r = f32::from_bits(bits) as f64;
            let ours = (libm::cos(r) as f32, libm::sin(r) as f32);
            let platform = (r.cos() as f32, r.sin() as f32);
            checked += 1;
            differ += u64::from(ours != platform);
            bits += step;
        }
        (checked, differ)
    }

    #[test]
    fn libm_cos_sin_equal_the_platforms_after_rounding() {
        let (checked, differ) = libm_matches_the_platform(12.6, 541);
        assert!(checked > 2_000_000);
        assert_eq!(differ, 0, "of {checked} radians");
    }

    #[test]
    #[ignore = "1.1e9 evaluations (a minute in release): cargo test --release --lib every_f32_radian -- --ignored"]
    fn libm_cos_sin_equal_the_platforms_for_every_f32_radian_within_720_degrees() {
        let (checked, differ) = libm_matches_the_platform(12.6, 1);
        println!("{checked} radians checked");
        assert_eq!(differ, 0, "of {checked} radians");
    }

    #[test]
    fn rotation_truncates_toward_zero_and_clamps() {
        let p = Placement::of(&KeyPoint::new(50.0, 50.0).with_angle(45.0), true);
        // 24 · cos 45 - (-24) · sin 45 = 33.9: clamped to 24; 10 · cos 45 - 0 = 7.07: 7;
        // -10 · cos 45 = -7.07: -7 (toward zero, not -8).
        assert_eq!(p.rotate(24, -24), (24, 0));
        assert_eq!(p.rotate(10, 0), (7, 7));
        assert_eq!(p.rotate(-10, 0), (-7, -7));
        let upright = Placement::of(&KeyPoint::new(50.4, 50.5).with_angle(45.0), false);
        assert_eq!((upright.x, upright.y), (50, 51));
        assert_eq!(upright.rotate(-24, 24), (-24, 24));
    }
}
