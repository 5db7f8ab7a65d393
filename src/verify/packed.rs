//! Many pairs as flat records, the layout of `kernels/clatch.h`'s `clatch_verify_*` structs: what the
//! CUDA twin of [`super::two_view::estimate_two_view`] (`kernels/verify.cu`) reads and writes, and
//! what its host C++ build (`host_twin/`) is compared through. Packing checks nothing: the pairs were
//! checked by the caller ([`super::check_pairs`]). Neighbour consistency, when on, runs here on the
//! host (integer rules, [`super::NeighbourConsistency::kept`]); the device sees the kept matches only,
//! and [`PackedPairs::geometry`] maps their inliers back to the pair's match indices.

// Used by the CUDA backend and the host twin (`internals`) only.
#![cfg_attr(not(any(feature = "cuda", feature = "internals")), allow(dead_code))]

use super::ViewPair;
use super::camera::Intrinsics;
use super::config::VerifyConfig;
use super::essential::EssentialEstimator;
use super::fundamental::FundamentalEstimator;
use super::geometry::{GeometryConfig, InlierCounts, TwoViewGeometry};
use super::homography::HomographyEstimator;
use super::linalg::Mat3;
use super::ransac::RansacSettings;
use super::translation::TranslationEstimator;
use super::two_view::settings;

/// `u32` scratch entries per correspondence on the device: the F, H, E and translation inliers.
pub const LISTS: usize = 4;

/// `clatch_verify_point`: the matched keypoints' positions.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PointRecord {
    pub xa: f32,
    pub ya: f32,
    pub xb: f32,
    pub yb: f32,
}

/// `clatch_verify_ransac`: one estimator's resolved settings.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RansacRecord {
    pub max_residual: f64,
    pub stop_threshold: f64,
    pub min_trials: u32,
    pub max_trials: u32,
}

/// `clatch_verify_settings`: a launch's settings.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SettingsRecord {
    pub fundamental: RansacRecord,
    pub homography: RansacRecord,
    pub essential: RansacRecord,
    pub translation: RansacRecord,
    pub min_e_f_inlier_ratio: f64,
    pub max_h_inlier_ratio: f64,
    pub watermark_min_inlier_ratio: f64,
    pub watermark_border_size: f64,
    pub seed: u64,
    pub min_num_inliers: u64,
    pub detect_watermark: u32,
    pub planar_keeps_homography_inliers: u32,
}

/// `clatch_verify_pair`: one pair of a launch.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PairRecord {
    pub key: u64,
    pub first: u64,
    pub count: u32,
    pub flags: u32,
    pub intrinsics_a: [f64; 4],
    pub intrinsics_b: [f64; 4],
    pub size_a: [f64; 2],
    pub size_b: [f64; 2],
    pub essential_max_residual: f64,
}

/// `clatch_verify_result`: what one pair gives.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ResultRecord {
    pub f: [f64; 9],
    pub e: [f64; 9],
    pub h: [f64; 9],
    pub inliers_e: u64,
    pub inliers_f: u64,
    pub inliers_h: u64,
    pub config: u32,
    pub models: u32,
    pub inlier_count: u32,
    pub pad: u32,
}

/// `CLATCH_VERIFY_CAMERAS`, `CLATCH_VERIFY_INTRINSICS`.
pub const FLAG_CAMERAS: u32 = 1;
pub const FLAG_INTRINSICS: u32 = 2;
/// `CLATCH_VERIFY_HAS_F`, `_E`, `_H`.
pub const HAS_F: u32 = 1;
pub const HAS_E: u32 = 2;
pub const HAS_H: u32 = 4;

fn ransac_record(s: RansacSettings) -> RansacRecord {
    RansacRecord {
        max_residual: s.max_residual,
        stop_threshold: s.stop_threshold,
        min_trials: s.min_trials,
        max_trials: s.max_trials,
    }
}

/// The settings of `config` as the device reads them (the host's `libm` numbers included).
pub fn settings_record(config: &VerifyConfig) -> SettingsRecord {
    let t = config.max_error;
    let ratio = config.min_inlier_ratio;
    SettingsRecord {
        fundamental: ransac_record(settings::<FundamentalEstimator>(config, t, ratio, 0)),
        homography: ransac_record(settings::<HomographyEstimator>(config, t, ratio, 0)),
        // E's threshold depends on the pair's cameras: PairRecord::essential_max_residual.
        essential: ransac_record(settings::<EssentialEstimator>(config, t, ratio, 0)),
        translation: ransac_record(settings::<TranslationEstimator>(
            config,
            t,
            config.watermark_min_inlier_ratio,
            0,
        )),
        min_e_f_inlier_ratio: config.min_e_f_inlier_ratio,
        max_h_inlier_ratio: config.max_h_inlier_ratio,
        watermark_min_inlier_ratio: config.watermark_min_inlier_ratio,
        watermark_border_size: config.watermark_border_size,
        seed: config.seed,
        min_num_inliers: config.min_num_inliers as u64,
        detect_watermark: u32::from(config.detect_watermark),
        planar_keeps_homography_inliers: u32::from(config.planar_keeps_homography_inliers),
    }
}

/// The correspondences a pair's device run sees: every match, or the neighbour-consistent ones.
pub fn kept_matches(pair: &ViewPair<'_>, config: &VerifyConfig) -> Option<Vec<u32>> {
    config
        .neighbour_consistency
        .as_ref()
        .map(|rule| rule.kept(pair.keypoints_a, pair.keypoints_b, pair.matches))
}

/// How many correspondences a pair sends to the device.
pub fn correspondences(pair: &ViewPair<'_>, kept: Option<&[u32]>) -> usize {
    kept.map_or(pair.matches.len(), <[u32]>::len)
}

/// A batch of checked pairs as records: settings, one record per pair, their correspondences
/// back to back (pair `i`'s at `pairs[i].first`).
#[derive(Clone, Debug, Default)]
pub struct PackedPairs {
    pub settings: SettingsRecord,
    pub pairs: Vec<PairRecord>,
    pub points: Vec<PointRecord>,
    kept: Vec<Option<Vec<u32>>>,
}

impl PackedPairs {
    /// Packs `pairs` (checked, with `config` checked), each with its kept matches (`kept[i]`,
    /// [`kept_matches`]).
    pub fn new(pairs: &[ViewPair<'_>], kept: Vec<Option<Vec<u32>>>, config: &VerifyConfig) -> Self {
        let total: usize = pairs
            .iter()
            .zip(&kept)
            .map(|(p, k)| correspondences(p, k.as_deref()))
            .sum();
        let mut points = Vec::with_capacity(total);
        let mut records = Vec::with_capacity(pairs.len());
        for (pair, kept) in pairs.iter().zip(&kept) {
            let first = points.len() as u64;
            let point = |m: &crate::Match| {
                let (a, b) = (
                    &pair.keypoints_a[m.query as usize],
                    &pair.keypoints_b[m.train as usize],
                );
                PointRecord {
                    xa: a.x,
                    ya: a.y,
                    xb: b.x,
                    yb: b.y,
                }
            };
            match kept {
                Some(kept) => points.extend(kept.iter().map(|&i| point(&pair.matches[i as usize]))),
                None => points.extend(pair.matches.iter().map(point)),
            }
            records.push(pair_record(
                pair,
                first,
                points.len() as u64 - first,
                config,
            ));
        }
        Self {
            settings: settings_record(config),
            pairs: records,
            points,
            kept,
        }
    }

    /// Pair `index`'s geometry from its result record and its inliers (`inliers[..inlier_count]`,
    /// indices into its correspondences).
    pub fn geometry(
        &self,
        index: usize,
        result: &ResultRecord,
        inliers: &[u32],
    ) -> TwoViewGeometry {
        let matrix = |flag: u32, m: &[f64; 9]| -> Option<Mat3> {
            (result.models & flag != 0)
                .then(|| [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
        };
        let inliers = &inliers[..result.inlier_count as usize];
        let inliers = match &self.kept[index] {
            Some(kept) => inliers.iter().map(|&i| kept[i as usize]).collect(),
            None => inliers.to_vec(),
        };
        TwoViewGeometry {
            config: GeometryConfig::from_colmap_code(i64::from(result.config))
                .unwrap_or(GeometryConfig::Undefined),
            f: matrix(HAS_F, &result.f),
            e: matrix(HAS_E, &result.e),
            h: matrix(HAS_H, &result.h),
            inliers,
            inlier_counts: InlierCounts {
                e: result.inliers_e as usize,
                f: result.inliers_f as usize,
                h: result.inliers_h as usize,
            },
        }
    }
}

/// The record of one pair whose correspondences start at `first`.
fn pair_record(pair: &ViewPair<'_>, first: u64, count: u64, config: &VerifyConfig) -> PairRecord {
    let mut record = PairRecord {
        key: pair.key,
        first,
        count: count as u32,
        ..PairRecord::default()
    };
    let Some((ca, cb)) = pair.cameras else {
        return record;
    };
    record.flags = FLAG_CAMERAS;
    record.size_a = [f64::from(ca.width), f64::from(ca.height)];
    record.size_b = [f64::from(cb.width), f64::from(cb.height)];
    if let (Some(ka), Some(kb)) = (ca.intrinsics, cb.intrinsics) {
        record.flags |= FLAG_INTRINSICS;
        let k = |k: &Intrinsics| [k.fx, k.fy, k.cx, k.cy];
        record.intrinsics_a = k(&ka);
        record.intrinsics_b = k(&kb);
        let threshold =
            (ka.camera_threshold(config.max_error) + kb.camera_threshold(config.max_error)) / 2.0;
        record.essential_max_residual =
            settings::<EssentialEstimator>(config, threshold, config.min_inlier_ratio, pair.key)
                .max_residual;
    }
    record
}
