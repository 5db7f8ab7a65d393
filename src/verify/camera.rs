//! The cameras of a pair: image size (for COLMAP's watermark test) and, when known, pinhole
//! intrinsics (COLMAP's "prior focal length"; with both known the pair is verified calibrated).

use crate::error::{Error, Result};

/// Pinhole intrinsics in pixels, in clatch's pixel convention (pixel centres at integer coordinates,
/// as [`crate::KeyPoint`]); COLMAP's principal point is `cx + 0.5, cy + 0.5` in its own convention.
///
/// ```
/// use clatch::verify::Intrinsics;
///
/// let k = Intrinsics::new(1200.0, 1200.0, 959.5, 539.5);
/// assert_eq!(k.image_to_camera([959.5 + 1200.0, 539.5]), [1.0, 0.0]);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x, in pixels (positive).
    pub fx: f64,
    /// Focal length along y, in pixels (positive).
    pub fy: f64,
    /// Principal point, column.
    pub cx: f64,
    /// Principal point, row.
    pub cy: f64,
}

impl Intrinsics {
    /// Intrinsics with these focal lengths and principal point.
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self { fx, fy, cx, cy }
    }

    /// `K⁻¹ (x, y, 1)`: `((x − cx) / fx, (y − cy) / fy)`.
    pub fn image_to_camera(&self, p: [f64; 2]) -> [f64; 2] {
        [(p[0] - self.cx) / self.fx, (p[1] - self.cy) / self.fy]
    }

    /// A pixel threshold in camera-normalised units: `threshold / ((fx + fy) / 2)` (COLMAP's
    /// `ImageToWorldThreshold` of a pinhole camera).
    pub fn camera_threshold(&self, threshold: f64) -> f64 {
        threshold / ((self.fx + self.fy) / 2.0)
    }

    fn check(&self, what: &'static str) -> Result<()> {
        for (name, value) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
        ] {
            if !value.is_finite() {
                return Err(Error::InvalidInput {
                    what,
                    reason: format!("{name} = {value} is not finite"),
                });
            }
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(Error::InvalidInput {
                what,
                reason: format!("focal lengths ({}, {}) must be positive", self.fx, self.fy),
            });
        }
        Ok(())
    }
}

/// One view's camera: its image size and, when known, its intrinsics.
///
/// ```
/// use clatch::verify::{Camera, Intrinsics};
///
/// let calibrated = Camera::new(1920, 1080).with_intrinsics(Intrinsics::new(1500.0, 1500.0, 959.5, 539.5));
/// assert!(calibrated.intrinsics.is_some());
/// assert!(Camera::new(1920, 1080).intrinsics.is_none());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Image width in pixels (at least 1).
    pub width: u32,
    /// Image height in pixels (at least 1).
    pub height: u32,
    /// Pinhole intrinsics, when known.
    pub intrinsics: Option<Intrinsics>,
}

impl Camera {
    /// A camera of this image size with unknown intrinsics.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            intrinsics: None,
        }
    }

    /// The same camera with known intrinsics.
    #[must_use]
    pub fn with_intrinsics(self, intrinsics: Intrinsics) -> Self {
        Self {
            intrinsics: Some(intrinsics),
            ..self
        }
    }

    /// `Error::InvalidInput` for an empty image or unusable intrinsics.
    pub(crate) fn check(&self, what: &'static str) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(Error::InvalidInput {
                what,
                reason: format!("image size {}x{} is empty", self.width, self.height),
            });
        }
        self.intrinsics.as_ref().map_or(Ok(()), |k| k.check(what))
    }
}
