//! What verification finds for a pair: COLMAP's configuration and models, and the inlier matches.

use super::linalg::{Mat3, mul3, transpose3};

/// The kind of two-view geometry, with COLMAP 3.8's numbering (`TwoViewGeometry::ConfigurationType`,
/// the `config` column of its `two_view_geometries` table): [`GeometryConfig::colmap_code`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(i32)]
pub enum GeometryConfig {
    /// Not estimated.
    Undefined = 0,
    /// Too few inliers for any model.
    Degenerate = 1,
    /// An essential matrix explains the matches (both cameras have intrinsics).
    Calibrated = 2,
    /// A fundamental matrix explains the matches.
    Uncalibrated = 3,
    /// A plane (COLMAP decides it only with a relative pose; not produced here).
    Planar = 4,
    /// A pure rotation (COLMAP decides it only with a relative pose; not produced here).
    Panoramic = 5,
    /// A homography explains (almost) as many matches as the epipolar model: a plane or a rotation.
    PlanarOrPanoramic = 6,
    /// The inliers sit near the border and follow a translation: a watermark or a time stamp.
    Watermark = 7,
    /// Several models (COLMAP's `EstimateMultiple`; not produced here).
    Multiple = 8,
}

impl GeometryConfig {
    /// COLMAP 3.8's integer for this configuration.
    ///
    /// ```
    /// use clatch::verify::GeometryConfig;
    ///
    /// assert_eq!(GeometryConfig::Calibrated.colmap_code(), 2);
    /// assert_eq!(GeometryConfig::PlanarOrPanoramic.colmap_code(), 6);
    /// ```
    pub fn colmap_code(self) -> i32 {
        self as i32
    }

    /// The configuration of a stored `config`, `None` for an integer COLMAP 3.8 does not define.
    ///
    /// ```
    /// use clatch::verify::GeometryConfig;
    ///
    /// assert_eq!(GeometryConfig::from_colmap_code(2), Some(GeometryConfig::Calibrated));
    /// assert_eq!(GeometryConfig::from_colmap_code(9), None);
    /// ```
    pub fn from_colmap_code(code: i64) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|c| i64::from(c.colmap_code()) == code)
    }

    /// Every configuration, in COLMAP's order.
    pub const ALL: [GeometryConfig; 9] = [
        Self::Undefined,
        Self::Degenerate,
        Self::Calibrated,
        Self::Uncalibrated,
        Self::Planar,
        Self::Panoramic,
        Self::PlanarOrPanoramic,
        Self::Watermark,
        Self::Multiple,
    ];
}

/// Inliers of each model LO-RANSAC found (0 for a model not estimated).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InlierCounts {
    /// Of the essential matrix (calibrated pairs only).
    pub e: usize,
    /// Of the fundamental matrix.
    pub f: usize,
    /// Of the homography.
    pub h: usize,
}

/// The geometry of one pair, as COLMAP's `TwoViewGeometry::Estimate` reports it.
///
/// Matrices are row-major and act on clatch's pixel coordinates (pixel centres at integers, as
/// [`crate::KeyPoint`]): `b̂ᵀ F â = 0`, `b̂ ~ H â` for the keypoints `a` of the first image and `b`
/// of the second in homogeneous form; `E` acts on camera-normalised coordinates (`K⁻¹ x`). Each is
/// `None` when its estimation did not succeed (or was not run: `E` without intrinsics for both
/// cameras); its scale is arbitrary.
#[derive(Clone, Debug, PartialEq)]
pub struct TwoViewGeometry {
    /// The configuration COLMAP's rules choose.
    pub config: GeometryConfig,
    /// The fundamental matrix.
    pub f: Option<Mat3>,
    /// The essential matrix.
    pub e: Option<Mat3>,
    /// The homography.
    pub h: Option<Mat3>,
    /// Indices into the pair's matches of the inliers of the chosen model, ascending (empty for
    /// [`GeometryConfig::Degenerate`]).
    pub inliers: Vec<u32>,
    /// Inliers of each model.
    pub inlier_counts: InlierCounts,
}

impl TwoViewGeometry {
    /// The same geometry in COLMAP's pixel convention (pixel centres at `+ 0.5`, as its database
    /// stores keypoints): `F ← Sᵀ F S`, `H ← S⁻¹ H S` with `S` the shift by `−0.5` (clatch's
    /// coordinates of a COLMAP position); `E` (camera coordinates) and the inliers are unchanged.
    ///
    /// ```
    /// use clatch::verify::{GeometryConfig, InlierCounts, TwoViewGeometry};
    ///
    /// let shift = [[1.0, 0.0, 3.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    /// let g = TwoViewGeometry { config: GeometryConfig::PlanarOrPanoramic, f: None, e: None, h: Some(shift),
    ///     inliers: vec![], inlier_counts: InlierCounts::default() };
    /// assert_eq!(g.in_colmap_pixels().h, Some(shift)); // a translation commutes with the shift
    /// ```
    pub fn in_colmap_pixels(&self) -> TwoViewGeometry {
        let shift = [[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]];
        let unshift = [[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]];
        TwoViewGeometry {
            f: self.f.map(|f| mul3(&mul3(&transpose3(&shift), &f), &shift)),
            h: self.h.map(|h| mul3(&mul3(&unshift, &h), &shift)),
            ..self.clone()
        }
    }

    /// A degenerate pair: no model, no inliers.
    pub(crate) fn degenerate(inlier_counts: InlierCounts) -> Self {
        Self {
            config: GeometryConfig::Degenerate,
            f: None,
            e: None,
            h: None,
            inliers: Vec::new(),
            inlier_counts,
        }
    }
}
