//! Geometric verification of putative matches: for each pair of images, the two-view geometry
//! COLMAP 3.8 would find (`TwoViewGeometry::Estimate`): a fundamental matrix, an essential matrix
//! when both cameras' intrinsics are known, a homography, each by LO-RANSAC, COLMAP's rules to
//! choose among them ([`GeometryConfig`], numbered as COLMAP numbers them), and the inlier matches.
//! One rule differs by default: a planar-or-panoramic pair keeps the homography's inliers, not the
//! under-determined fundamental matrix's larger set
//! ([`VerifyConfig::planar_keeps_homography_inliers`]; off, COLMAP's rule). One more can be turned
//! on, and is in the folder run: RANSAC sees only the matches whose neighbours move with them
//! ([`NeighbourConsistency`], [`VerifyConfig::neighbour_consistency`]), which drops matches one
//! period off on repeated structure. After verification, [`guided_matches`] matches a pair's
//! descriptors again under its geometry (COLMAP's guided matching; on in the folder run).
//!
//! This is the CPU reference, written as the specification a CUDA twin reproduces bit for bit:
//! every solver uses `+ − × ÷` and `sqrt` in `f64` in a written order, roots come from Sturm
//! sequences and bisection (no eigen solver, no trigonometry), samples are counter-based
//! (`(seed, pair key, trial)` decides trial `t`'s sample), and support is an integer. The rules
//! are in [`crate::numerics`], section "Verification".
//!
//! Solvers: homography by normalised DLT (4 points; least squares for local optimisation);
//! fundamental matrix by the 7-point solver (up to 3 models) and the normalised 8-point solver;
//! essential matrix by Nistér's 5-point solver (up to 10 models).
//!
//! ```
//! use clatch::verify::{Camera, GeometryConfig, Intrinsics, VerifyConfig, verify_pair};
//! use clatch::{KeyPoint, Match};
//!
//! // Thirty points of a plane seen by two cameras that differ by a sideways shift: every match
//! // moves 20 pixels to the left.
//! let a: Vec<KeyPoint> = (0..30).map(|i| KeyPoint::new(100.0 + 37.0 * (i % 6) as f32, 80.0 + 41.0 * (i / 6) as f32)).collect();
//! let b: Vec<KeyPoint> = a.iter().map(|k| KeyPoint::new(k.x - 20.0, k.y)).collect();
//! let matches: Vec<Match> = (0..30).map(|i| Match { query: i, train: i, distance: 0 }).collect();
//!
//! let geometry = verify_pair(&a, &b, &matches, None, &VerifyConfig::default())?;
//! assert_eq!(geometry.config, GeometryConfig::PlanarOrPanoramic);
//! assert_eq!(geometry.inliers.len(), 30);
//! # Ok::<(), clatch::Error>(())
//! ```

// Index loops here state the order of the arithmetic, the part of the specification a CUDA twin
// reproduces line by line; iterator chains would hide it.
#![allow(clippy::needless_range_loop)]

mod camera;
mod config;
mod consistency;
mod essential;
mod fundamental;
mod geometry;
mod guided;
mod homography;
mod linalg;
#[cfg(feature = "internals")]
#[doc(hidden)]
pub mod packed;
#[cfg(not(feature = "internals"))]
pub(crate) mod packed;
mod poly;
mod ransac;
mod sampler;
mod translation;
mod two_view;

#[cfg(test)]
mod tests;

pub use camera::{Camera, Intrinsics};
pub use config::VerifyConfig;
pub use consistency::NeighbourConsistency;
pub use geometry::{GeometryConfig, InlierCounts, TwoViewGeometry};
pub use guided::{GuidedMatches, GuidedMatching, guided_matches};

use crate::error::{Error, Result};
use crate::keypoint::KeyPoint;
use crate::matching::Match;
use crate::parallel::*;

/// One pair to verify: the keypoints of both images, the putative matches (`query` indexes
/// `keypoints_a`, `train` indexes `keypoints_b`), the cameras when known, and the pair's key, which
/// with [`VerifyConfig::seed`] fixes every random sample, so that a pair's result depends on its own
/// data only, never on the batch it came in (COLMAP's `pair_id` is a natural key).
#[derive(Clone, Copy, Debug)]
pub struct ViewPair<'a> {
    /// Keypoints of the first image.
    pub keypoints_a: &'a [KeyPoint],
    /// Keypoints of the second image.
    pub keypoints_b: &'a [KeyPoint],
    /// Putative matches.
    pub matches: &'a [Match],
    /// Both cameras, when known: their image sizes allow the watermark test, and with intrinsics for
    /// both the pair is verified calibrated.
    pub cameras: Option<(&'a Camera, &'a Camera)>,
    /// The pair's key for the sampler (default 0).
    pub key: u64,
}

impl<'a> ViewPair<'a> {
    /// A pair with unknown cameras and key 0.
    pub fn new(
        keypoints_a: &'a [KeyPoint],
        keypoints_b: &'a [KeyPoint],
        matches: &'a [Match],
    ) -> Self {
        Self {
            keypoints_a,
            keypoints_b,
            matches,
            cameras: None,
            key: 0,
        }
    }

    /// The same pair with these cameras.
    #[must_use]
    pub fn with_cameras(self, a: &'a Camera, b: &'a Camera) -> Self {
        Self {
            cameras: Some((a, b)),
            ..self
        }
    }

    /// The same pair with this sampler key.
    #[must_use]
    pub fn with_key(self, key: u64) -> Self {
        Self { key, ..self }
    }

    /// `Error::InvalidInput` for a match that names a keypoint not there, a matched keypoint with a
    /// non-finite position, more matches than `u32` counts, or an unusable camera.
    fn check(&self) -> Result<()> {
        if u32::try_from(self.matches.len()).is_err() {
            return Err(Error::InvalidInput {
                what: "matches",
                reason: format!("{} matches; at most 2^32 - 1", self.matches.len()),
            });
        }
        for (i, m) in self.matches.iter().enumerate() {
            for (image, keypoints, index) in [
                ("A", self.keypoints_a, m.query),
                ("B", self.keypoints_b, m.train),
            ] {
                let Some(k) = keypoints.get(index as usize) else {
                    return Err(Error::InvalidInput {
                        what: "match",
                        reason: format!(
                            "match {i} names keypoint {index} of image {image}, which has {}",
                            keypoints.len()
                        ),
                    });
                };
                if !(k.x.is_finite() && k.y.is_finite()) {
                    return Err(Error::InvalidInput {
                        what: "keypoint",
                        reason: format!(
                            "keypoint {index} of image {image} (match {i}) is at ({}, {}), not finite",
                            k.x, k.y
                        ),
                    });
                }
            }
        }
        if let Some((a, b)) = self.cameras {
            a.check("camera A")?;
            b.check("camera B")?;
        }
        Ok(())
    }

    /// Verifies this pair ([`verify_pair`]).
    pub fn verify(&self, config: &VerifyConfig) -> Result<TwoViewGeometry> {
        config.check()?;
        self.check()?;
        Ok(self.estimate(config))
    }

    /// The geometry of a checked pair.
    fn estimate(&self, config: &VerifyConfig) -> TwoViewGeometry {
        let position = |k: &KeyPoint| [f64::from(k.x), f64::from(k.y)];
        let a: Vec<[f64; 2]> = self
            .matches
            .iter()
            .map(|m| position(&self.keypoints_a[m.query as usize]))
            .collect();
        let b: Vec<[f64; 2]> = self
            .matches
            .iter()
            .map(|m| position(&self.keypoints_b[m.train as usize]))
            .collect();
        let Some(rule) = &config.neighbour_consistency else {
            return two_view::estimate_two_view(&a, &b, self.cameras, config, self.key);
        };
        let kept = rule.kept(self.keypoints_a, self.keypoints_b, self.matches);
        let pick = |points: &[[f64; 2]]| -> Vec<[f64; 2]> {
            kept.iter().map(|&i| points[i as usize]).collect()
        };
        let mut geometry =
            two_view::estimate_two_view(&pick(&a), &pick(&b), self.cameras, config, self.key);
        for inlier in &mut geometry.inliers {
            *inlier = kept[*inlier as usize];
        }
        geometry
    }
}

/// The two-view geometry of one pair of images: COLMAP's configuration, `F`, `E` (with intrinsics
/// for both cameras), `H`, and the indices of the inlier matches. `cameras`, when given, enables
/// the watermark test (image sizes) and, with intrinsics for both, the calibrated path. The pair's
/// sampler key is 0 ([`ViewPair::with_key`] for another).
///
/// Errors: `Error::InvalidConfig` for a setting out of range, `Error::InvalidInput` for a match
/// naming a keypoint that is not there, a matched keypoint at a non-finite position, or a camera
/// with an empty image, non-finite intrinsics or a focal length that is not positive.
///
/// ```
/// use clatch::verify::{VerifyConfig, verify_pair};
/// use clatch::{ErrorKind, KeyPoint, Match};
///
/// let a = [KeyPoint::new(1.0, 2.0)];
/// let bad = [Match { query: 0, train: 5, distance: 0 }];
/// let error = verify_pair(&a, &a, &bad, None, &VerifyConfig::default()).unwrap_err();
/// assert_eq!(error.kind(), ErrorKind::InvalidInput);
/// ```
pub fn verify_pair(
    keypoints_a: &[KeyPoint],
    keypoints_b: &[KeyPoint],
    matches: &[Match],
    cameras: Option<(&Camera, &Camera)>,
    config: &VerifyConfig,
) -> Result<TwoViewGeometry> {
    ViewPair {
        keypoints_a,
        keypoints_b,
        matches,
        cameras,
        key: 0,
    }
    .verify(config)
}

/// Verifies many pairs in parallel (rayon with the `cpu` feature); results in input order, each
/// equal to [`ViewPair::verify`] of that pair whatever the thread count. Every pair is checked
/// before any work: the first bad one (in input order) is the error, its message naming the pair.
///
/// [`crate::Verifier`] runs the same on a chosen backend (the CPU or a CUDA device).
pub fn verify_pairs(pairs: &[ViewPair<'_>], config: &VerifyConfig) -> Result<Vec<TwoViewGeometry>> {
    check_pairs(pairs, config)?;
    Ok(pairs.par_iter().map(|pair| pair.estimate(config)).collect())
}

/// The checks of [`verify_pairs`], the same on every backend: the configuration, then every pair in
/// input order, the first bad one's error naming it.
pub(crate) fn check_pairs(pairs: &[ViewPair<'_>], config: &VerifyConfig) -> Result<()> {
    config.check()?;
    for (index, pair) in pairs.iter().enumerate() {
        pair.check().map_err(|error| match error {
            Error::InvalidInput { what, reason } => Error::InvalidInput {
                what,
                reason: format!("pair {index}: {reason}"),
            },
            other => other,
        })?;
    }
    Ok(())
}
