//! A second view of an image through a known homography (bilinear): the test views of the demo and
//! of the evaluation's synthetic pairs, whose ground truth is the homography itself.

use super::Homography;
use crate::error::Result;
use crate::gray_view::{GrayView, check_sides};

/// Value given to output pixels whose source lies outside the input.
pub const FILL: u8 = 0;

/// The view of `src` through `h` (which maps `src` pixels to output pixels): `width * height` pixels,
/// row-major.
///
/// Each output pixel `(x, y)` samples `src` at `h⁻¹(x, y)` bilinearly, rounded; samples outside
/// `[0, w - 1] x [0, h - 1]`, at infinity, or of a singular `h` get [`FILL`]. Sides of 0 are
/// [`Error::EmptyImage`](crate::Error::EmptyImage), above [`MAX_IMAGE_SIDE`](crate::MAX_IMAGE_SIDE)
/// [`Error::ImageTooLarge`](crate::Error::ImageTooLarge).
pub fn warp(src: &GrayView<'_>, h: &Homography, width: usize, height: usize) -> Result<Vec<u8>> {
    check_sides(width, height)?;
    let mut out = vec![FILL; width * height];
    let Some(inv) = h.inverse() else {
        return Ok(out);
    };
    let (sw, sh) = (src.width(), src.height());
    let at = |x: usize, y: usize| src.at(x, y) as f64;
    let (last_x, last_y) = (sw as f64 - 1.0, sh as f64 - 1.0);
    for (i, px) in out.iter_mut().enumerate() {
        let (x, y) = ((i % width) as f64, (i / width) as f64);
        let Some((sx, sy)) = inv.apply(x, y) else {
            continue;
        };
        if !(0.0..=last_x).contains(&sx) || !(0.0..=last_y).contains(&sy) {
            continue;
        }
        let (x0, y0) = (sx.floor(), sy.floor());
        let (fx, fy) = (sx - x0, sy - y0);
        let (x0, y0) = (x0 as usize, y0 as usize);
        let (x1, y1) = ((x0 + 1).min(sw - 1), (y0 + 1).min(sh - 1));
        let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
        let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
        *px = (top * (1.0 - fy) + bottom * fy).round().clamp(0.0, 255.0) as u8;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::gray_view::MAX_IMAGE_SIDE;

    /// 4x3 ramp: value 10 x + 50 y.
    const RAMP: [u8; 12] = [0, 10, 20, 30, 50, 60, 70, 80, 100, 110, 120, 130];

    fn ramp() -> GrayView<'static> {
        GrayView::new(&RAMP, 4, 3, 4).unwrap()
    }

    #[test]
    fn identity_copies() {
        assert_eq!(warp(&ramp(), &Homography::identity(), 4, 3).unwrap(), RAMP);
    }

    #[test]
    fn integer_translation_shifts_and_fills() {
        let out = warp(&ramp(), &Homography::translation(1.0, 1.0), 5, 4).unwrap();
        for (x, y) in [(0, 0), (4, 0), (0, 3)] {
            assert_eq!(out[y * 5 + x], FILL);
        }
        for y in 0..3 {
            for x in 0..4 {
                assert_eq!(out[(y + 1) * 5 + x + 1], RAMP[y * 4 + x]);
            }
        }
    }

    #[test]
    fn half_pixel_shift_interpolates() {
        // A shift by -0.5 makes output pixel x sample the source at x + 0.5.
        let out = warp(&ramp(), &Homography::translation(-0.5, 0.0), 3, 3).unwrap();
        for y in 0..3 {
            for x in 0..3 {
                let (a, b) = (RAMP[y * 4 + x] as f64, RAMP[y * 4 + x + 1] as f64);
                assert_eq!(out[y * 3 + x], ((a + b) / 2.0).round() as u8);
            }
        }
        // Upscaling by 2: output (2, 2) samples source (1, 1) exactly, (1, 0) the middle of (0,0)-(1,0).
        let out = warp(&ramp(), &Homography::rotation_scale(0.0, 2.0), 7, 5).unwrap();
        assert_eq!(out[2 * 7 + 2], RAMP[4 + 1]);
        assert_eq!(out[1], 5);
        assert_eq!(out[4 * 7 + 6], RAMP[2 * 4 + 3]);
    }

    #[test]
    fn a_singular_map_gives_fill_and_bad_sizes_are_typed_errors() {
        let singular = Homography::from_rows([[0.0; 3]; 3]);
        assert_eq!(warp(&ramp(), &singular, 2, 2).unwrap(), [FILL; 4]);
        let id = Homography::identity();
        assert!(matches!(
            warp(&ramp(), &id, 0, 3),
            Err(Error::EmptyImage { .. })
        ));
        assert!(matches!(
            warp(&ramp(), &id, MAX_IMAGE_SIDE + 1, 1),
            Err(Error::ImageTooLarge { .. })
        ));
    }
}
