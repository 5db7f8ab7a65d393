//! From image files and decoded images (the `image` crate) to the 8-bit gray images clatch reads
//! (feature `image`).
//!
//! [`open_gray`] reads a file with its size checked from the header against [`DecodeLimits`] before any
//! pixel buffer is allocated, refuses anything but a regular file, truncated JPEGs and palette PNGs
//! with indices past their palette; [`gray_from_dynamic`] converts what the `image` crate decoded.
//!
//! ```
//! let rgb = image::RgbImage::from_pixel(80, 60, image::Rgb([255, 0, 0]));
//! let gray = clatch::decode::gray_from_dynamic(&image::DynamicImage::ImageRgb8(rgb));
//! let view = clatch::GrayView::try_from(&gray)?;
//! assert_eq!(view.get(0, 0), Some(76)); // OpenCV's RGB2GRAY of pure red
//! # Ok::<(), clatch::Error>(())
//! ```

mod jpeg_end;
mod jpeg_scan;
mod open;
mod palette;

/// What a path that is not a regular file is, in words (kept here, where it was first public).
pub use crate::output::file_kind;
pub use open::{
    DecodeError, DecodeLimits, ImageInfo, MAX_METADATA_BYTES, open_gray, open_gray_with_exif, probe,
};

use crate::error::{Error, Result};
use crate::gray_view::GrayView;

/// Borrows an `image` crate gray image (its rows are packed: stride = width).
impl<'a> TryFrom<&'a image::GrayImage> for GrayView<'a> {
    type Error = Error;

    fn try_from(img: &'a image::GrayImage) -> Result<Self> {
        let (w, h) = (img.width() as usize, img.height() as usize);
        GrayView::new(img.as_raw(), w, h, w)
    }
}

impl crate::gray_view::AsGrayView for image::GrayImage {
    fn gray_view(&self) -> Result<GrayView<'_>> {
        GrayView::try_from(self)
    }
}

/// Luma of one RGB pixel: the weights 0.299, 0.587, 0.114 in 14-bit fixed point (4899, 9617, 1868),
/// rounded half up, the integer form of OpenCV's `COLOR_RGB2GRAY` weights. It is close to OpenCV, not
/// bit-identical: OpenCV 5.0.0's `cvtColor` differs by 1 on 0.26 % of uniformly random pixels
/// (measured on 2026-12-01).
#[inline]
pub fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((r as u32 * 4899 + g as u32 * 9617 + b as u32 * 1868 + (1 << 13)) >> 14) as u8
}

/// Converts an RGB image to gray with [`luma`].
pub fn gray_from_rgb(img: &image::RgbImage) -> image::GrayImage {
    let mut out = image::GrayImage::new(img.width(), img.height());
    for (dst, src) in out.pixels_mut().zip(img.pixels()) {
        dst.0[0] = luma(src.0[0], src.0[1], src.0[2]);
    }
    out
}

/// Converts any decoded image to 8-bit gray; alpha is ignored.
///
/// - 8-bit gray keeps its values; 8-bit colour goes through [`luma`].
/// - 16-bit images (gray, or colour through [`luma`]'s weights on 16-bit values) are scaled **full
///   range**: the image's darkest value becomes 0 and its brightest 255,
///   `round_half_up((v - min) · 255 / (max - min))`. 16-bit files often hold 10- or 12-bit data (a
///   12-bit sensor's 0..4095), which keeping the high byte would turn nearly black. A constant image
///   becomes `round_half_up(v · 255 / 65535)`.
/// - Anything else is converted to 8-bit RGB by the `image` crate, then through [`luma`].
pub fn gray_from_dynamic(img: &image::DynamicImage) -> image::GrayImage {
    use image::DynamicImage as D;
    match img {
        D::ImageLuma8(g) => g.clone(),
        D::ImageLumaA8(_) => img.to_luma8(),
        D::ImageLuma16(g) => full_range(g.width(), g.height(), g.pixels().map(|p| p.0[0])),
        D::ImageLumaA16(g) => full_range(g.width(), g.height(), g.pixels().map(|p| p.0[0])),
        D::ImageRgb16(c) => full_range(c.width(), c.height(), c.pixels().map(|p| luma16(p.0))),
        D::ImageRgba16(c) => full_range(c.width(), c.height(), c.pixels().map(|p| luma16(p.0))),
        other => gray_from_rgb(&other.to_rgb8()),
    }
}

/// [`luma`]'s weights on 16-bit samples (the first three of `rgb`).
fn luma16<const N: usize>(rgb: [u16; N]) -> u16 {
    let [r, g, b] = [rgb[0], rgb[1], rgb[2]].map(u32::from);
    ((r * 4899 + g * 9617 + b * 1868 + (1 << 13)) >> 14) as u16
}

/// 16-bit values, row-major, scaled so that their minimum is 0 and their maximum 255.
fn full_range(
    width: u32,
    height: u32,
    values: impl Iterator<Item = u16> + Clone,
) -> image::GrayImage {
    let (lo, hi) = values
        .clone()
        .fold((u16::MAX, 0), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let scale = |v: u16| -> u8 {
        if hi <= lo {
            return ((u32::from(v) * 255 + 32767) / 65535) as u8;
        }
        let (num, den) = (u32::from(v - lo) * 255, u32::from(hi - lo));
        ((2 * num + den) / (2 * den)) as u8
    };
    let mut out = image::GrayImage::new(width, height);
    for (dst, v) in out.iter_mut().zip(values) {
        *dst = scale(v);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn luma_matches_opencv_weights() {
        assert_eq!(luma(0, 0, 0), 0);
        assert_eq!(luma(255, 255, 255), 255);
        // 0.299 * 255 = 76.245 -> 76; 0.587 * 255 = 149.685 -> 150; 0.114 * 255 = 29.07 -> 29.
        assert_eq!(luma(255, 0, 0), 76);
        assert_eq!(luma(0, 255, 0), 150);
        assert_eq!(luma(0, 0, 255), 29);
    }

    #[test]
    fn conversions_from_image_crate() {
        let rgb =
            image::RgbImage::from_fn(3, 2, |x, y| image::Rgb([x as u8 * 100, y as u8 * 200, 7]));
        let gray = gray_from_rgb(&rgb);
        assert_eq!(gray.get_pixel(2, 1).0[0], luma(200, 200, 7));
        let view = GrayView::try_from(&gray).unwrap();
        assert_eq!(view.at(2, 1), luma(200, 200, 7));
        let dynamic = image::DynamicImage::ImageRgb8(rgb);
        assert_eq!(gray_from_dynamic(&dynamic), gray);
        let empty = image::GrayImage::new(0, 0);
        assert!(GrayView::try_from(&empty).is_err());
    }
}
