//! Borrowed 8-bit gray images and conversions from the `image` crate.

use crate::error::{Error, Result};

/// Largest image side supported. Sample positions are 16.16 fixed point in `i64` on the CPU; the limit
/// keeps `side * 2^16` well inside `i32` on the GPU.
pub const MAX_IMAGE_SIDE: usize = 32_767;

/// A borrowed 8-bit gray image: `height` rows of `width` pixels, row `y` starting at byte `y * stride`.
///
/// Construction checks every size, so code that holds a `GrayView` can index it without further checks.
///
/// ```
/// let pixels = vec![0u8; 100 * 80];
/// let view = clatch::GrayView::new(&pixels, 100, 80, 100).unwrap();
/// assert_eq!((view.width(), view.height()), (100, 80));
/// ```
#[derive(Clone, Copy, Debug)]
pub struct GrayView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> GrayView<'a> {
    /// Wraps `data` as a `width` x `height` image whose rows start `stride` bytes apart.
    pub fn new(data: &'a [u8], width: usize, height: usize, stride: usize) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(Error::EmptyImage { width, height });
        }
        if stride < width {
            return Err(Error::StrideTooSmall { width, stride });
        }
        if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
            return Err(Error::ImageTooLarge {
                width,
                height,
                max: MAX_IMAGE_SIDE,
            });
        }
        let needed = stride
            .checked_mul(height - 1)
            .and_then(|n| n.checked_add(width));
        if needed.is_none_or(|n| data.len() < n) {
            return Err(Error::BufferTooSmall {
                width,
                height,
                stride,
                needed: needed.unwrap_or(usize::MAX),
                got: data.len(),
            });
        }
        Ok(Self {
            data,
            width,
            height,
            stride,
        })
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Bytes from the start of one row to the start of the next.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The underlying bytes (rows `stride` apart).
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Row `y` (exactly `width` pixels). Panics if `y >= height`: internal use after validation.
    #[inline]
    pub fn row(&self, y: usize) -> &'a [u8] {
        &self.data[y * self.stride..y * self.stride + self.width]
    }

    /// Pixel at `(x, y)`. Panics outside the image: internal use after validation.
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> u8 {
        self.data[y * self.stride + x]
    }
}

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
    fn rejects_bad_geometry() {
        let buf = vec![0u8; 100];
        assert!(matches!(
            GrayView::new(&buf, 0, 5, 10),
            Err(Error::EmptyImage { .. })
        ));
        assert!(matches!(
            GrayView::new(&buf, 5, 0, 10),
            Err(Error::EmptyImage { .. })
        ));
        assert!(matches!(
            GrayView::new(&buf, 10, 5, 9),
            Err(Error::StrideTooSmall {
                width: 10,
                stride: 9
            })
        ));
        assert!(matches!(
            GrayView::new(&buf, 10, 11, 10),
            Err(Error::BufferTooSmall {
                needed: 110,
                got: 100,
                ..
            })
        ));
        // The last row needs only `width` bytes, not a whole stride.
        assert!(GrayView::new(&buf, 10, 10, 10).is_ok());
        assert!(GrayView::new(&buf[..94], 4, 10, 10).is_ok());
        assert!(matches!(
            GrayView::new(&buf, 40_000, 1, 40_000),
            Err(Error::ImageTooLarge { .. })
        ));
    }

    #[test]
    fn strided_rows() {
        let buf: Vec<u8> = (0..30).collect();
        let v = GrayView::new(&buf, 4, 3, 10).unwrap();
        assert_eq!(v.row(1), &[10, 11, 12, 13]);
        assert_eq!(v.at(3, 2), 23);
    }

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
