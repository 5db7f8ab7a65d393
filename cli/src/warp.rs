//! Warping a gray image by a homography, with bilinear interpolation.

use image::GrayImage;

use crate::homography::Homography;

/// Value given to output pixels whose source lies outside the input.
pub const FILL: u8 = 0;

/// The view of `src` through `h` (which maps `src` pixels to output pixels), `width` x `height`.
///
/// Each output pixel `(x, y)` samples `src` at `h⁻¹(x, y)` bilinearly; samples outside
/// `[0, w - 1] x [0, h - 1]` (or at infinity) get [`FILL`]. Returns `None` if `h` is singular.
pub fn warp(src: &GrayImage, h: &Homography, width: u32, height: u32) -> Option<GrayImage> {
    let inv = h.inverse()?;
    let (sw, sh) = (src.width() as usize, src.height() as usize);
    let data = src.as_raw();
    let at = |x: usize, y: usize| data[y * sw + x] as f64;
    let last_x = sw as f64 - 1.0;
    let last_y = sh as f64 - 1.0;
    let mut out = GrayImage::new(width, height);
    for (x, y, px) in out.enumerate_pixels_mut() {
        px.0[0] = match inv.apply(x as f64, y as f64) {
            Some((sx, sy)) if (0.0..=last_x).contains(&sx) && (0.0..=last_y).contains(&sy) => {
                let (x0, y0) = (sx.floor(), sy.floor());
                let (fx, fy) = (sx - x0, sy - y0);
                let (x0, y0) = (x0 as usize, y0 as usize);
                let (x1, y1) = ((x0 + 1).min(sw - 1), (y0 + 1).min(sh - 1));
                let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
                let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
                (top * (1.0 - fy) + bottom * fy).round().clamp(0.0, 255.0) as u8
            }
            _ => FILL,
        };
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> GrayImage {
        // 4x3 ramp: value 10 x + 50 y.
        GrayImage::from_fn(4, 3, |x, y| image::Luma([(10 * x + 50 * y) as u8]))
    }

    #[test]
    fn identity_copies() {
        let src = tiny();
        let out = warp(&src, &Homography::identity(), 4, 3).unwrap();
        assert_eq!(out, src);
    }

    #[test]
    fn integer_translation_shifts_and_fills() {
        let src = tiny();
        let out = warp(&src, &Homography::translation(1.0, 1.0), 5, 4).unwrap();
        assert_eq!(out.get_pixel(0, 0).0[0], FILL);
        assert_eq!(out.get_pixel(4, 0).0[0], FILL);
        assert_eq!(out.get_pixel(0, 3).0[0], FILL);
        for y in 0..3 {
            for x in 0..4 {
                assert_eq!(out.get_pixel(x + 1, y + 1), src.get_pixel(x, y));
            }
        }
    }

    #[test]
    fn half_pixel_shift_interpolates() {
        let src = tiny();
        // A shift by -0.5 makes output pixel x sample the source at x + 0.5.
        let out = warp(&src, &Homography::translation(-0.5, 0.0), 3, 3).unwrap();
        for y in 0..3 {
            for x in 0..3 {
                let a = src.get_pixel(x, y).0[0] as f64;
                let b = src.get_pixel(x + 1, y).0[0] as f64;
                assert_eq!(out.get_pixel(x, y).0[0], ((a + b) / 2.0).round() as u8);
            }
        }
        // Upscaling by 2: output (2, 2) samples source (1, 1) exactly, (1, 0) the middle of (0,0)-(1,0).
        let out = warp(&src, &Homography::rotation_scale(0.0, 2.0), 7, 5).unwrap();
        assert_eq!(out.get_pixel(2, 2), src.get_pixel(1, 1));
        assert_eq!(out.get_pixel(1, 0).0[0], 5);
        assert_eq!(out.get_pixel(6, 4), src.get_pixel(3, 2));
    }

    #[test]
    fn singular_is_refused() {
        let h = Homography([[0.0; 3]; 3]);
        assert!(warp(&tiny(), &h, 2, 2).is_none());
    }
}
