//! The settings of verification: COLMAP 3.8's `TwoViewGeometry::Options` and `RANSACOptions` with
//! their defaults (as its matcher sets them), and the seed of the counter-based sampler.

use crate::error::{Error, Result};

/// How pairs are verified. The defaults are COLMAP 3.8's for geometric verification.
///
/// `#[non_exhaustive]`: start from [`VerifyConfig::default`] and change what differs with the
/// `with_*` methods.
///
/// ```
/// use clatch::verify::VerifyConfig;
///
/// let config = VerifyConfig::default().with_max_error(2.0).with_seed(42);
/// assert_eq!((config.max_error, config.min_num_inliers, config.seed), (2.0, 15, 42));
/// ```
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct VerifyConfig {
    /// Inlier threshold in pixels: the Sampson distance for F (and for E, converted with the mean
    /// focal length of the two cameras), the transfer distance for H. Default 4.
    pub max_error: f64,
    /// Confidence that an outlier-free sample was drawn, in (0, 1). Default 0.999.
    pub confidence: f64,
    /// Factor on the dynamic trial count (COLMAP's `dyn_num_trials_multiplier`). Default 3.
    pub trials_multiplier: f64,
    /// Trials always run. Default 100.
    pub min_num_trials: u32,
    /// Trials at most. Default 10 000.
    pub max_num_trials: u32,
    /// A-priori inlier ratio that lowers the trial ceiling, in [0, 1]. Default 0.25.
    pub min_inlier_ratio: f64,
    /// Fewest inliers for any model to count. Default 15.
    pub min_num_inliers: usize,
    /// E's inliers over F's above which a calibrated pair is [`super::GeometryConfig::Calibrated`].
    /// Default 0.95.
    pub min_e_f_inlier_ratio: f64,
    /// H's inliers over E's (or F's) above which a pair is planar or panoramic. Default 0.8.
    pub max_h_inlier_ratio: f64,
    /// Test for watermarks (needs the cameras' image sizes). Default true.
    pub detect_watermark: bool,
    /// Share of inliers in the border, and of those following a translation, that make a watermark.
    /// Default 0.7.
    pub watermark_min_inlier_ratio: f64,
    /// Width of the border as a share of the image diagonal. Default 0.1.
    pub watermark_border_size: f64,
    /// Seed of the sampler: with the pair's key, it fixes every sample. Default 0.
    pub seed: u64,
    /// Whether a planar-or-panoramic pair keeps the homography's inliers (default true) rather than
    /// the larger set, often the fundamental matrix's, as COLMAP 3.8 does (false). Where a homography
    /// explains the matches, F is under-determined: its epipolar lines are one choice among many, and
    /// the matches it adds to H's lie on those lines, not on the true ones (on repeated structure, a
    /// window matched to its neighbour).
    pub planar_keeps_homography_inliers: bool,
    /// Before RANSAC, keep only the matches whose neighbours in the first image move with them into
    /// the second ([`super::NeighbourConsistency`]: drops matches one period off on repeated
    /// structure). The geometry's inliers still index the pair's matches. Default `None` (COLMAP 3.8's
    /// verification; a general scene of sparse points at very different depths has neighbours that do
    /// not move alike). The folder run turns it on ([`crate::colmap::FolderJob::default_verification`]):
    /// on the generated facades it took the verified inliers within 4 px of the true correspondence
    /// from 61-77 % to 97-99 % (EVALUATION.md, "repeated structure: neighbour consistency").
    pub neighbour_consistency: Option<super::NeighbourConsistency>,
}

impl Default for VerifyConfig {
    fn default() -> Self {
        Self {
            max_error: 4.0,
            confidence: 0.999,
            trials_multiplier: 3.0,
            min_num_trials: 100,
            max_num_trials: 10_000,
            min_inlier_ratio: 0.25,
            min_num_inliers: 15,
            min_e_f_inlier_ratio: 0.95,
            max_h_inlier_ratio: 0.8,
            detect_watermark: true,
            watermark_min_inlier_ratio: 0.7,
            watermark_border_size: 0.1,
            seed: 0,
            planar_keeps_homography_inliers: true,
            neighbour_consistency: None,
        }
    }
}

impl VerifyConfig {
    with_methods! {
        /// The same settings with this neighbour rule ([`VerifyConfig::neighbour_consistency`]).
        with_neighbour_consistency => neighbour_consistency: Option<super::NeighbourConsistency>;
        /// The same settings with this inlier threshold ([`VerifyConfig::max_error`], pixels).
        with_max_error => max_error: f64;
        /// The same settings with this confidence ([`VerifyConfig::confidence`]).
        with_confidence => confidence: f64;
        /// The same settings with this trial multiplier ([`VerifyConfig::trials_multiplier`]).
        with_trials_multiplier => trials_multiplier: f64;
        /// The same settings with this minimum trial count ([`VerifyConfig::min_num_trials`]).
        with_min_num_trials => min_num_trials: u32;
        /// The same settings with this maximum trial count ([`VerifyConfig::max_num_trials`]).
        with_max_num_trials => max_num_trials: u32;
        /// The same settings with this a-priori inlier ratio ([`VerifyConfig::min_inlier_ratio`]).
        with_min_inlier_ratio => min_inlier_ratio: f64;
        /// The same settings with this inlier minimum ([`VerifyConfig::min_num_inliers`]).
        with_min_num_inliers => min_num_inliers: usize;
        /// The same settings with this E/F ratio ([`VerifyConfig::min_e_f_inlier_ratio`]).
        with_min_e_f_inlier_ratio => min_e_f_inlier_ratio: f64;
        /// The same settings with this H ratio ([`VerifyConfig::max_h_inlier_ratio`]).
        with_max_h_inlier_ratio => max_h_inlier_ratio: f64;
        /// The same settings with the watermark test on or off ([`VerifyConfig::detect_watermark`]).
        with_detect_watermark => detect_watermark: bool;
        /// The same settings with this watermark ratio ([`VerifyConfig::watermark_min_inlier_ratio`]).
        with_watermark_min_inlier_ratio => watermark_min_inlier_ratio: f64;
        /// The same settings with this border ([`VerifyConfig::watermark_border_size`]).
        with_watermark_border_size => watermark_border_size: f64;
        /// The same settings with this sampler seed ([`VerifyConfig::seed`]).
        with_seed => seed: u64;
        /// The same settings with this inlier rule for planar-or-panoramic pairs
        /// ([`VerifyConfig::planar_keeps_homography_inliers`]).
        with_planar_keeps_homography_inliers => planar_keeps_homography_inliers: bool;
    }

    /// `Error::InvalidConfig` for a setting out of its range.
    pub(crate) fn check(&self) -> Result<()> {
        let invalid = |field: &'static str, value: String, reason: &'static str| {
            Err(Error::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        let open_unit = |v: f64| v.is_finite() && v > 0.0 && v < 1.0;
        let closed_unit = |v: f64| v.is_finite() && (0.0..=1.0).contains(&v);
        if !(self.max_error.is_finite() && self.max_error > 0.0) {
            return invalid(
                "max_error",
                self.max_error.to_string(),
                "must be finite and positive",
            );
        }
        if !open_unit(self.confidence) {
            return invalid(
                "confidence",
                self.confidence.to_string(),
                "must be in (0, 1)",
            );
        }
        if !(self.trials_multiplier.is_finite() && self.trials_multiplier > 0.0) {
            return invalid(
                "trials_multiplier",
                self.trials_multiplier.to_string(),
                "must be finite and positive",
            );
        }
        if self.max_num_trials == 0 {
            return invalid("max_num_trials", "0".into(), "must be at least 1");
        }
        if self.min_num_trials > self.max_num_trials {
            return invalid(
                "min_num_trials",
                self.min_num_trials.to_string(),
                "must not exceed max_num_trials",
            );
        }
        for (field, value) in [
            ("min_inlier_ratio", self.min_inlier_ratio),
            ("min_e_f_inlier_ratio", self.min_e_f_inlier_ratio),
            ("max_h_inlier_ratio", self.max_h_inlier_ratio),
            (
                "watermark_min_inlier_ratio",
                self.watermark_min_inlier_ratio,
            ),
        ] {
            if !closed_unit(value) {
                return invalid(field, value.to_string(), "must be in [0, 1]");
            }
        }
        if !(self.watermark_border_size.is_finite()
            && (0.0..0.5).contains(&self.watermark_border_size))
        {
            return invalid(
                "watermark_border_size",
                self.watermark_border_size.to_string(),
                "must be in [0, 0.5)",
            );
        }
        Ok(())
    }
}
