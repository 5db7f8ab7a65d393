//! Sub-pixel keypoint positions for structure from motion.
//!
//! FAST keypoints sit on whole pixels, and a whole-pixel position is up to half a pixel off: on its own
//! that is about 0.38 px of mean reprojection error (the mean length of a vector uniform in a unit
//! square), which the mapper cannot remove. Positions written to COLMAP are refined by default with the
//! library's [`crate::Subpixel::Score`] (the peak of the FAST score, on every pyramid level); this
//! module adds the `corner` method ([`Refinement::Corner`]): the corner estimator of Förstner and Gülch
//! (1987), the one behind OpenCV's `cornerSubPix`, the point closest, in the least-squares sense, to
//! the lines through every pixel of a window along which the intensity does not change (each pixel's
//! gradient is normal to its line). Descriptors and matches are untouched: they come from the
//! whole-pixel keypoints, as every backend computes them.

use image::GrayImage;

use crate::detect::Subpixel;
use crate::keypoint::KeyPoint;

/// How the keypoint positions written to COLMAP are refined below a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refinement {
    /// Whole pixels, as detected.
    None,
    /// The library's [`Subpixel::Score`]: the peak of a parabola through the FAST scores of the
    /// keypoint and its 4 neighbours, per axis, on the keypoint's pyramid level.
    Score,
    /// Förstner's least-squares corner over the `(2 radius + 1)²` window around each whole-pixel
    /// keypoint of the photo ([`refine_corners`]).
    Corner {
        /// Half side of the window, in pixels.
        radius: u32,
    },
}

impl Refinement {
    /// The detector's setting: `Score` is the detector's own, the others detect whole pixels.
    pub fn detector_subpixel(self) -> Subpixel {
        match self {
            Refinement::Score => Subpixel::Score,
            Refinement::None | Refinement::Corner { .. } => Subpixel::None,
        }
    }

    /// `keypoints` (as the extractor returned them for `img`) with the host-side refinement, if this
    /// method has one.
    pub fn apply(self, img: &GrayImage, keypoints: Vec<KeyPoint>) -> Vec<KeyPoint> {
        match self {
            Refinement::None | Refinement::Score => keypoints,
            Refinement::Corner { radius } => refine_corners(img, &keypoints, radius),
        }
    }
}

/// Largest shift accepted, in pixels: farther means the window holds no corner to speak of.
const MAX_SHIFT: f64 = 1.0;

/// `keypoints` with `x`, `y` moved to the least-squares corner of the `(2r+1)²` window around each,
/// or left where they are when the window has no well-conditioned corner (edges, flat patches) or
/// the estimate moves farther than one pixel. `r = 0` returns them unchanged.
pub fn refine_corners(img: &GrayImage, keypoints: &[KeyPoint], r: u32) -> Vec<KeyPoint> {
    keypoints
        .iter()
        .map(|k| match corner(img, k.x as i64, k.y as i64, r as i64) {
            Some((x, y)) => KeyPoint {
                x: x as f32,
                y: y as f32,
                ..*k
            },
            None => *k,
        })
        .collect()
}

fn corner(img: &GrayImage, x0: i64, y0: i64, r: i64) -> Option<(f64, f64)> {
    let (w, h) = (img.width() as i64, img.height() as i64);
    if r == 0 || x0 - r - 1 < 0 || y0 - r - 1 < 0 || x0 + r + 1 >= w || y0 + r + 1 >= h {
        return None;
    }
    let at = |x: i64, y: i64| f64::from(img.get_pixel(x as u32, y as u32).0[0]);
    let sigma2 = (r as f64 / 2.0).powi(2).max(0.25);
    // Normal equations of min Σ w (gᵀ (q - p))²: (Σ w g gᵀ) q = Σ w g gᵀ p.
    let (mut a, mut b, mut c, mut bx, mut by) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, y) = (x0 + dx, y0 + dy);
            let gx = (at(x + 1, y) - at(x - 1, y)) / 2.0;
            let gy = (at(x, y + 1) - at(x, y - 1)) / 2.0;
            let wt = (-((dx * dx + dy * dy) as f64) / (2.0 * sigma2)).exp();
            let (gxx, gxy, gyy) = (wt * gx * gx, wt * gx * gy, wt * gy * gy);
            a += gxx;
            b += gxy;
            c += gyy;
            bx += gxx * x as f64 + gxy * y as f64;
            by += gxy * x as f64 + gyy * y as f64;
        }
    }
    let det = a * c - b * b;
    // Both eigenvalues of the structure tensor must be substantial: a corner, not an edge.
    let trace = a + c;
    if trace <= 0.0 || det <= 0.05 * trace * trace {
        return None;
    }
    let qx = (c * bx - b * by) / det;
    let qy = (a * by - b * bx) / det;
    let shift = (qx - x0 as f64).hypot(qy - y0 as f64);
    (shift <= MAX_SHIFT).then_some((qx, qy))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bright quadrant whose corner is at (cx, cy), anti-aliased by area coverage.
    fn quadrant(cx: f64, cy: f64) -> GrayImage {
        GrayImage::from_fn(40, 40, |x, y| {
            let cover = |lo: f64, p: u32| (f64::from(p) + 0.5 - lo).clamp(0.0, 1.0);
            let v = 40.0 + 160.0 * cover(cx, x) * cover(cy, y);
            image::Luma([v.round() as u8])
        })
    }

    #[test]
    fn a_corner_between_pixels_is_found() {
        // Pixel centres are at integers: a corner at (20.3, 19.6) lies between pixel centres.
        let img = quadrant(20.3, 19.6);
        let kp = KeyPoint::new(20.0, 20.0);
        let refined = refine_corners(&img, &[kp], 3)[0];
        assert!((refined.x - 20.3).abs() < 0.15, "{refined:?}");
        assert!((refined.y - 19.6).abs() < 0.15, "{refined:?}");
        assert_eq!(refine_corners(&img, &[kp], 0)[0], kp);
    }

    #[test]
    fn edges_flat_patches_and_borders_stay_put() {
        let edge = GrayImage::from_fn(40, 40, |x, _| image::Luma([if x < 20 { 30 } else { 200 }]));
        let flat = GrayImage::from_pixel(40, 40, image::Luma([90]));
        for img in [&edge, &flat] {
            let kp = KeyPoint::new(20.0, 20.0);
            assert_eq!(refine_corners(img, &[kp], 3)[0], kp);
        }
        let corner_at_border = quadrant(1.2, 1.2);
        let kp = KeyPoint::new(1.0, 1.0);
        assert_eq!(refine_corners(&corner_at_border, &[kp], 3)[0], kp);
    }
}
