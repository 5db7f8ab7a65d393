//! The PINHOLE camera that the database's `cameras` table stores.

use crate::colmap::error::ColmapError;

/// COLMAP's PINHOLE model (model id 1): `fx, fy, cx, cy`, no distortion.
///
/// Coordinates are COLMAP's: the centre of the first pixel is at `(0.5, 0.5)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f64,
    /// Focal length along y, in pixels.
    pub fy: f64,
    /// Principal point x, in pixels.
    pub cx: f64,
    /// Principal point y, in pixels.
    pub cy: f64,
    /// Whether the focal length is known (COLMAP's `prior_focal_length`): a given K is, a guess is not.
    pub focal_is_known: bool,
}

/// Smallest focal length accepted, as a multiple of the larger image side: a pinhole view 176° wide
/// ([`PinholeCamera::validated`]).
pub const MIN_FOCAL_RATIO: f64 = 0.01;

/// Largest focal length accepted, as a multiple of the larger image side: a view 0.6° wide (a
/// 3600 mm lens on a full-frame sensor).
pub const MAX_FOCAL_RATIO: f64 = 100.0;

/// COLMAP's model id of [`PinholeCamera`].
pub const PINHOLE_MODEL_ID: i64 = 1;

/// COLMAP's guess of an unknown focal length, as a multiple of the larger image side
/// (its `ImageReader.default_focal_length_factor`, 1.2 in COLMAP 3.8).
pub const DEFAULT_FOCAL_FACTOR: f64 = 1.2;

impl PinholeCamera {
    /// A camera from a 3x3 intrinsic matrix `K` given as nine whitespace-separated numbers, row-major
    /// (as `K.txt` files of the Strecha and openMVG data sets). K must be
    /// `[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]` up to a skew of 0.
    ///
    /// ```
    /// use clatch::colmap::PinholeCamera;
    /// let k = "2759.48 0 1520.69\n0 2764.16 1006.81\n0 0 1\n";
    /// let camera = PinholeCamera::from_k_text(k, 3072, 2048)?;
    /// assert_eq!((camera.fx, camera.cy), (2759.48, 1006.81));
    /// # Ok::<(), clatch::colmap::ColmapError>(())
    /// ```
    pub fn from_k_text(text: &str, width: u32, height: u32) -> Result<Self, ColmapError> {
        let bad = |reason: String| ColmapError::InvalidCamera { reason };
        let numbers = text
            .split_whitespace()
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| bad(format!("K holds {s:?}, which is not a number")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let k: [f64; 9] = numbers
            .as_slice()
            .try_into()
            .map_err(|_| bad(format!("K needs 9 numbers, found {}", numbers.len())))?;
        if [k[1], k[3], k[6], k[7]] != [0.0; 4] || k[8] != 1.0 {
            return Err(bad(format!(
                "K must be [[fx 0 cx] [0 fy cy] [0 0 1]], got {k:?}"
            )));
        }
        Self {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            focal_is_known: true,
        }
        .validated()
    }

    /// COLMAP's own guess for an image without known intrinsics: focal length
    /// [`DEFAULT_FOCAL_FACTOR`] times the larger side, principal point at the image centre.
    pub fn guess(width: u32, height: u32) -> Result<Self, ColmapError> {
        let focal = DEFAULT_FOCAL_FACTOR * f64::from(width.max(height));
        Self {
            width,
            height,
            fx: focal,
            fy: focal,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
            focal_is_known: false,
        }
        .validated()
    }

    /// Checks sizes and intrinsics: a positive size; finite values; focal lengths between
    /// [`MIN_FOCAL_RATIO`] and [`MAX_FOCAL_RATIO`] times the larger side; the principal point inside
    /// the image (`0 ≤ cx ≤ width`, `0 ≤ cy ≤ height`).
    pub fn validated(self) -> Result<Self, ColmapError> {
        let bad = |reason: String| Err(ColmapError::InvalidCamera { reason });
        if self.width == 0 || self.height == 0 {
            return bad(format!("image size {}x{}", self.width, self.height));
        }
        let finite = [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|v| v.is_finite());
        if !finite || self.fx <= 0.0 || self.fy <= 0.0 {
            return bad(format!(
                "focal lengths must be positive and every value finite: fx {} fy {} cx {} cy {}",
                self.fx, self.fy, self.cx, self.cy
            ));
        }
        // Plausibility against the image (COLMAP's mapper spins for minutes on fx = 1e-300, aborts on
        // 1e308, and fails only at its end on a principal point outside the image).
        let side = f64::from(self.width.max(self.height));
        let (lo, hi) = (side * MIN_FOCAL_RATIO, side * MAX_FOCAL_RATIO);
        for (name, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(lo..=hi).contains(&f) {
                return bad(format!(
                    "{name} {f} is implausible for a {}x{} image: focal lengths must lie between \
                     {MIN_FOCAL_RATIO} and {MAX_FOCAL_RATIO} times the larger side ({lo} to {hi} pixels)",
                    self.width, self.height
                ));
            }
        }
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        if !(0.0..=w).contains(&self.cx) || !(0.0..=h).contains(&self.cy) {
            return bad(format!(
                "the principal point ({}, {}) lies outside the {}x{} image (0..{w}, 0..{h})",
                self.cx, self.cy, self.width, self.height
            ));
        }
        Ok(self)
    }

    /// The `params` blob: four little-endian float64.
    pub fn params_blob(&self) -> Vec<u8> {
        [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn k_files_are_parsed_and_checked() {
        // Trailing spaces and a missing final newline, as in real K.txt files.
        let camera =
            PinholeCamera::from_k_text("2905.88 0 1416 \n0 2905.88 1064\n0 0 1", 2832, 2128)
                .unwrap();
        assert_eq!(camera.fx, 2905.88);
        assert_eq!(camera.cx, 1416.0);
        assert!(camera.focal_is_known);
        for bad in [
            "1 0 1 0 1 1 0 0",
            "1 0 1 0 1 1 0 0 2",
            "1 0 x 0 1 1 0 0 1",
            "0 0 1 0 1 1 0 0 1",
        ] {
            assert!(
                PinholeCamera::from_k_text(bad, 10, 10).is_err(),
                "{bad} should be refused"
            );
        }
    }

    #[test]
    fn implausible_intrinsics_are_refused_against_the_image_size() {
        for (k, needle) in [
            ("1e-300 0 320 0 1e-300 240 0 0 1", "fx 0.00000"),
            ("1e308 0 320 0 1e308 240 0 0 1", "implausible"),
            ("500 0 320 0 1e5 240 0 0 1", "fy 100000 is implausible"),
            ("500 0 9000 0 500 240 0 0 1", "outside the 640x480 image"),
            ("500 0 320 0 500 -1 0 0 1", "outside"),
        ] {
            let e = PinholeCamera::from_k_text(k, 640, 480).unwrap_err();
            assert!(
                e.to_string().contains(needle.split(' ').next().unwrap()),
                "{k}: {e}"
            );
            assert!(matches!(e, ColmapError::InvalidCamera { .. }), "{k}: {e}");
        }
        PinholeCamera::from_k_text("6.4 0 0 0 64000 480 0 0 1", 640, 480).unwrap();
    }

    #[test]
    fn guess_follows_colmap() {
        let camera = PinholeCamera::guess(3000, 2000).unwrap();
        assert_eq!(
            (camera.fx, camera.fy, camera.cx, camera.cy),
            (3600.0, 3600.0, 1500.0, 1000.0)
        );
        assert!(!camera.focal_is_known);
        assert!(PinholeCamera::guess(0, 10).is_err());
        let blob = camera.params_blob();
        assert_eq!(blob.len(), 32);
        assert_eq!(f64::from_le_bytes(blob[24..32].try_into().unwrap()), 1000.0);
    }
}
