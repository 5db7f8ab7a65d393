//! Geometric verification through the public API: synthetic two-view scenes with known cameras
//! (general, planar, pure rotation; outliers; noise), COLMAP's configuration, the recovered models
//! against the truth, exact inlier sets, determinism across calls and thread counts, typed errors.

mod common;

use clatch::verify::{
    Camera, GeometryConfig, Intrinsics, TwoViewGeometry, VerifyConfig, ViewPair, verify_pair,
    verify_pairs,
};
use clatch::{ErrorKind, KeyPoint, Match};
use common::two_view::{Rng, Scene, Shape, distance_up_to_scale, sampson, scene, transfer};

/// A scene as the library takes it: keypoints of B stored in a shuffled order (so that `train`
/// indices differ from `query` ones), one match per correspondence, and both cameras.
struct Pair {
    scene: Scene,
    keypoints_a: Vec<KeyPoint>,
    keypoints_b: Vec<KeyPoint>,
    matches: Vec<Match>,
    camera_a: Camera,
    camera_b: Camera,
}

impl Pair {
    fn new(scene: Scene) -> Self {
        let n = scene.a.len();
        // Image B's keypoint of correspondence i sits at (7 i + 3) mod n (n is never a multiple of 7).
        let slot = |i: usize| (7 * i + 3) % n;
        let keypoints_a = scene
            .a
            .iter()
            .map(|p| KeyPoint::new(p[0] as f32, p[1] as f32))
            .collect();
        let mut keypoints_b = vec![KeyPoint::new(0.0, 0.0); n];
        for (i, p) in scene.b.iter().enumerate() {
            keypoints_b[slot(i)] = KeyPoint::new(p[0] as f32, p[1] as f32);
        }
        let matches = (0..n)
            .map(|i| Match {
                query: i as u32,
                train: slot(i) as u32,
                distance: 0,
            })
            .collect();
        let camera = |(f, cx, cy): (f64, f64, f64)| {
            Camera::new(scene.width, scene.height).with_intrinsics(Intrinsics::new(f, f, cx, cy))
        };
        let (camera_a, camera_b) = (camera(scene.camera_a), camera(scene.camera_b));
        Self {
            scene,
            keypoints_a,
            keypoints_b,
            matches,
            camera_a,
            camera_b,
        }
    }

    fn calibrated(&self) -> ViewPair<'_> {
        self.uncalibrated()
            .with_cameras(&self.camera_a, &self.camera_b)
    }

    fn uncalibrated(&self) -> ViewPair<'_> {
        ViewPair::new(&self.keypoints_a, &self.keypoints_b, &self.matches)
    }

    /// The indices of the true inliers.
    fn true_inliers(&self) -> Vec<u32> {
        (0..self.matches.len() as u32)
            .filter(|&i| self.scene.inlier[i as usize])
            .collect()
    }
}

/// Matches `i ↔ i` for `i < n`.
fn identity_matches(n: u32) -> Vec<Match> {
    (0..n)
        .map(|i| Match {
            query: i,
            train: i,
            distance: 0,
        })
        .collect()
}

fn verify(pair: ViewPair<'_>) -> TwoViewGeometry {
    pair.verify(&VerifyConfig::default()).unwrap()
}

#[test]
fn general_scene_calibrated_is_calibrated_with_the_exact_inliers() {
    for (seed, outliers) in [(1, 0.0), (2, 0.3), (3, 0.7)] {
        let pair = Pair::new(scene(seed, Shape::General, 400, outliers, 0.0));
        let g = verify(pair.calibrated());
        assert_eq!(
            g.config,
            GeometryConfig::Calibrated,
            "{outliers} outliers: {:?}",
            g.inlier_counts
        );
        assert_eq!(g.inliers, pair.true_inliers(), "{outliers} outliers");
        let e = g.e.expect("calibrated pairs have E");
        assert!(
            distance_up_to_scale(&e, &pair.scene.e) < 1e-5,
            "{outliers}: E {e:?}"
        );
        let f = g.f.expect("F is estimated too");
        assert!(
            distance_up_to_scale(&f, &pair.scene.f) < 1e-4,
            "{outliers}: F {f:?}"
        );
        assert!(
            g.inlier_counts.h < g.inlier_counts.e / 2,
            "{:?}",
            g.inlier_counts
        );
    }
}

#[test]
fn general_scene_uncalibrated_is_uncalibrated_with_the_exact_inliers() {
    for (seed, outliers) in [(4, 0.0), (5, 0.3), (6, 0.5)] {
        let pair = Pair::new(scene(seed, Shape::General, 400, outliers, 0.0));
        // Cameras of known size without intrinsics: the watermark test runs, E does not.
        let sizes = (Camera::new(1024, 768), Camera::new(1024, 768));
        let g = verify(pair.uncalibrated().with_cameras(&sizes.0, &sizes.1));
        assert_eq!(
            g.config,
            GeometryConfig::Uncalibrated,
            "{outliers}: {:?}",
            g.inlier_counts
        );
        assert_eq!(g.e, None);
        assert_eq!(g.inliers, pair.true_inliers(), "{outliers} outliers");
        let f = g.f.unwrap();
        let worst = pair
            .scene
            .a
            .iter()
            .zip(&pair.scene.b)
            .zip(&pair.scene.inlier)
            .filter(|(_, inlier)| **inlier)
            .map(|((a, b), _)| sampson(&f, *a, *b))
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{outliers}: worst inlier Sampson {worst} px²");
        assert!(distance_up_to_scale(&f, &pair.scene.f) < 1e-4);
    }
}

#[test]
fn planar_scene_is_planar_or_panoramic_with_the_true_homography() {
    for (seed, outliers) in [(7, 0.0), (8, 0.4)] {
        let pair = Pair::new(scene(seed, Shape::Planar, 300, outliers, 0.0));
        let truth = pair.true_inliers();
        for g in [verify(pair.calibrated()), verify(pair.uncalibrated())] {
            assert_eq!(
                g.config,
                GeometryConfig::PlanarOrPanoramic,
                "{:?}",
                g.inlier_counts
            );
            assert_eq!(g.inlier_counts.h, truth.len());
            // H's inliers, the true ones, outliers or not.
            assert_eq!(g.inliers, truth);
            let h = g.h.unwrap();
            assert!(
                distance_up_to_scale(&h, pair.scene.h.as_ref().unwrap()) < 1e-6,
                "{h:?}"
            );
        }
    }
}

#[test]
fn colmaps_rule_keeps_the_larger_inlier_set_of_a_planar_pair() {
    // COLMAP reports F's inliers unless H has more; on a plane F is under-determined, and outliers
    // near its epipolar lines join them. Every true inlier is there; without outliers exactly those.
    let colmap = VerifyConfig::default().with_planar_keeps_homography_inliers(false);
    let mut joined = 0;
    for (seed, outliers) in [(7, 0.0), (8, 0.4)] {
        let pair = Pair::new(scene(seed, Shape::Planar, 300, outliers, 0.0));
        let truth = pair.true_inliers();
        for view in [pair.calibrated(), pair.uncalibrated()] {
            let g = view.verify(&colmap).unwrap();
            assert_eq!(g.config, GeometryConfig::PlanarOrPanoramic);
            assert!(truth.iter().all(|i| g.inliers.binary_search(i).is_ok()));
            if outliers == 0.0 {
                assert_eq!(g.inliers, truth);
            }
            joined += g.inliers.len() - truth.len();
        }
    }
    assert!(
        joined > 0,
        "no outlier joined F's inliers: the two rules were not told apart"
    );
}

#[test]
fn pure_rotation_is_planar_or_panoramic() {
    let pair = Pair::new(scene(9, Shape::Rotation, 300, 0.3, 0.0));
    let g = verify(pair.calibrated());
    assert_eq!(
        g.config,
        GeometryConfig::PlanarOrPanoramic,
        "{:?}",
        g.inlier_counts
    );
    assert_eq!(g.inlier_counts.h, pair.true_inliers().len());
    let h = g.h.unwrap();
    assert!(distance_up_to_scale(&h, pair.scene.h.as_ref().unwrap()) < 1e-6);
    let worst = pair
        .true_inliers()
        .iter()
        .map(|&i| transfer(&h, pair.scene.a[i as usize], pair.scene.b[i as usize]))
        .fold(0.0, f64::max);
    assert!(worst < 1e-6, "{worst}");
}

#[test]
fn noisy_scenes_keep_nearly_every_inlier_and_no_outlier() {
    // One pixel of noise against a four-pixel threshold (30 px between outliers and the truth).
    for (seed, calibrated) in [(10, true), (11, false)] {
        let pair = Pair::new(scene(seed, Shape::General, 500, 0.4, 1.0));
        let g = verify(if calibrated {
            pair.calibrated()
        } else {
            pair.uncalibrated()
        });
        let expected = if calibrated {
            GeometryConfig::Calibrated
        } else {
            GeometryConfig::Uncalibrated
        };
        assert_eq!(g.config, expected);
        let truth = pair.true_inliers();
        let kept = g
            .inliers
            .iter()
            .filter(|i| truth.binary_search(i).is_ok())
            .count();
        assert_eq!(kept, g.inliers.len(), "no outlier is kept");
        assert!(
            kept as f64 >= 0.97 * truth.len() as f64,
            "{kept} of {}",
            truth.len()
        );
    }
}

#[test]
fn too_few_or_random_matches_are_degenerate() {
    let pair = Pair::new(scene(12, Shape::General, 14, 0.0, 0.0));
    let g = verify(pair.calibrated());
    assert_eq!(
        (g.config, g.inliers.len(), g.f),
        (GeometryConfig::Degenerate, 0, None)
    );
    let mut rng = Rng::new(5);
    let mut random = || {
        (0..200)
            .map(|_| {
                KeyPoint::new(
                    rng.uniform(0.0, 1024.0) as f32,
                    rng.uniform(0.0, 768.0) as f32,
                )
            })
            .collect::<Vec<_>>()
    };
    let (a, b) = (random(), random());
    let matches = identity_matches(200);
    let g = verify_pair(
        &a,
        &b,
        &matches,
        None,
        &VerifyConfig::default().with_max_error(0.5),
    )
    .unwrap();
    assert_eq!(
        g.config,
        GeometryConfig::Degenerate,
        "{:?}",
        g.inlier_counts
    );
}

#[test]
fn a_translation_in_the_border_is_a_watermark() {
    // Sixty matches that stay in place in the bottom band of both images (a time stamp), some of
    // them moved by a pixel.
    let mut rng = Rng::new(3);
    let a: Vec<KeyPoint> = (0..60)
        .map(|_| {
            KeyPoint::new(
                rng.uniform(20.0, 1000.0) as f32,
                rng.uniform(700.0, 760.0) as f32,
            )
        })
        .collect();
    let b: Vec<KeyPoint> = a
        .iter()
        .enumerate()
        .map(|(i, k)| KeyPoint::new(k.x + (i % 2) as f32, k.y))
        .collect();
    let matches = identity_matches(60);
    let camera = Camera::new(1024, 768);
    let g = verify_pair(
        &a,
        &b,
        &matches,
        Some((&camera, &camera)),
        &VerifyConfig::default(),
    )
    .unwrap();
    assert_eq!(g.config, GeometryConfig::Watermark, "{:?}", g.inlier_counts);
    let off = VerifyConfig::default().with_detect_watermark(false);
    let g = verify_pair(&a, &b, &matches, Some((&camera, &camera)), &off).unwrap();
    assert_ne!(g.config, GeometryConfig::Watermark);
    // Without the cameras' sizes there is no border to test.
    assert_ne!(
        verify_pair(&a, &b, &matches, None, &VerifyConfig::default())
            .unwrap()
            .config,
        GeometryConfig::Watermark
    );
}

/// Every bit of a geometry, for comparisons that NaN or signed zeros cannot fool.
fn bits(g: &TwoViewGeometry) -> (i32, Vec<u64>, Vec<u32>, [usize; 3]) {
    let matrices = [g.f, g.e, g.h]
        .into_iter()
        .flat_map(|m| m.into_iter().flatten().flatten().map(f64::to_bits))
        .collect();
    (
        g.config.colmap_code(),
        matrices,
        g.inliers.clone(),
        [g.inlier_counts.e, g.inlier_counts.f, g.inlier_counts.h],
    )
}

#[test]
fn results_are_the_same_twice_and_with_any_thread_count() {
    let pairs: Vec<Pair> = (0..6)
        .map(|k| {
            Pair::new(scene(
                20 + k,
                [Shape::General, Shape::Planar][k as usize % 2],
                250,
                0.4,
                0.7,
            ))
        })
        .collect();
    let views: Vec<ViewPair<'_>> = pairs
        .iter()
        .enumerate()
        .map(|(k, p)| {
            if k % 3 == 0 {
                p.uncalibrated()
            } else {
                p.calibrated()
            }
            .with_key(k as u64)
        })
        .collect();
    let config = VerifyConfig::default().with_seed(17);
    let in_pool = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| verify_pairs(&views, &config))
            .unwrap()
            .iter()
            .map(bits)
            .collect::<Vec<_>>()
    };
    let one = in_pool(1);
    assert_eq!(one, in_pool(2));
    assert_eq!(one, in_pool(2), "twice");
    let alone: Vec<_> = views
        .iter()
        .map(|v| bits(&v.verify(&config).unwrap()))
        .collect();
    assert_eq!(one, alone, "a pair's result does not depend on its batch");
    // The key and the seed do choose the samples: the trial bound or the model's last bits move.
    let reseeded: Vec<_> = views
        .iter()
        .map(|v| bits(&v.verify(&config.clone().with_seed(18)).unwrap()))
        .collect();
    assert_ne!(one, reseeded);
}

#[test]
fn bad_inputs_are_typed_errors() {
    let pair = Pair::new(scene(30, Shape::General, 40, 0.0, 0.0));
    let config = VerifyConfig::default();
    let kind = |result: clatch::Result<TwoViewGeometry>| result.unwrap_err().kind();

    let with_matches = |matches: &[Match]| {
        kind(verify_pair(
            &pair.keypoints_a,
            &pair.keypoints_b,
            matches,
            None,
            &config,
        ))
    };
    let mut out_of_range = pair.matches.clone();
    out_of_range[5].train = 40;
    assert_eq!(with_matches(&out_of_range), ErrorKind::InvalidInput);
    out_of_range[5] = Match {
        query: u32::MAX,
        train: 0,
        distance: 0,
    };
    assert_eq!(with_matches(&out_of_range), ErrorKind::InvalidInput);

    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut keypoints = pair.keypoints_a.clone();
        keypoints[3].y = bad;
        assert_eq!(
            kind(verify_pair(
                &keypoints,
                &pair.keypoints_b,
                &pair.matches,
                None,
                &config
            )),
            ErrorKind::InvalidInput
        );
    }

    let good = Intrinsics::new(900.0, 900.0, 512.0, 384.0);
    for intrinsics in [
        Intrinsics { fx: 0.0, ..good },
        Intrinsics { fy: -900.0, ..good },
        Intrinsics {
            cx: f64::NAN,
            ..good
        },
        Intrinsics {
            fx: f64::INFINITY,
            ..good
        },
    ] {
        let camera = Camera::new(1024, 768).with_intrinsics(intrinsics);
        let result = pair
            .uncalibrated()
            .with_cameras(&pair.camera_a, &camera)
            .verify(&config);
        assert_eq!(kind(result), ErrorKind::InvalidInput, "{intrinsics:?}");
    }
    let empty = Camera::new(0, 768);
    assert_eq!(
        kind(
            pair.uncalibrated()
                .with_cameras(&empty, &pair.camera_b)
                .verify(&config)
        ),
        ErrorKind::InvalidInput
    );

    for bad in [
        config.clone().with_max_error(0.0),
        config.clone().with_max_error(f64::NAN),
        config.clone().with_confidence(1.0),
        config.clone().with_min_num_trials(20_000),
        config.clone().with_max_num_trials(0),
        config.clone().with_max_h_inlier_ratio(1.5),
        config.clone().with_trials_multiplier(-1.0),
        config.clone().with_watermark_border_size(0.5),
    ] {
        assert_eq!(
            kind(pair.calibrated().verify(&bad)),
            ErrorKind::InvalidConfig,
            "{bad:?}"
        );
    }

    // In a batch the error names the pair.
    let mut nan = pair.keypoints_b.clone();
    nan[0].x = f32::NAN;
    let broken = ViewPair::new(&pair.keypoints_a, &nan, &pair.matches);
    let error = verify_pairs(&[pair.calibrated(), broken], &config).unwrap_err();
    assert_eq!(error.kind(), ErrorKind::InvalidInput);
    assert!(error.to_string().contains("pair 1"), "{error}");

    // Unmatched keypoints are never read: a NaN among them is fine.
    let mut extra = pair.keypoints_a.clone();
    extra.push(KeyPoint::new(f32::NAN, 0.0));
    assert!(verify_pair(&extra, &pair.keypoints_b, &pair.matches, None, &config).is_ok());
    // Extreme but finite positions are no error and no panic: at worst no model.
    let huge: Vec<KeyPoint> = (0..40)
        .map(|i| {
            KeyPoint::new(
                if i % 2 == 0 { f32::MAX } else { -f32::MAX },
                i as f32 * 1e36,
            )
        })
        .collect();
    let few_trials = config
        .clone()
        .with_min_num_trials(0)
        .with_max_num_trials(300);
    for cameras in [None, Some((&pair.camera_a, &pair.camera_b))] {
        let g = verify_pair(
            &huge,
            &pair.keypoints_b,
            &pair.matches,
            cameras,
            &few_trials,
        )
        .unwrap();
        assert!(g.inliers.len() <= 40);
    }
    // No matches at all: degenerate, not an error.
    assert_eq!(
        verify_pair(&[], &[], &[], None, &config).unwrap().config,
        GeometryConfig::Degenerate
    );
}

#[test]
fn models_in_colmaps_pixel_convention_fit_the_shifted_positions() {
    let pair = Pair::new(scene(31, Shape::Planar, 200, 0.0, 0.0));
    let g = verify(pair.uncalibrated());
    let colmap = g.in_colmap_pixels();
    assert_eq!((colmap.config, &colmap.inliers), (g.config, &g.inliers));
    let shifted = |p: &[f64; 2]| [p[0] + 0.5, p[1] + 0.5];
    for (a, b) in pair.scene.a.iter().zip(&pair.scene.b) {
        assert!(sampson(&colmap.f.unwrap(), shifted(a), shifted(b)) < 1e-9);
        assert!(transfer(&colmap.h.unwrap(), shifted(a), shifted(b)) < 1e-9);
    }
    assert_ne!(colmap.h, g.h);
    assert_ne!(colmap.f, g.f);
}

/// A pair built with `+ − × ÷` only (no `sin`, `ln` of the platform): 600 random points in depth,
/// a rotation by Cayley's formula, 35 % of the matches moved at random.
fn arithmetic_only_pair() -> (Vec<KeyPoint>, Vec<KeyPoint>, Vec<Match>, Camera, Camera) {
    let mut rng = clatch::synthetic::SplitMix64::new(2026);
    let mut unit = || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
    // R = (I + S)(I − S)⁻¹ for the skew matrix S of s = (0.05, −0.1, 0.08).
    let (x, y, z) = (0.05, -0.1, 0.08);
    let scale = 1.0 / (1.0 + x * x + y * y + z * z);
    let r = [
        [
            1.0 + x * x - y * y - z * z,
            2.0 * (x * y - z),
            2.0 * (x * z + y),
        ],
        [
            2.0 * (x * y + z),
            1.0 - x * x + y * y - z * z,
            2.0 * (y * z - x),
        ],
        [
            2.0 * (x * z - y),
            2.0 * (y * z + x),
            1.0 - x * x - y * y + z * z,
        ],
    ]
    .map(|row| row.map(|v| v * scale));
    let t = [1.0, 0.2, -0.1];
    let (f, cx, cy) = (950.0, 511.5, 383.5);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    while a.len() < 600 {
        let p = [unit() * 8.0 - 4.0, unit() * 6.0 - 3.0, 5.0 + unit() * 10.0];
        let q: Vec<f64> = (0..3)
            .map(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i])
            .collect();
        let (ua, va) = (f * p[0] / p[2] + cx, f * p[1] / p[2] + cy);
        let (ub, vb) = (f * q[0] / q[2] + cx, f * q[1] / q[2] + cy);
        if [ua, ub].iter().all(|u| (0.0..1024.0).contains(u))
            && [va, vb].iter().all(|v| (0.0..768.0).contains(v))
        {
            a.push(KeyPoint::new(ua as f32, va as f32));
            b.push(KeyPoint::new(ub as f32, vb as f32));
        }
    }
    for k in (0..600).filter(|k| k % 20 < 7) {
        b[k] = KeyPoint::new((unit() * 1024.0) as f32, (unit() * 768.0) as f32);
    }
    let camera = Camera::new(1024, 768).with_intrinsics(Intrinsics::new(f, f, cx, cy));
    (a, b, identity_matches(600), camera, camera)
}

/// FNV-1a over the bits of a geometry.
fn fingerprint(g: &TwoViewGeometry) -> u64 {
    let (config, matrices, inliers, counts) = bits(g);
    let words = std::iter::once(config as u64)
        .chain(matrices)
        .chain(inliers.into_iter().map(u64::from))
        .chain(counts.into_iter().map(|c| c as u64));
    words.fold(0xcbf2_9ce4_8422_2325, |hash, word| {
        (hash ^ word).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The specification pinned: these bits change only with a deliberate change of the arithmetic in
/// `docs/numerics.md`, section 7 (and then the CUDA twin changes with it). The pair uses only basic
/// IEEE operations, so the expected values hold on every platform.
#[test]
fn golden_bits_of_a_fixed_pair() {
    let (a, b, matches, camera_a, camera_b) = arithmetic_only_pair();
    let config = VerifyConfig::default().with_seed(7);
    let calibrated = ViewPair::new(&a, &b, &matches)
        .with_cameras(&camera_a, &camera_b)
        .with_key(3)
        .verify(&config)
        .unwrap();
    let uncalibrated = ViewPair::new(&a, &b, &matches)
        .with_key(3)
        .verify(&config)
        .unwrap();
    assert_eq!(calibrated.config, GeometryConfig::Calibrated);
    assert_eq!(uncalibrated.config, GeometryConfig::Uncalibrated);
    let truth: Vec<u32> = (0..600).filter(|k| k % 20 >= 7).collect();
    // Every true match, and the few moved ones that landed within 4 px of their epipolar line.
    assert!(
        truth
            .iter()
            .all(|k| calibrated.inliers.binary_search(k).is_ok())
    );
    assert!(
        calibrated.inliers.len() < truth.len() + 12,
        "{}",
        calibrated.inliers.len()
    );
    assert_eq!(
        (fingerprint(&calibrated), fingerprint(&uncalibrated)),
        (0xd640_ccd5_9722_f773, 0x7fa2_887c_ff8a_94aa),
        "the verification arithmetic changed: change docs/numerics.md section 7 and the CUDA twin with it"
    );
}

#[test]
fn configurations_carry_colmaps_numbers() {
    let codes = [
        (GeometryConfig::Undefined, 0),
        (GeometryConfig::Degenerate, 1),
        (GeometryConfig::Calibrated, 2),
        (GeometryConfig::Uncalibrated, 3),
        (GeometryConfig::Planar, 4),
        (GeometryConfig::Panoramic, 5),
        (GeometryConfig::PlanarOrPanoramic, 6),
        (GeometryConfig::Watermark, 7),
        (GeometryConfig::Multiple, 8),
    ];
    for (config, code) in codes {
        assert_eq!(config.colmap_code(), code, "{config:?}");
    }
}
