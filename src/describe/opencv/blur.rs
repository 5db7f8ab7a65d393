//! OpenCV's 3x3 Gaussian pre-blur of LATCH, bit for bit: `cv::GaussianBlur(gray, gray, Size(3, 3),
//! sigma, sigma)` on an 8-bit image, which OpenCV computes in fixed point.
//!
//! The rules (OpenCV `modules/imgproc/src/smooth.dispatch.cpp`, `getGaussianKernelBitExact` and
//! `getGaussianKernelFixedPoint_ED`, and the 8-bit fixed-point filter; checked against cv2 by
//! `tests/opencv_latch.rs`):
//! - the 1-D kernel is `[k, 256 - 2k, k] / 256` with, for `sigma > 0`,
//!   `t = exp(4 · (-0.125 / sigma²))`, `k = round_half_even((t · (1 / (2t + 1))) · 256)` in `f64`
//!   (for sigma 2: `[82, 92, 82]`); for `sigma < 0` OpenCV uses the binomial `[64, 128, 64]`;
//! - horizontal then vertical pass, products summed exactly (16 fraction bits), result
//!   `(sum + 2^15) >> 16` (round half up);
//! - the border is `BORDER_REFLECT_101` (`-1 → 1`, `n → n - 2`).

use crate::error::{Error, Result};
use crate::gray_view::GrayView;

/// Fraction bits of the kernel weights (OpenCV's `ufixedpoint16`).
const KERNEL_FRACTION_BITS: u32 = 8;
/// How far `k · 256` must stay from a rounding tie (`x.5`) so that the last bit of `exp` cannot
/// change `k`: OpenCV's soft-float `exp` and ours agree to far better than this.
const TIE_MARGIN: f64 = 1e-9;

/// The 1-D weight `k` of the outer taps of OpenCV's 3-tap kernel for `sigma` (the centre tap is
/// `256 - 2k`), or why `sigma` is not supported. `sigma = 0` means "no blur" to LATCH and is not a
/// kernel.
pub fn outer_weight(sigma: f64) -> Result<u32> {
    let unsupported = |reason| Error::InvalidConfig {
        field: "sigma",
        value: sigma.to_string(),
        reason,
    };
    if !sigma.is_finite() {
        return Err(unsupported("must be finite"));
    }
    if sigma == 0.0 {
        return Err(unsupported("0 means no blur, not a kernel"));
    }
    if sigma < 0.0 {
        // OpenCV clamps sigma to 0, which selects its fixed binomial [1/4, 1/2, 1/4].
        return Ok(64);
    }
    let scale = -0.125 / (sigma * sigma);
    let t = libm::exp(4.0 * scale);
    let sum = 2.0 * t + 1.0;
    let adjusted = t * (1.0 / sum) * f64::from(1u32 << KERNEL_FRACTION_BITS);
    if (adjusted - adjusted.floor() - 0.5).abs() < TIE_MARGIN {
        return Err(unsupported(
            "its fixed-point kernel weight lies at a rounding tie, where OpenCV's result is not \
             reproducible",
        ));
    }
    Ok(adjusted.round_ties_even() as u32)
}

/// Index `i` of a line of `len` pixels under `BORDER_REFLECT_101`, for `i` in `-1..=len`.
#[inline]
fn reflect_101(i: isize, len: usize) -> usize {
    let last = len as isize - 1;
    if last == 0 {
        return 0;
    }
    let r = if i < 0 {
        -i
    } else if i > last {
        2 * last - i
    } else {
        i
    };
    r as usize
}

/// The blurred image (row-major, stride = width) with outer weight `k` (see [`outer_weight`]).
pub fn blur3x3(image: &GrayView, k: u32) -> Vec<u8> {
    let (w, h) = (image.width(), image.height());
    let kernel = [k, 256 - 2 * k, k];
    // Horizontal pass: 8 fraction bits, at most 255 · 256, exact in u32.
    let mut rows = vec![0u32; w * h];
    for (y, out) in rows.chunks_exact_mut(w).enumerate() {
        let row = image.row(y);
        for (x, o) in out.iter_mut().enumerate() {
            *o = (0..3)
                .map(|j| kernel[j] * row[reflect_101(x as isize + j as isize - 1, w)] as u32)
                .sum();
        }
    }
    // Vertical pass: 16 fraction bits, at most 255 · 65536, exact in u32; round half up.
    let mut out = vec![0u8; w * h];
    for (y, o) in out.chunks_exact_mut(w).enumerate() {
        let taps = [-1isize, 0, 1].map(|d| &rows[reflect_101(y as isize + d, h) * w..][..w]);
        for (x, p) in o.iter_mut().enumerate() {
            let sum: u32 = (0..3).map(|j| kernel[j] * taps[j][x]).sum();
            *p = ((sum + (1 << 15)) >> 16) as u8;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigma_two_is_opencvs_82_92_82() {
        // latch_reference.md, section 3: verified against cv2 5.0.0.
        assert_eq!(outer_weight(2.0), Ok(82));
        assert_eq!(outer_weight(-1.0), Ok(64), "negative sigma: binomial");
        assert_eq!(outer_weight(1e-3), Ok(0), "tiny sigma: identity");
        assert_eq!(outer_weight(1e6), Ok(85), "huge sigma: nearly flat");
        assert!(outer_weight(0.0).is_err());
        assert!(outer_weight(f64::NAN).is_err());
        assert!(outer_weight(f64::INFINITY).is_err());
    }

    #[test]
    fn reflect_101_mirrors_without_repeating_the_edge() {
        assert_eq!(reflect_101(-1, 5), 1);
        assert_eq!(reflect_101(5, 5), 3);
        assert_eq!(reflect_101(2, 5), 2);
        assert_eq!(reflect_101(-1, 1), 0);
        assert_eq!(reflect_101(1, 1), 0);
        assert_eq!(reflect_101(-1, 2), 1);
        assert_eq!(reflect_101(2, 2), 0);
    }

    #[test]
    fn blur_matches_a_direct_2d_sum() {
        // The separable passes must equal the 2-D sum of k_i k_j p over the reflected neighbourhood,
        // rounded half up once, on an image with odd sizes and ties.
        let (w, h) = (7, 5);
        let pixels: Vec<u8> = (0..w * h).map(|i| ((i * 97 + 13) % 256) as u8).collect();
        let image = GrayView::new(&pixels, w, h, w).unwrap();
        for k in [82u32, 64, 0, 85] {
            let kernel = [k, 256 - 2 * k, k];
            let blurred = blur3x3(&image, k);
            for y in 0..h {
                for x in 0..w {
                    let mut sum = 0u64;
                    for (i, dy) in (-1isize..=1).enumerate() {
                        for (j, dx) in (-1isize..=1).enumerate() {
                            let p = image.at(
                                reflect_101(x as isize + dx, w),
                                reflect_101(y as isize + dy, h),
                            );
                            sum += (kernel[i] * kernel[j]) as u64 * p as u64;
                        }
                    }
                    assert_eq!(
                        blurred[y * w + x] as u64,
                        (sum + 32768) >> 16,
                        "k {k} ({x}, {y})"
                    );
                }
            }
        }
        assert_eq!(blur3x3(&image, 0), pixels, "k = 0 is the identity");
    }
}
