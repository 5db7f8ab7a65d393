//! Borrowed 8-bit gray images.

use crate::error::{Error, Result};

/// Largest image side supported. Sample positions are 16.16 fixed point in `i64` on the CPU; the limit
/// keeps `side * 2^16` well inside `i32` on the GPU.
pub const MAX_IMAGE_SIDE: usize = 32_767;

/// Refuses sides above [`MAX_IMAGE_SIDE`] ([`Error::ImageTooLarge`]), so no size can overflow or
/// exhaust memory.
pub(crate) fn check_max_side(width: usize, height: usize) -> Result<()> {
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(Error::ImageTooLarge {
            width,
            height,
            max: MAX_IMAGE_SIDE,
        });
    }
    Ok(())
}

/// Refuses the sides no image can have: 0 ([`Error::EmptyImage`]) or above [`MAX_IMAGE_SIDE`].
pub(crate) fn check_sides(width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::EmptyImage { width, height });
    }
    check_max_side(width, height)
}

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
        check_sides(width, height)?;
        if stride < width {
            return Err(Error::StrideTooSmall { width, stride });
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

    /// Pixel `(x, y)`, or `None` outside the image.
    pub fn get(&self, x: usize, y: usize) -> Option<u8> {
        (x < self.width && y < self.height).then(|| self.at(x, y))
    }

    /// Row `y` (exactly `width` pixels), or `None` past the last row.
    pub fn get_row(&self, y: usize) -> Option<&'a [u8]> {
        (y < self.height).then(|| self.row(y))
    }

    /// Row `y` (exactly `width` pixels). Panics if `y >= height`: internal use after validation.
    #[inline]
    pub(crate) fn row(&self, y: usize) -> &'a [u8] {
        &self.data[y * self.stride..y * self.stride + self.width]
    }

    /// Pixel at `(x, y)`. Panics outside the image: internal use after validation.
    #[inline]
    pub(crate) fn at(&self, x: usize, y: usize) -> u8 {
        self.data[y * self.stride + x]
    }
}

/// Something that holds a gray image: what [`crate::Extractor::detect_and_describe_stream`] takes
/// and keeps alive while the image is being worked on (a decoded image with its metadata, a frame
/// buffer, a view).
pub trait AsGrayView {
    /// The image, borrowed.
    fn gray_view(&self) -> Result<GrayView<'_>>;
}

impl AsGrayView for GrayView<'_> {
    fn gray_view(&self) -> Result<GrayView<'_>> {
        Ok(*self)
    }
}

impl<T: AsGrayView + ?Sized> AsGrayView for &T {
    fn gray_view(&self) -> Result<GrayView<'_>> {
        (**self).gray_view()
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
}
