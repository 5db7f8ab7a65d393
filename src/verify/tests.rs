//! The solvers and LO-RANSAC against synthetic scenes with known cameras.

#[path = "../../tests/common/two_view.rs"]
mod scene;

use super::essential::five_point;
use super::fundamental::{eight_point, sampson_error_squared, seven_point};
use super::homography::{homography_dlt, transfer_error_squared};
use super::ransac::{
    Estimator, RansacReport, RansacSettings, lo_ransac, lo_ransac_reference, prior_max_trials,
};
use super::sampler::Stream;
use super::translation::TranslationEstimator;
use super::{
    essential::EssentialEstimator, fundamental::FundamentalEstimator,
    homography::HomographyEstimator,
};
use crate::synthetic::SplitMix64;
use scene::{Scene, Shape, distance_up_to_scale};

/// The camera-normalised points of a scene.
fn normalised(scene: &Scene) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let to_camera = |(f, cx, cy): (f64, f64, f64), p: &[f64; 2]| [(p[0] - cx) / f, (p[1] - cy) / f];
    (
        scene
            .a
            .iter()
            .map(|p| to_camera(scene.camera_a, p))
            .collect(),
        scene
            .b
            .iter()
            .map(|p| to_camera(scene.camera_b, p))
            .collect(),
    )
}

/// The model of `models` closest to `truth` up to scale, and its distance.
fn closest(models: &[[[f64; 3]; 3]], truth: &[[f64; 3]; 3]) -> f64 {
    models
        .iter()
        .map(|m| distance_up_to_scale(m, truth))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn four_point_homography_is_the_plane_s() {
    for seed in 0..20 {
        let s = scene::scene(seed, Shape::Planar, 40, 0.0, 0.0);
        let h = homography_dlt(&s.a[..4], &s.b[..4]).unwrap();
        assert!(
            distance_up_to_scale(&h, s.h.as_ref().unwrap()) < 1e-9,
            "seed {seed}"
        );
        let worst =
            s.a.iter()
                .zip(&s.b)
                .map(|(a, b)| transfer_error_squared(&h, *a, *b))
                .fold(0.0, f64::max);
        assert!(worst < 1e-12, "seed {seed}: {worst}");
    }
}

#[test]
fn least_squares_homography_of_a_rotation() {
    let s = scene::scene(3, Shape::Rotation, 100, 0.0, 0.0);
    let h = homography_dlt(&s.a, &s.b).unwrap();
    assert!(distance_up_to_scale(&h, s.h.as_ref().unwrap()) < 1e-9);
    assert!(
        homography_dlt(&[[1.0, 1.0]; 4], &s.b[..4]).is_none(),
        "coincident points"
    );
}

#[test]
fn seven_point_finds_the_true_fundamental_matrix() {
    for seed in 0..30 {
        let s = scene::scene(seed, Shape::General, 60, 0.0, 0.0);
        let mut models = Vec::new();
        seven_point(&s.a[..7], &s.b[..7], &mut models);
        assert!(
            (1..=3).contains(&models.len()),
            "seed {seed}: {} models",
            models.len()
        );
        assert!(
            closest(&models, &s.f) < 1e-7,
            "seed {seed}: {}",
            closest(&models, &s.f)
        );
        for f in &models {
            let worst = s.a[..7]
                .iter()
                .zip(&s.b[..7])
                .map(|(a, b)| sampson_error_squared(f, *a, *b))
                .fold(0.0, f64::max);
            assert!(worst < 1e-16, "seed {seed}: {worst}");
        }
    }
}

#[test]
fn eight_point_fits_every_correspondence() {
    for seed in 0..10 {
        let s = scene::scene(seed, Shape::General, 100, 0.0, 0.0);
        let f = eight_point(&s.a, &s.b).unwrap();
        assert!(distance_up_to_scale(&f, &s.f) < 1e-8, "seed {seed}");
        let worst =
            s.a.iter()
                .zip(&s.b)
                .map(|(a, b)| sampson_error_squared(&f, *a, *b))
                .fold(0.0, f64::max);
        assert!(worst < 1e-18, "seed {seed}: {worst}");
    }
}

#[test]
fn five_point_finds_the_true_essential_matrix() {
    let mut counts = [0usize; 11];
    for seed in 0..50 {
        let s = scene::scene(seed, Shape::General, 30, 0.0, 0.0);
        let (a, b) = normalised(&s);
        let mut models = Vec::new();
        five_point(&a[..5], &b[..5], &mut models);
        counts[models.len()] += 1;
        assert!(
            closest(&models, &s.e) < 1e-6,
            "seed {seed}: {} models, {}",
            models.len(),
            closest(&models, &s.e)
        );
        // Every model fits its five points and is essential: det E = 0, 2 E Eᵀ E − tr(E Eᵀ) E = 0.
        for e in &models {
            let worst = a[..5]
                .iter()
                .zip(&b[..5])
                .map(|(p, q)| sampson_error_squared(e, *p, *q))
                .fold(0.0, f64::max);
            assert!(worst < 1e-18, "seed {seed}: {worst}");
        }
        // With all thirty points (the local optimisation's least squares) the truth still comes out.
        let mut all = Vec::new();
        five_point(&a, &b, &mut all);
        assert!(closest(&all, &s.e) < 1e-6, "seed {seed}, 30 points");
    }
    assert!(
        counts[0] == 0 && counts[1..].iter().step_by(2).sum::<usize>() == 0,
        "an even number of real roots: {counts:?}"
    );
}

/// LO-RANSAC settings as COLMAP's defaults give them (4 px).
fn settings<E: Estimator>(max_error: f64) -> RansacSettings {
    RansacSettings {
        max_residual: max_error * max_error,
        min_trials: 100,
        max_trials: prior_max_trials(0.25, 0.999, 3.0, E::SAMPLE_SIZE).min(10_000) as u32,
        stop_threshold: 1e-9,
        seed: 1,
        pair: 0,
    }
}

#[test]
fn lo_ransac_separates_outliers_exactly() {
    for (shape, outliers) in [
        (Shape::General, 0.0),
        (Shape::General, 0.3),
        (Shape::General, 0.5),
    ] {
        let s = scene::scene(11, shape, 300, outliers, 0.0);
        let f = lo_ransac::<FundamentalEstimator>(
            &s.a,
            &s.b,
            &settings::<FundamentalEstimator>(4.0),
            Stream::Fundamental,
        );
        assert!(f.success);
        let differ: Vec<_> = (0..300)
            .filter(|&i| f.inlier_mask[i] != s.inlier[i])
            .map(|i| {
                (
                    i,
                    s.inlier[i],
                    scene::sampson(&s.f, s.a[i], s.b[i]),
                    scene::sampson(&f.model.unwrap(), s.a[i], s.b[i]),
                )
            })
            .collect();
        assert!(differ.is_empty(), "F, {outliers} outliers: {differ:?}");
        assert!(distance_up_to_scale(&f.model.unwrap(), &s.f) < 1e-6);
        let (a, b) = normalised(&s);
        let e = lo_ransac::<EssentialEstimator>(
            &a,
            &b,
            &settings::<EssentialEstimator>(4.0 / 950.0),
            Stream::Essential,
        );
        assert_eq!(e.inlier_mask, s.inlier, "E, {outliers} outliers");
        assert!(distance_up_to_scale(&e.model.unwrap(), &s.e) < 1e-6);
    }
    let s = scene::scene(12, Shape::Planar, 300, 0.5, 0.0);
    let h = lo_ransac::<HomographyEstimator>(
        &s.a,
        &s.b,
        &settings::<HomographyEstimator>(4.0),
        Stream::Homography,
    );
    assert_eq!(h.inlier_mask, s.inlier);
    assert!(distance_up_to_scale(&h.model.unwrap(), s.h.as_ref().unwrap()) < 1e-9);
}

#[test]
fn lo_ransac_stops_early_on_clean_data_and_runs_to_the_ceiling_on_noise() {
    let clean = scene::scene(5, Shape::Planar, 200, 0.0, 0.0);
    let h = lo_ransac::<HomographyEstimator>(
        &clean.a,
        &clean.b,
        &settings::<HomographyEstimator>(4.0),
        Stream::Homography,
    );
    assert_eq!(
        h.trials, 101,
        "all inliers: the bound is reached once the minimum (trial index 100) is"
    );
    // Random pairs: nothing beyond chance, so every allowed trial runs.
    let mut rng = scene::Rng::new(9);
    let a: Vec<[f64; 2]> = (0..100)
        .map(|_| [rng.uniform(0.0, 1000.0), rng.uniform(0.0, 1000.0)])
        .collect();
    let b: Vec<[f64; 2]> = (0..100)
        .map(|_| [rng.uniform(0.0, 1000.0), rng.uniform(0.0, 1000.0)])
        .collect();
    let short = RansacSettings {
        max_trials: 300,
        ..settings::<HomographyEstimator>(1.0)
    };
    let h = lo_ransac::<HomographyEstimator>(&a, &b, &short, Stream::Homography);
    assert_eq!(h.trials, 300);
    assert!(h.support.inliers < 20, "{}", h.support.inliers);
}

#[test]
fn lo_ransac_is_a_pure_function_of_its_inputs() {
    let s = scene::scene(21, Shape::General, 200, 0.4, 1.0);
    let run = |seed| {
        let settings = RansacSettings {
            seed,
            ..settings::<FundamentalEstimator>(4.0)
        };
        lo_ransac::<FundamentalEstimator>(&s.a, &s.b, &settings, Stream::Fundamental)
    };
    let (first, second) = (run(3), run(3));
    assert_eq!(
        first.model.map(|m| m.map(|r| r.map(f64::to_bits))),
        second.model.map(|m| m.map(|r| r.map(f64::to_bits)))
    );
    assert_eq!(
        (&first.inlier_mask, first.trials, first.support),
        (&second.inlier_mask, second.trials, second.support)
    );
    // Another seed draws other samples; local optimisation still ends on the same inliers.
    let other = run(4);
    assert_eq!(other.inlier_mask, first.inlier_mask);
}

#[test]
fn too_few_points_is_no_model() {
    let s = scene::scene(1, Shape::General, 6, 0.0, 0.0);
    let f = lo_ransac::<FundamentalEstimator>(
        &s.a,
        &s.b,
        &settings::<FundamentalEstimator>(4.0),
        Stream::Fundamental,
    );
    assert!(!f.success && f.model.is_none() && f.inlier_mask.is_empty() && f.trials == 0);
}

/// Every bit of a report: model, support, success, inlier mask, trials.
fn report_bits<M: Copy>(
    r: &RansacReport<M>,
    bits: impl Fn(M) -> Vec<u64>,
) -> (Option<Vec<u64>>, usize, u64, bool, Vec<bool>, u32) {
    (
        r.model.map(bits),
        r.support.inliers,
        r.support.score,
        r.success,
        r.inlier_mask.clone(),
        r.trials,
    )
}

fn matrix_bits(m: [[f64; 3]; 3]) -> Vec<u64> {
    m.iter().flatten().map(|v| v.to_bits()).collect()
}

fn vector_bits(t: [f64; 2]) -> Vec<u64> {
    t.iter().map(|v| v.to_bits()).collect()
}

/// [`lo_ransac`] and [`lo_ransac_reference`] agree on every bit of their reports.
fn same<E: Estimator>(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    settings: &RansacSettings,
    stream: Stream,
    bits: impl Fn(E::Model) -> Vec<u64>,
    what: &str,
) {
    assert_eq!(
        report_bits(&lo_ransac::<E>(a, b, settings, stream), &bits),
        report_bits(&lo_ransac_reference::<E>(a, b, settings, stream), &bits),
        "{stream:?}, {what}"
    );
}

/// The fast LO-RANSAC (support counted over columns, stopped once a model cannot reach the best)
/// against the straightforward one, on many random pairs: the same models, inliers, scores and trial
/// counts, bit for bit, for every estimator.
#[test]
fn fast_lo_ransac_is_the_reference_bit_for_bit() {
    let mut rng = SplitMix64::new(99);
    for k in 0..48u64 {
        let shape = [Shape::General, Shape::Planar, Shape::Rotation][k as usize % 3];
        let n = [9usize, 20, 60, 150, 400][(rng.next_u64() % 5) as usize];
        let outliers = [0.0, 0.2, 0.45, 0.7, 0.9][(rng.next_u64() % 5) as usize];
        let noise = [0.0, 0.5, 2.0][(rng.next_u64() % 3) as usize];
        let s = scene::scene(500 + k, shape, n, outliers, noise);
        let max_error = [1.0, 4.0][(k % 2) as usize];
        let with_seed = |mut settings: RansacSettings| {
            settings.seed = k;
            settings.pair = k * 7;
            settings.min_trials = [0, 100][(k / 2 % 2) as usize];
            settings.stop_threshold = [1e-9, 1e-3][(k / 4 % 2) as usize];
            settings
        };
        let f = with_seed(settings::<FundamentalEstimator>(max_error));
        let h = with_seed(settings::<HomographyEstimator>(max_error));
        let e = with_seed(settings::<EssentialEstimator>(max_error / 950.0));
        let t = with_seed(settings::<TranslationEstimator>(max_error));
        let (na, nb) = normalised(&s);
        let what = format!("case {k}");
        same::<FundamentalEstimator>(&s.a, &s.b, &f, Stream::Fundamental, matrix_bits, &what);
        same::<HomographyEstimator>(&s.a, &s.b, &h, Stream::Homography, matrix_bits, &what);
        same::<EssentialEstimator>(&na, &nb, &e, Stream::Essential, matrix_bits, &what);
        same::<TranslationEstimator>(&s.a, &s.b, &t, Stream::Translation, vector_bits, &what);
    }
}
