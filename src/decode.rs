//! From decoded images (the `image` crate) to the 8-bit gray images clatch reads (feature `image`).
//!
//! ```
//! let rgb = image::RgbImage::from_pixel(80, 60, image::Rgb([255, 0, 0]));
//! let gray = clatch::decode::gray_from_dynamic(&image::DynamicImage::ImageRgb8(rgb));
//! let view = clatch::GrayView::try_from(&gray)?;
//! assert_eq!(view.get(0, 0), Some(76)); // OpenCV's RGB2GRAY of pure red
//! # Ok::<(), clatch::Error>(())
//! ```

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

/// Luma of one RGB pixel with OpenCV's `COLOR_RGB2GRAY` integer weights (0.299, 0.587, 0.114 in 14-bit
/// fixed point, rounded half up), so a colour photo gives the same gray image here as in OpenCV.
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

/// Converts any decoded image to 8-bit gray: gray images keep their values (16-bit ones keep the high
/// byte), colour images go through [`luma`] (alpha is ignored).
pub fn gray_from_dynamic(img: &image::DynamicImage) -> image::GrayImage {
    match img {
        image::DynamicImage::ImageLuma8(g) => g.clone(),
        image::DynamicImage::ImageLumaA8(_)
        | image::DynamicImage::ImageLuma16(_)
        | image::DynamicImage::ImageLumaA16(_) => img.to_luma8(),
        other => gray_from_rgb(&other.to_rgb8()),
    }
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
