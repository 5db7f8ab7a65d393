//! End to end: detection, description and matching together, on synthetic images and the embedded
//! photograph; the detector's margin against the description fit rule; determinism across runs, input
//! orders and rayon thread counts.

mod common;

use clatch::angle::{ANGLE_BINS, bin_degrees};
use clatch::describe::SamplingFrame;
use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorConfig, DescriptorWidth, DetectorConfig, Extractor, ExtractorConfig,
    Features, KeyPoint, MatchConfig, Matcher, PatchWeights,
};
use common::{Gray, astronaut, rectangles};

fn extractor_with(keypoint_size: f32) -> Extractor {
    Extractor::new(
        Backend::Cpu,
        ExtractorConfig::single_scale().with_detector(
            DetectorConfig::default()
                .with_keypoint_size(keypoint_size)
                .with_subpixel(clatch::Subpixel::None),
        ),
    )
    .unwrap()
}

fn images() -> Vec<(&'static str, Gray)> {
    vec![
        ("astronaut", astronaut()),
        ("rectangles 640x480", rectangles(640, 480, 3)),
        ("rectangles 333x517", rectangles(333, 517, 9)),
    ]
}

#[test]
fn detect_and_describe_gives_one_descriptor_per_keypoint() {
    for (name, image) in images() {
        let e = extractor_with(64.0);
        let features = e.detect_and_describe(&image.view()).unwrap();
        assert!(
            features.keypoints.len() > 100,
            "{name}: {}",
            features.keypoints.len()
        );
        assert_eq!(
            features.keypoints.len(),
            features.descriptors.len(),
            "{name}"
        );
        assert_eq!(features.descriptors.width(), DescriptorWidth::FULL);
        // The same as the two steps run separately.
        let keypoints = e.detect(&image.view()).unwrap();
        assert_eq!(features.keypoints, keypoints, "{name}");
        let described = e.describe(&image.view(), &keypoints).unwrap();
        assert_eq!(features.descriptors, described.descriptors, "{name}");
    }
}

#[test]
fn every_detected_keypoint_is_described_at_every_size() {
    for (name, image) in images() {
        for size in [16.0, 64.0, 200.0] {
            let e = extractor_with(size);
            let keypoints = e.detect(&image.view()).unwrap();
            assert!(
                keypoints.len() > 20,
                "{name}, size {size}: {}",
                keypoints.len()
            );
            let margin = e.config().detector.margin();
            // Detection reaches the margin (otherwise the fit check below would prove little).
            let reach = keypoints
                .iter()
                .map(|k| {
                    (k.x as usize - margin)
                        .min(k.y as usize - margin)
                        .min(image.width - 1 - margin - k.x as usize)
                        .min(image.height - 1 - margin - k.y as usize)
                })
                .min()
                .unwrap();
            assert!(
                reach < 20,
                "{name}, size {size}: closest keypoint {reach} inside the margin"
            );
            for k in &keypoints {
                assert_eq!(k.size, size);
                assert!(
                    SamplingFrame::of(k).fits(image.width, image.height),
                    "{k:?}"
                );
            }
            let described = e.describe(&image.view(), &keypoints).unwrap();
            assert!(
                described.skipped.is_empty(),
                "{name}, size {size}: {:?}",
                described.skipped
            );
            assert_eq!(
                described.keypoint_index,
                (0..keypoints.len()).collect::<Vec<_>>()
            );
            let features = e.detect_and_describe(&image.view()).unwrap();
            assert_eq!(features.keypoints, keypoints);
        }
    }
}

/// The extreme detectable positions (`margin` from the left/top, `margin + 1` from the right/bottom since
/// only `m <= x < W - m` is scored) fit at every one of the 2880 angle bins, for many sizes.
#[test]
fn margin_positions_fit_at_every_angle_bin() {
    let mut sizes = vec![
        1.0f32, 1.5, 7.9, 16.0, 31.0, 45.3, 63.99, 64.0, 100.0, 200.0, 362.0, 1000.0, 1024.0,
    ];
    let mut rng = SplitMix64::new(12);
    sizes.extend((0..20).map(|_| 1.0 + (rng.below(1 << 20) as f32 / (1 << 20) as f32) * 1023.0));
    for size in sizes {
        let m = DetectorConfig::default().with_keypoint_size(size).margin();
        // The smallest image with a detectable pixel, and a larger, non-square one.
        for (w, h) in [(2 * m + 1, 2 * m + 1), (2 * m + 37, 2 * m + 5)] {
            let positions = [
                (m, m),
                (w - 1 - m, m),
                (m, h - 1 - m),
                (w - 1 - m, h - 1 - m),
            ];
            for bin in 0..ANGLE_BINS {
                for &(x, y) in &positions {
                    let k = KeyPoint::new(x as f32, y as f32)
                        .with_size(size)
                        .with_angle(bin_degrees(bin));
                    assert!(
                        SamplingFrame::of(&k).fits(w, h),
                        "{k:?} on {w}x{h} (margin {m})"
                    );
                }
            }
        }
    }
}

/// The same at the API level: describing the margin keypoints at all 2880 bins skips none (for the sizes
/// whose images are cheap to allocate), and the detector does find a corner exactly at the margin but
/// not one pixel outside it.
#[test]
fn detector_margin_is_inclusive_and_its_keypoints_are_described() {
    for size in [16.0f32, 64.0, 200.0] {
        let e = extractor_with(size);
        let m = e.config().detector.margin();
        let (w, h) = ((2 * m + 41).max(90), (2 * m + 23).max(70)); // images are at least 64x64
        // Single bright pixels on a dark background are FAST corners (score = contrast) and nothing
        // around them is: at the four extreme positions, and one pixel outside each.
        let inside = [
            (m, m),
            (w - 1 - m, m),
            (m, h - 1 - m),
            (w - 1 - m, h - 1 - m),
        ];
        let outside = [
            (m - 1, m + 10),
            (w - m, m + 10),
            (m + 10, m - 1),
            (m + 10, h - m),
        ];
        let mut pixels = vec![10u8; w * h];
        for &(x, y) in inside.iter().chain(&outside) {
            pixels[y * w + x] = 200;
        }
        let image = Gray::new(pixels, w, h);
        let found: Vec<(usize, usize)> = e
            .detect(&image.view())
            .unwrap()
            .iter()
            .map(|k| {
                assert_eq!(k.response, 190.0);
                (k.x as usize, k.y as usize)
            })
            .collect();
        let mut expected = inside.to_vec();
        expected.sort_by_key(|&(x, y)| (y, x)); // equal scores: raster order
        assert_eq!(found, expected, "size {size}, margin {m}");

        let keypoints: Vec<KeyPoint> = (0..ANGLE_BINS)
            .flat_map(|bin| {
                inside.iter().map(move |&(x, y)| {
                    KeyPoint::new(x as f32, y as f32)
                        .with_size(size)
                        .with_angle(bin_degrees(bin))
                })
            })
            .collect();
        let described = e.describe(&image.view(), &keypoints).unwrap();
        assert!(
            described.skipped.is_empty(),
            "size {size}: {} skipped",
            described.skipped.len()
        );
        assert_eq!(described.descriptors.len(), keypoints.len());
    }
}

#[cfg(not(feature = "cuda"))]
#[test]
fn auto_backend_is_the_cpu_without_cuda() {
    assert_eq!(Backend::auto(), Backend::Cpu);
    assert_eq!(Backend::default(), Backend::Cpu);
    assert!(Backend::Cpu.ensure_available().is_ok());
}

/// Descriptor rows keyed by input keypoint (`None` = skipped).
fn by_keypoint(described: &Features, count: usize) -> Vec<Option<Vec<u64>>> {
    let mut rows = vec![None; count];
    for (row, &i) in described.keypoint_index.iter().enumerate() {
        assert!(rows[i].is_none(), "keypoint {i} described twice");
        rows[i] = Some(described.descriptors.get(row).unwrap().to_vec());
    }
    let mut skipped: Vec<usize> = described.skipped.iter().map(|s| s.keypoint).collect();
    skipped.dedup();
    assert_eq!(skipped.len(), described.skipped.len());
    assert!(
        described.keypoint_index.windows(2).all(|p| p[0] < p[1]),
        "input order"
    );
    assert!(skipped.windows(2).all(|p| p[0] < p[1]), "input order");
    for &i in &skipped {
        assert!(rows[i].is_none());
    }
    assert_eq!(skipped.len() + described.keypoint_index.len(), count);
    rows
}

/// Random keypoints over the whole image (some skipped), random sizes, angles and sub-pixel positions.
fn random_keypoints(image: &Gray, n: usize, seed: u64) -> Vec<KeyPoint> {
    let mut rng = SplitMix64::new(seed);
    let mut unit = move || (rng.next_u64() >> 40) as f32 / (1u32 << 24) as f32;
    (0..n)
        .map(|_| {
            KeyPoint::new(
                unit() * (image.width - 1) as f32,
                unit() * (image.height - 1) as f32,
            )
            .with_size(8.0 + unit() * 120.0)
            .with_angle(unit() * 720.0 - 360.0)
        })
        .collect()
}

#[test]
fn descriptors_do_not_depend_on_order_or_company() {
    let image = astronaut();
    let e = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    let keypoints = random_keypoints(&image, 3000, 8);
    let reference = by_keypoint(
        &e.describe(&image.view(), &keypoints).unwrap(),
        keypoints.len(),
    );
    let described_count = reference.iter().filter(|r| r.is_some()).count();
    assert!(
        described_count > 1000 && described_count < keypoints.len(),
        "{described_count}"
    );

    // Each keypoint on its own.
    for (i, k) in keypoints.iter().enumerate().step_by(37) {
        let alone = by_keypoint(
            &e.describe(&image.view(), std::slice::from_ref(k)).unwrap(),
            1,
        );
        assert_eq!(alone[0], reference[i], "keypoint {i} alone");
    }
    // Shuffled, reversed, subsets, duplicates.
    let mut rng = SplitMix64::new(99);
    for trial in 0..6 {
        let mut order: Vec<usize> = (0..keypoints.len()).collect();
        match trial {
            0 => order.reverse(),
            1 => order.retain(|i| i % 3 == 1),
            2 => order.extend(0..500), // duplicates
            _ => {
                for i in (1..order.len()).rev() {
                    order.swap(i, rng.below(i as u64 + 1) as usize);
                }
                order.truncate(order.len() * (trial - 2) / 4);
            }
        }
        let subset: Vec<KeyPoint> = order.iter().map(|&i| keypoints[i]).collect();
        let rows = by_keypoint(&e.describe(&image.view(), &subset).unwrap(), subset.len());
        for (j, &i) in order.iter().enumerate() {
            assert_eq!(
                rows[j], reference[i],
                "trial {trial}: keypoint {i} at position {j}"
            );
        }
    }
}

fn run_everything(image: &Gray) -> (Features, Features, Vec<clatch::Match>, clatch::KnnMatches) {
    let config = ExtractorConfig::single_scale().with_descriptor(
        DescriptorConfig::default()
            .with_width(DescriptorWidth::from_bits(256).unwrap())
            .with_weights(PatchWeights::uniform()),
    );
    let e = Extractor::new(Backend::Cpu, config).unwrap();
    let features = e.detect_and_describe(&image.view()).unwrap();
    let described = e
        .describe(&image.view(), &random_keypoints(image, 1500, 4))
        .unwrap();
    let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
    let matches = matcher
        .match_descriptors(&described.descriptors, &features.descriptors)
        .unwrap();
    let knn = matcher
        .knn(&features.descriptors, &described.descriptors, 3)
        .unwrap();
    (features, described, matches, knn)
}

#[test]
fn identical_across_runs_and_thread_counts() {
    for (name, image) in images() {
        let reference = run_everything(&image);
        assert!(!reference.2.is_empty(), "{name}: some matches");
        assert_eq!(run_everything(&image), reference, "{name}: second run");
        for threads in [1, 2, 3, 7] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let result = pool.install(|| run_everything(&image));
            assert_eq!(result, reference, "{name}: {threads} threads");
        }
    }
}

#[test]
fn an_image_matched_against_itself_finds_itself() {
    let image = rectangles(640, 480, 21);
    let e = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    let features = e.detect_and_describe(&image.view()).unwrap();
    let matcher = Matcher::new(
        Backend::Cpu,
        MatchConfig::default()
            .with_ratio(None)
            .with_cross_check(true)
            .with_max_distance(None),
    )
    .unwrap();
    let matches = matcher
        .match_descriptors(&features.descriptors, &features.descriptors)
        .unwrap();
    // Every query's best match is at distance 0: itself, or an identical descriptor with a lower index
    // (ties go to the lowest index); cross-check then keeps exactly the first of each group of equals.
    let knn = matcher
        .knn(&features.descriptors, &features.descriptors, 1)
        .unwrap();
    for (q, n) in knn.iter().enumerate() {
        assert_eq!(n[0].distance, 0);
        assert!(n[0].train as usize <= q);
        assert_eq!(
            features.descriptors.get(q),
            features.descriptors.get(n[0].train as usize)
        );
    }
    let firsts = knn
        .iter()
        .enumerate()
        .filter(|(q, n)| n[0].train as usize == *q)
        .count();
    assert_eq!(matches.len(), firsts);
    assert!(
        matches
            .iter()
            .all(|m| m.query == m.train && m.distance == 0)
    );
    assert!(matches.len() as f64 > 0.95 * features.keypoints.len() as f64);
}
