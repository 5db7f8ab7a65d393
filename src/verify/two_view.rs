//! COLMAP 3.8's choice of two-view geometry (`TwoViewGeometry::EstimateCalibrated`,
//! `EstimateUncalibrated`, `DetectWatermark` in `estimators/two_view_geometry.cc`): estimate E (with
//! intrinsics for both cameras), F and H by LO-RANSAC, compare their inlier counts, keep the inliers
//! of the model the rules pick.

use super::camera::{Camera, Intrinsics};
use super::config::VerifyConfig;
use super::essential::EssentialEstimator;
use super::fundamental::FundamentalEstimator;
use super::geometry::{GeometryConfig, InlierCounts, TwoViewGeometry};
use super::homography::HomographyEstimator;
use super::ransac::{Estimator, RansacReport, RansacSettings, lo_ransac, prior_max_trials};
use super::sampler::Stream;
use super::translation::TranslationEstimator;

/// The LO-RANSAC settings of one estimator: squared threshold, trial bounds resolved on the host.
pub(super) fn settings<E: Estimator>(
    config: &VerifyConfig,
    max_error: f64,
    min_inlier_ratio: f64,
    pair: u64,
) -> RansacSettings {
    let prior = prior_max_trials(
        min_inlier_ratio,
        config.confidence,
        config.trials_multiplier,
        E::SAMPLE_SIZE,
    );
    RansacSettings {
        max_residual: max_error * max_error,
        min_trials: config.min_num_trials,
        max_trials: prior.min(u64::from(config.max_num_trials)) as u32,
        stop_threshold: libm::pow(1.0 - config.confidence, config.trials_multiplier),
        seed: config.seed,
        pair,
    }
}

/// LO-RANSAC with the estimator `E`, the pixel (or camera-unit) threshold `max_error` and the
/// configured a-priori inlier ratio.
fn run<E: Estimator>(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    config: &VerifyConfig,
    max_error: f64,
    pair: u64,
    stream: Stream,
) -> RansacReport<E::Model> {
    lo_ransac::<E>(
        a,
        b,
        &settings::<E>(config, max_error, config.min_inlier_ratio, pair),
        stream,
    )
}

/// The successful model of a report.
fn model<M: Copy>(report: &RansacReport<M>) -> Option<M> {
    if report.success { report.model } else { None }
}

/// Indices of the set entries of `mask`.
fn mask_indices(mask: &[bool]) -> Vec<u32> {
    mask.iter()
        .enumerate()
        .filter(|(_, inlier)| **inlier)
        .map(|(i, _)| i as u32)
        .collect()
}

/// COLMAP's `TwoViewGeometry::Estimate` of the correspondences `a[i] ↔ b[i]` (pixels): calibrated
/// when both cameras have intrinsics, else uncalibrated; the watermark test when the cameras are
/// known and it is on.
pub(crate) fn estimate_two_view(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    cameras: Option<(&Camera, &Camera)>,
    config: &VerifyConfig,
    pair: u64,
) -> TwoViewGeometry {
    if a.len() < config.min_num_inliers {
        return TwoViewGeometry::degenerate(InlierCounts::default());
    }
    let intrinsics = cameras.and_then(|(ca, cb)| Some((ca.intrinsics?, cb.intrinsics?)));
    let f = run::<FundamentalEstimator>(a, b, config, config.max_error, pair, Stream::Fundamental);
    let h = run::<HomographyEstimator>(a, b, config, config.max_error, pair, Stream::Homography);
    let e = intrinsics.map(|(ka, kb)| estimate_essential(a, b, &ka, &kb, config, pair));
    let counts = InlierCounts {
        e: e.as_ref().map_or(0, |r| r.support.inliers),
        f: f.support.inliers,
        h: h.support.inliers,
    };
    let chosen = match &e {
        Some(e) => choose_calibrated(e, &f, &h, counts, config),
        None => choose_uncalibrated(&f, &h, counts, config),
    };
    let chosen = planar_inliers(chosen, &h, counts, config);
    let Some((config_type, mask)) = chosen else {
        return TwoViewGeometry::degenerate(counts);
    };
    let inliers = mask_indices(mask);
    let watermark = config.detect_watermark
        && cameras.is_some_and(|(ca, cb)| is_watermark(a, b, &inliers, ca, cb, config, pair));
    TwoViewGeometry {
        config: if watermark {
            GeometryConfig::Watermark
        } else {
            config_type
        },
        f: model(&f),
        e: e.as_ref().and_then(model),
        h: model(&h),
        inliers,
        inlier_counts: counts,
    }
}

/// E on camera-normalised points, with the threshold `(t/f̄_a + t/f̄_b) / 2`.
fn estimate_essential(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    ka: &Intrinsics,
    kb: &Intrinsics,
    config: &VerifyConfig,
    pair: u64,
) -> RansacReport<[[f64; 3]; 3]> {
    let na: Vec<[f64; 2]> = a.iter().map(|p| ka.image_to_camera(*p)).collect();
    let nb: Vec<[f64; 2]> = b.iter().map(|p| kb.image_to_camera(*p)).collect();
    let threshold =
        (ka.camera_threshold(config.max_error) + kb.camera_threshold(config.max_error)) / 2.0;
    run::<EssentialEstimator>(&na, &nb, config, threshold, pair, Stream::Essential)
}

/// `EstimateCalibrated`'s rules: E when it explains nearly as many matches as F, else F; planar or
/// panoramic when H explains most of them; the larger inlier set wins.
fn choose_calibrated<'r, M>(
    e: &'r RansacReport<M>,
    f: &'r RansacReport<M>,
    h: &'r RansacReport<M>,
    counts: InlierCounts,
    config: &VerifyConfig,
) -> Option<(GeometryConfig, &'r [bool])> {
    let min = config.min_num_inliers;
    if (!e.success && !f.success && !h.success)
        || (counts.e < min && counts.f < min && counts.h < min)
    {
        return None;
    }
    let e_f_ratio = counts.e as f64 / counts.f as f64;
    let h_f_ratio = counts.h as f64 / counts.f as f64;
    let h_e_ratio = counts.h as f64 / counts.e as f64;
    if e.success && e_f_ratio > config.min_e_f_inlier_ratio && counts.e >= min {
        // The model with more inliers gives them.
        let (best, mask) = if counts.e >= counts.f {
            (counts.e, &e.inlier_mask)
        } else {
            (counts.f, &f.inlier_mask)
        };
        if h_e_ratio > config.max_h_inlier_ratio {
            let mask = if counts.h > best {
                &h.inlier_mask
            } else {
                mask
            };
            Some((GeometryConfig::PlanarOrPanoramic, mask))
        } else {
            Some((GeometryConfig::Calibrated, mask))
        }
    } else if f.success && counts.f >= min {
        planar_or(
            GeometryConfig::Uncalibrated,
            f,
            h,
            counts,
            h_f_ratio,
            config,
        )
    } else if h.success && counts.h >= min {
        Some((GeometryConfig::PlanarOrPanoramic, &h.inlier_mask))
    } else {
        None
    }
}

/// F's inliers and `otherwise`, or H's (when more) and planar-or-panoramic where H explains more
/// than `max_h_inlier_ratio` of F's inliers.
fn planar_or<'r, M>(
    otherwise: GeometryConfig,
    f: &'r RansacReport<M>,
    h: &'r RansacReport<M>,
    counts: InlierCounts,
    h_f_ratio: f64,
    config: &VerifyConfig,
) -> Option<(GeometryConfig, &'r [bool])> {
    if h_f_ratio > config.max_h_inlier_ratio {
        let mask = if counts.h > counts.f {
            &h.inlier_mask
        } else {
            &f.inlier_mask
        };
        Some((GeometryConfig::PlanarOrPanoramic, mask))
    } else {
        Some((otherwise, &f.inlier_mask))
    }
}

/// `EstimateUncalibrated`'s rules: F's inliers always; planar or panoramic when H explains more than
/// `max_h_inlier_ratio` of them.
fn choose_uncalibrated<'r, M>(
    f: &'r RansacReport<M>,
    h: &'r RansacReport<M>,
    counts: InlierCounts,
    config: &VerifyConfig,
) -> Option<(GeometryConfig, &'r [bool])> {
    let min = config.min_num_inliers;
    if (!f.success && !h.success) || (counts.f < min && counts.h < min) {
        return None;
    }
    let h_f_ratio = counts.h as f64 / counts.f as f64;
    let config_type = if h_f_ratio > config.max_h_inlier_ratio {
        GeometryConfig::PlanarOrPanoramic
    } else {
        GeometryConfig::Uncalibrated
    };
    // COLMAP keeps F's inlier mask here even when H has more inliers (or F did not succeed).
    Some((config_type, &f.inlier_mask))
}

/// The inliers a planar-or-panoramic pair keeps: H's (when H succeeded with enough of them) with
/// [`VerifyConfig::planar_keeps_homography_inliers`], else what COLMAP's rules chose.
fn planar_inliers<'r, M>(
    chosen: Option<(GeometryConfig, &'r [bool])>,
    h: &'r RansacReport<M>,
    counts: InlierCounts,
    config: &VerifyConfig,
) -> Option<(GeometryConfig, &'r [bool])> {
    match chosen {
        Some((GeometryConfig::PlanarOrPanoramic, _))
            if config.planar_keeps_homography_inliers
                && h.success
                && counts.h >= config.min_num_inliers =>
        {
            Some((GeometryConfig::PlanarOrPanoramic, &h.inlier_mask))
        }
        other => other,
    }
}

/// `DetectWatermark`: most inliers lie in the border band of both images, and most of them follow
/// one translation. Positions are tested in COLMAP's pixel convention (centres at `+ 0.5`).
fn is_watermark(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    inliers: &[u32],
    ca: &Camera,
    cb: &Camera,
    config: &VerifyConfig,
    pair: u64,
) -> bool {
    if inliers.is_empty() {
        return false;
    }
    let inner_box = |camera: &Camera| {
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        let border = config.watermark_border_size * (w * w + h * h).sqrt();
        move |p: [f64; 2]| {
            let (x, y) = (p[0] + 0.5, p[1] + 0.5);
            x >= border && x <= w - border && y >= border && y <= h - border
        }
    };
    let (inside_a, inside_b) = (inner_box(ca), inner_box(cb));
    let (points_a, points_b): (Vec<_>, Vec<_>) = inliers
        .iter()
        .map(|&i| (a[i as usize], b[i as usize]))
        .unzip();
    let in_border = points_a
        .iter()
        .zip(&points_b)
        .filter(|(pa, pb)| !inside_a(**pa) && !inside_b(**pb))
        .count();
    let count = inliers.len() as f64;
    if (in_border as f64) / count < config.watermark_min_inlier_ratio {
        return false;
    }
    let settings = settings::<TranslationEstimator>(
        config,
        config.max_error,
        config.watermark_min_inlier_ratio,
        pair,
    );
    let report =
        lo_ransac::<TranslationEstimator>(&points_a, &points_b, &settings, Stream::Translation);
    (report.support.inliers as f64) / count >= config.watermark_min_inlier_ratio
}
