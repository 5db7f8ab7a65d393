//! Rotation sanity: turning the image by exact multiples of 90 degrees (a pixel permutation) and adding
//! the same angle to the keypoints must (a) give (almost always exactly) the same descriptors and
//! (b) detect the same keypoints, at the rotated positions with the angle turned by exactly 90 degrees
//! per turn.
//!
//! Why (a) is nearly exact: the rotation table is symmetric under +90 degrees bit for bit
//! (`R[k + 720] = (-S, C)`), so the rotated frame's steps are the original's turned by 90 degrees, and so
//! is every sample position, except where a fixed-point rounding (`(q·S + 2^13) >> 14` of a negated
//! value, or `(P + 128) >> 8`) hits an exact half step: `floor(-v + 1/2) != -floor(v + 1/2)` only there.
//! Bilinear interpolation is exactly symmetric (the same four products in another order).

mod common;

use clatch::angle::{ANGLE_BINS, bin_degrees};
use clatch::synthetic::SplitMix64;
use clatch::{Backend, DescriptorSet, DetectorConfig, Extractor, ExtractorConfig, KeyPoint};
use common::{Gray, astronaut, rectangles, rotate90_point};

fn extractor(detector: DetectorConfig) -> Extractor {
    Extractor::new(
        Backend::Cpu,
        ExtractorConfig::single_scale()
            .with_detector(detector.with_subpixel(clatch::Subpixel::None)),
    )
    .unwrap()
}

/// A keypoint of `image` carried through `turns` quarter turns: position and angle.
fn rotate_keypoint(k: &KeyPoint, image: &Gray, turns: usize) -> KeyPoint {
    let (mut x, mut y) = (k.x as usize, k.y as usize);
    let (mut w, mut h) = (image.width, image.height);
    for _ in 0..turns {
        (x, y) = rotate90_point(x, y, h);
        (w, h) = (h, w);
    }
    let _ = w;
    KeyPoint {
        x: x as f32,
        y: y as f32,
        angle: k.angle + 90.0 * turns as f32,
        ..*k
    }
}

fn distances(a: &DescriptorSet, b: &DescriptorSet) -> Vec<u32> {
    assert_eq!(a.len(), b.len());
    a.rows()
        .zip(b.rows())
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p ^ q).count_ones()).sum())
        .collect()
}

struct Stats {
    count: usize,
    max: u32,
    sum: u64,
    nonzero: usize,
}

impl Stats {
    fn new() -> Self {
        Self {
            count: 0,
            max: 0,
            sum: 0,
            nonzero: 0,
        }
    }

    fn add(&mut self, d: &[u32]) {
        self.count += d.len();
        self.max = self.max.max(d.iter().copied().max().unwrap_or(0));
        self.sum += d.iter().map(|&v| v as u64).sum::<u64>();
        self.nonzero += d.iter().filter(|&&v| v != 0).count();
    }

    fn mean(&self) -> f64 {
        self.sum as f64 / self.count as f64
    }
}

/// Random keypoints at integer positions whose windows fit at every angle, angles on the 1/8-degree
/// grid (so adding 90 is exact and lands on the bin 720 further), sizes 16, 31, 64 and 100.
fn random_keypoints(image: &Gray, n: usize, seed: u64) -> Vec<KeyPoint> {
    let mut rng = SplitMix64::new(seed);
    let sizes = [16.0f32, 31.0, 64.0, 100.0];
    (0..n)
        .map(|i| {
            let size = sizes[i % sizes.len()];
            let margin = DetectorConfig::default().with_keypoint_size(size).margin();
            let x = margin + rng.below((image.width - 2 * margin) as u64) as usize;
            let y = margin + rng.below((image.height - 2 * margin) as u64) as usize;
            let angle = bin_degrees(rng.below(ANGLE_BINS as u64) as usize);
            KeyPoint::new(x as f32, y as f32)
                .with_size(size)
                .with_angle(angle)
        })
        .collect()
}

/// Describes `keypoints` on `image` and their rotated twins on the rotated image; returns the distances.
fn rotated_distances(image: &Gray, keypoints: &[KeyPoint], turns: usize) -> Vec<u32> {
    let e = extractor(DetectorConfig::default());
    let rotated = image.rotate(turns);
    let twins: Vec<KeyPoint> = keypoints
        .iter()
        .map(|k| rotate_keypoint(k, image, turns))
        .collect();
    let a = e.describe(&image.view(), keypoints).unwrap();
    let b = e.describe(&rotated.view(), &twins).unwrap();
    assert!(a.skipped.is_empty() && b.skipped.is_empty());
    distances(&a.descriptors, &b.descriptors)
}

fn images() -> Vec<(&'static str, Gray)> {
    vec![
        ("astronaut", astronaut()),
        ("rectangles", rectangles(300, 220, 11)),
        (
            "noise",
            Gray::new(
                clatch::synthetic::noise(160, 200, 4).expect("synthetic image"),
                160,
                200,
            ),
        ),
    ]
}

#[test]
fn rotate90_is_a_rotation() {
    let img = rectangles(70, 90, 1);
    let r = img.rotate90();
    assert_eq!((r.width, r.height), (90, 70));
    // Four quarter turns give the original back; two give the 180-degree flip.
    assert_eq!(img.rotate(4), img);
    let half = img.rotate(2);
    for y in 0..90 {
        for x in 0..70 {
            assert_eq!(half.at(69 - x, 89 - y), img.at(x, y));
        }
    }
    // The top-left pixel goes to the top-right corner: offset (-a, -b) from the centre -> (b, -a).
    assert_eq!(r.at(89, 0), img.at(0, 0));
}

/// Descriptor distances of random keypoints (sizes 16, 31, 64, 100, integer positions, random angle bins)
/// and their twins on the image turned 90, 180 and 270 degrees.
///
/// Measured: most twins are identical, a few percent differ by 1-5 bits (the half-step roundings
/// shown by `window_samples_rotate_exactly_except_on_half_steps`: a sample moves by 1/256 pixel and
/// its value by 1, which can flip a bit whose two SSDs were within a few units). An exploratory run
/// of 108 000 pairs (3 images x 4 sizes x 3000 keypoints x 3 turns) gave max 5 bits, mean 0.027-0.13
/// per (turn, size) (size 16 and 180 degrees worst: both axes round, and with `q = 4096` a quarter of
/// the bins put a step exactly on a half unit), 2.4-10.7 % nonzero. This test's fixed sample (seeds as
/// written, 3 x 2000 keypoints per turn) measures:
///   90 degrees: max 4, mean 0.042, 3.6 % nonzero; 180: max 3, mean 0.070, 6.1 % nonzero;
///   270: max 3, mean 0.039, 3.5 % nonzero.
/// Bounds: max <= 6 bits, mean < 0.1, at least 90 % exactly equal.
#[test]
fn descriptors_of_rotated_keypoints_on_rotated_images() {
    for turns in 1..=3 {
        let mut stats = Stats::new();
        for (seed, (name, image)) in images().into_iter().enumerate() {
            let keypoints = random_keypoints(&image, 2000, 77 + seed as u64);
            let d = rotated_distances(&image, &keypoints, turns);
            stats.add(&d);
            eprintln!(
                "{name}, {} degrees: max {}, mean {:.4}, nonzero {}",
                90 * turns,
                d.iter().max().unwrap(),
                d.iter().sum::<u32>() as f64 / d.len() as f64,
                d.iter().filter(|&&v| v > 0).count()
            );
        }
        let zero_fraction = 1.0 - stats.nonzero as f64 / stats.count as f64;
        eprintln!(
            "{} degrees: max {}, mean {:.4}, {:.2} % nonzero",
            90 * turns,
            stats.max,
            stats.mean(),
            100.0 * (1.0 - zero_fraction)
        );
        assert!(
            stats.max <= 6 && stats.mean() < 0.1 && zero_fraction >= 0.9,
            "{} degrees: max {}, mean {}, {} of {} nonzero",
            90 * turns,
            stats.max,
            stats.mean(),
            stats.nonzero,
            stats.count
        );
    }
}

/// A 16.16 (`one = 65536`) or 24.8 (`one = 256`) fixed-point position on a `width x height` image carried
/// through `turns` quarter turns (see `common::rotate90_point`).
fn rotate_fixed(
    mut p: [i64; 2],
    one: i64,
    mut width: usize,
    mut height: usize,
    turns: usize,
) -> [i64; 2] {
    for _ in 0..turns {
        p = [one * (height as i64 - 1) - p[1], p[0]];
        (width, height) = (height, width);
    }
    p
}

/// A 16.16 vector turned `turns` quarter turns.
fn rotate_vector(mut v: [i64; 2], turns: usize) -> [i64; 2] {
    for _ in 0..turns {
        v = [-v[1], v[0]];
    }
    v
}

/// The mechanism behind the rare differences, sample by sample: the rotated window samples the rotated
/// position except where a rounding falls on an exact half step; there the position moves by at most
/// 1/256 pixel and the sample by at most 1; everywhere else the samples are identical (bilinear
/// interpolation is exactly symmetric). With steps that rotate exactly (the same `q·C`, `q·S` rounding),
/// positions move only where a negated 16.16 coordinate is exactly half a 24.8 unit (`≡ 128 mod 256`).
#[test]
fn window_samples_rotate_exactly_except_on_half_steps() {
    use clatch::describe::SamplingFrame;
    use clatch::describe::cpu::sample_window;
    const W: usize = clatch::describe::WINDOW;
    let image = astronaut();
    let (mut samples, mut moved, mut changed, mut exact_step_frames) =
        (0usize, 0usize, 0usize, 0usize);
    let mut largest_change = 0;
    for turns in 1..=3 {
        let rotated = image.rotate(turns);
        for k in random_keypoints(&image, 300, 31 + turns as u64) {
            let twin = rotate_keypoint(&k, &image, turns);
            let (f, g) = (SamplingFrame::of(&k), SamplingFrame::of(&twin));
            assert_eq!(
                g.origin,
                rotate_fixed(f.origin, 65536, image.width, image.height, turns)
            );
            // The steps are vectors: each quarter turn maps (a, b) to (-b, a). (Written as a plain function:
            // rustc 1.95.0 miscompiled an earlier closure version of this, see tests/toolchain.rs.)
            let (su, sv) = (
                rotate_vector(f.step_u, turns),
                rotate_vector(f.step_v, turns),
            );
            let exact_steps = g.step_u == su && g.step_v == sv;
            exact_step_frames += exact_steps as usize;
            for axis in 0..2 {
                assert!((g.step_u[axis] - su[axis]).abs() <= 1, "{k:?} {f:?} {g:?}");
                assert!((g.step_v[axis] - sv[axis]).abs() <= 1, "{k:?} {f:?} {g:?}");
            }
            let (mut a, mut b) = (Box::new([0i16; W * W]), Box::new([0i16; W * W]));
            sample_window(&image.view(), &f, &mut a);
            sample_window(&rotated.view(), &g, &mut b);
            for v in 0..W {
                for u in 0..W {
                    let (du, dv) = (u as i64 - 32, v as i64 - 32);
                    let p16 = [0, 1].map(|s| f.origin[s] + du * f.step_u[s] + dv * f.step_v[s]);
                    let expected = rotate_fixed(
                        f.sample_position(u, v),
                        256,
                        image.width,
                        image.height,
                        turns,
                    );
                    let got = g.sample_position(u, v);
                    let (sa, sb) = (a[v * W + u], b[v * W + u]);
                    samples += 1;
                    if got == expected {
                        assert_eq!(sa, sb, "{k:?} ({u}, {v})");
                        continue;
                    }
                    moved += 1;
                    assert!(
                        (got[0] - expected[0]).abs() <= 1 && (got[1] - expected[1]).abs() <= 1,
                        "{k:?} ({u}, {v})"
                    );
                    if exact_steps {
                        // Only a coordinate that the rotation negates can round the other way.
                        let negated: &[usize] = match turns {
                            1 => &[1],
                            2 => &[0, 1],
                            _ => &[0],
                        };
                        assert!(
                            negated.iter().any(|&s| p16[s].rem_euclid(256) == 128),
                            "{k:?} ({u}, {v})"
                        );
                    }
                    changed += (sa != sb) as usize;
                    largest_change = largest_change.max((sa - sb).abs());
                }
            }
        }
    }
    eprintln!(
        "{samples} samples: {moved} moved by 1/256 pixel, {changed} changed value (at most {largest_change}); {exact_step_frames} of 900 frames with exact steps"
    );
    assert!(largest_change <= 1, "{largest_change}");
    assert!(
        (450..900).contains(&exact_step_frames),
        "both kinds of frames are exercised"
    );
    // Measured: 63 266 of 3 686 400 samples moved (1.7 %), 1761 changed value, by 1 at most.
    assert!(moved > 0 && (moved as f64) < 0.025 * samples as f64);
}

/// Every angle bin at one keypoint (sizes 31, 64, 100): the descriptor at bin k on the image equals the
/// descriptor at bin k + 720 on the rotated image, up to the half-step roundings. Measured: max 1 bit,
/// mean 0.0076, 66 of 8640 nonzero; bounds max <= 2, mean < 0.02.
#[test]
fn every_angle_bin_rotates_with_the_image() {
    let image = astronaut();
    let mut stats = Stats::new();
    for size in [31.0f32, 64.0, 100.0] {
        let keypoints: Vec<KeyPoint> = (0..ANGLE_BINS)
            .map(|k| {
                KeyPoint::new(250.0, 270.0)
                    .with_size(size)
                    .with_angle(bin_degrees(k))
            })
            .collect();
        let d = rotated_distances(&image, &keypoints, 1);
        stats.add(&d);
    }
    eprintln!(
        "all bins: max {}, mean {:.4}, nonzero {}",
        stats.max,
        stats.mean(),
        stats.nonzero
    );
    assert!(
        stats.max <= 2 && stats.mean() < 0.02,
        "max {}, mean {}",
        stats.max,
        stats.mean()
    );
}

/// The rotated descriptors are not trivially equal: without turning the angle they differ a lot.
#[test]
fn without_turning_the_angle_descriptors_differ() {
    let image = astronaut();
    let keypoints = random_keypoints(&image, 200, 5);
    let e = extractor(DetectorConfig::default());
    let rotated = image.rotate90();
    let twins: Vec<KeyPoint> = keypoints
        .iter()
        .map(|k| KeyPoint {
            angle: k.angle,
            ..rotate_keypoint(k, &image, 1)
        })
        .collect();
    let a = e.describe(&image.view(), &keypoints).unwrap();
    let b = e.describe(&rotated.view(), &twins).unwrap();
    let d = distances(&a.descriptors, &b.descriptors);
    let mean = d.iter().sum::<u32>() as f64 / d.len() as f64;
    assert!(mean > 100.0, "mean distance {mean}");
}

/// True iff one of the eight neighbours of the keypoint has the same score.
fn has_tie(scores: &[u8], width: usize, k: &KeyPoint) -> bool {
    let (x, y) = (k.x as usize, k.y as usize);
    let s = scores[y * width + x];
    assert!(s > 0);
    (y - 1..=y + 1)
        .any(|ny| (x - 1..=x + 1).any(|nx| (nx, ny) != (x, y) && scores[ny * width + nx] == s))
}

/// Smallest fraction of keypoints found in both the image and its rotation. Measured (both detector
/// configurations, 90/180/270 degrees, as a fraction of either image's keypoints): astronaut
/// 0.933-0.984, noise 0.981-0.996, rectangles 0.720-0.886 (its flat regions and straight edges make many
/// equal neighbouring scores; 180 degrees is worst, as it reverses both raster directions). Bounds a
/// little below.
fn min_fraction(image: &str) -> f64 {
    match image {
        "astronaut" => 0.92,
        "noise" => 0.97,
        "rectangles" => 0.70,
        other => panic!("{other}"),
    }
}

/// Detection on the image and on its rotation: matched keypoints (by rotated position) have the same
/// response and an angle exactly 90 degrees per turn larger (mod 360); keypoints found in one only are
/// explained by a tie in the 3x3 non-maximum suppression, whose raster-order rule is not rotation
/// invariant (an equal score among the eight neighbours).
#[test]
fn detection_is_covariant_under_quarter_turns() {
    let configs = [
        DetectorConfig::default().with_max_keypoints(usize::MAX),
        DetectorConfig::default()
            .with_max_keypoints(usize::MAX)
            .with_threshold(10)
            .with_keypoint_size(31.0),
    ];
    for config in configs {
        let e = extractor(config.clone());
        for (name, image) in images() {
            let original = e.detect(&image.view()).unwrap();
            assert!(original.len() > 50, "{name}: {}", original.len());
            let scores =
                clatch::detect::cpu::score_map(&image.view(), config.threshold, config.margin());
            for turns in 1..=3 {
                let rotated_image = image.rotate(turns);
                let rotated = e.detect(&rotated_image.view()).unwrap();
                let mut found = std::collections::HashMap::new();
                for k in &rotated {
                    found.insert((k.x as usize, k.y as usize), *k);
                }
                let rotated_scores = clatch::detect::cpu::score_map(
                    &rotated_image.view(),
                    config.threshold,
                    config.margin(),
                );
                let back: std::collections::HashSet<(usize, usize)> = original
                    .iter()
                    .map(|k| {
                        let t = rotate_keypoint(k, &image, turns);
                        (t.x as usize, t.y as usize)
                    })
                    .collect();
                for r in &rotated {
                    if !back.contains(&(r.x as usize, r.y as usize)) {
                        assert!(
                            has_tie(&rotated_scores, rotated_image.width, r),
                            "{name}: {r:?} found only on the rotated image, without a tie"
                        );
                    }
                }
                let mut matched = 0;
                for k in &original {
                    let twin = rotate_keypoint(k, &image, turns);
                    match found.get(&(twin.x as usize, twin.y as usize)) {
                        Some(r) => {
                            matched += 1;
                            assert_eq!(r.response, k.response);
                            assert_eq!(r.size, k.size);
                            let expected = (k.angle + 90.0 * turns as f32) % 360.0;
                            assert_eq!(r.angle, expected, "{name}, {turns} turns: {k:?} -> {r:?}");
                        }
                        None => assert!(
                            has_tie(&scores, image.width, k),
                            "{name}: {k:?} lost without a tie"
                        ),
                    }
                }
                let fraction = matched as f64 / original.len() as f64;
                let fraction_rotated = matched as f64 / rotated.len() as f64;
                eprintln!(
                    "{name}, threshold {}, {} degrees: {matched} matched of {} / {} rotated: {:.4} / {:.4}",
                    config.threshold,
                    90 * turns,
                    original.len(),
                    rotated.len(),
                    fraction,
                    fraction_rotated
                );
                assert!(
                    fraction.min(fraction_rotated) >= min_fraction(name),
                    "{name}, {turns} turns: {fraction}, {fraction_rotated}"
                );
            }
        }
    }
}
