//! Hostile inputs through every public entry point: random and absurd images, strides, keypoints,
//! configurations, descriptor sets, matches and COLMAP records, generated from fixed seeds. Each call
//! must return a value or a `clatch::Error` (never panic), and what comes back is checked against the
//! contract: a partition of the input keypoints, descriptors per keypoint, kNN and matches equal to
//! the naive references of `common::reference`. Bounded to well under a minute (test profile).

mod common;

use std::panic::{AssertUnwindSafe, catch_unwind};

use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorConfig, DescriptorSet, DescriptorWidth, DetectorConfig, Error, Extractor,
    ExtractorConfig, GrayView, KeyPoint, KnnMatches, Match, MatchConfig, Matcher, OpencvLatch,
    PatchWeights, Pyramid,
};
use common::reference::{naive_knn, naive_match};

/// Cases per test: `CLATCH_HOSTILE_SCALE` multiplies them (default 1) for a longer run.
fn cases(base: u64) -> u64 {
    let scale = std::env::var("CLATCH_HOSTILE_SCALE")
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
        .unwrap_or(1);
    base * scale.max(1)
}

/// Counts calls; a panic inside `f` is caught, counted and reported with its case.
#[derive(Default)]
struct Tally {
    calls: usize,
    errors: usize,
    panics: Vec<String>,
}

impl Tally {
    fn call<T>(
        &mut self,
        case: impl Fn() -> String,
        f: impl FnOnce() -> Result<T, Error>,
    ) -> Option<T> {
        self.calls += 1;
        match catch_unwind(AssertUnwindSafe(f)) {
            Ok(Ok(v)) => Some(v),
            Ok(Err(_)) => {
                self.errors += 1;
                None
            }
            Err(_) => {
                self.panics.push(case());
                None
            }
        }
    }

    fn finish(self, what: &str) {
        println!(
            "{what}: {} calls, {} typed errors, {} panics",
            self.calls,
            self.errors,
            self.panics.len()
        );
        assert!(
            self.panics.is_empty(),
            "{what}: panics in {:#?}",
            self.panics
        );
    }
}

/// `wild_f32` / `wild_usize` of a plain value drawn from the same generator first.
macro_rules! wild_f32 {
    ($rng:expr, $plain:expr) => {{
        let plain = $plain;
        wild_f32($rng, plain)
    }};
}
macro_rules! wild_usize {
    ($rng:expr, $plain:expr) => {{
        let plain = $plain;
        wild_usize($rng, plain)
    }};
}

/// A float that is sometimes absurd: NaN, infinities, negative, huge, subnormal, or plain.
fn wild_f32(rng: &mut SplitMix64, plain: f32) -> f32 {
    match rng.below(12) {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => f32::NEG_INFINITY,
        3 => -plain,
        4 => f32::MAX,
        5 => f32::MIN_POSITIVE / 2.0,
        6 => 0.0,
        _ => plain,
    }
}

fn wild_usize(rng: &mut SplitMix64, plain: usize) -> usize {
    match rng.below(10) {
        0 => 0,
        1 => usize::MAX,
        2 => plain.saturating_mul(1000),
        _ => plain,
    }
}

fn random_config(rng: &mut SplitMix64) -> ExtractorConfig {
    let detector = DetectorConfig::default()
        .with_threshold(rng.below(256) as u8)
        .with_max_keypoints(wild_usize!(rng, 1 + rng.below(3000) as usize))
        .with_keypoint_size(wild_f32!(rng, 8.0 + rng.below(120) as f32))
        .with_grid(wild_usize!(rng, 1 + rng.below(12) as usize))
        .with_level_budget(if rng.below(2) == 0 {
            clatch::LevelBudget::Global
        } else {
            clatch::LevelBudget::Geometric
        })
        .with_ranking(if rng.below(2) == 0 {
            clatch::Ranking::Fast
        } else {
            clatch::Ranking::Harris
        })
        .with_subpixel(if rng.below(2) == 0 {
            clatch::Subpixel::None
        } else {
            clatch::Subpixel::Score
        });
    let bits = match rng.below(6) {
        0 => rng.below(600) as usize,
        _ => 8 * (1 + rng.below(64) as usize),
    };
    let weights = match rng.below(5) {
        0 => PatchWeights::new(
            &(0..rng.below(70))
                .map(|_| rng.below(4) as u32)
                .collect::<Vec<_>>(),
        ),
        1 => PatchWeights::new(&[u32::MAX; 64]),
        2 => Ok(PatchWeights::uniform()),
        _ => Ok(PatchWeights::latch_7x7()),
    };
    let pyramid = match rng.below(4) {
        0 => Some(Pyramid::new(
            rng.below(40) as usize,
            wild_f32!(rng, 1.0 + rng.below(120) as f32 / 100.0),
        )),
        1 => Some(Pyramid::new(1 + rng.below(4) as usize, 2.0)),
        _ => None,
    };
    ExtractorConfig::default()
        .with_detector(detector)
        .with_descriptor(
            DescriptorConfig::default()
                .with_width(DescriptorWidth::from_bits(bits).unwrap_or_default())
                .with_weights(weights.unwrap_or_default()),
        )
        .with_pyramid(pyramid)
}

fn random_keypoints(rng: &mut SplitMix64, width: usize, height: usize) -> Vec<KeyPoint> {
    (0..rng.below(40))
        .map(|_| KeyPoint {
            x: wild_f32!(rng, rng.below(width as u64 * 4 + 8) as f32 / 4.0 - 1.0),
            y: wild_f32!(rng, rng.below(height as u64 * 4 + 8) as f32 / 4.0 - 1.0),
            size: wild_f32!(rng, 1.0 + rng.below(200) as f32),
            angle: wild_f32!(rng, rng.below(100_000) as f32 / 10.0 - 5000.0),
            response: wild_f32!(rng, rng.below(256) as f32),
            octave: rng.next_u64() as i32,
        })
        .collect()
}

/// Every input keypoint is described once or skipped once, in input order, with one row each.
fn check_partition(features: &clatch::Features, input: &[KeyPoint]) {
    assert_eq!(features.keypoints.len(), features.descriptors.len());
    assert_eq!(features.keypoints.len(), features.keypoint_index.len());
    let mut seen: Vec<usize> = features
        .keypoint_index
        .iter()
        .copied()
        .chain(features.skipped.iter().map(|s| s.keypoint))
        .collect();
    seen.sort_unstable();
    assert_eq!(seen, (0..input.len()).collect::<Vec<_>>());
    assert!(features.keypoint_index.windows(2).all(|w| w[0] < w[1]));
    for (row, &i) in features.keypoint_index.iter().enumerate() {
        assert_eq!(features.keypoints[row], input[i]);
    }
}

#[test]
fn images_keypoints_and_configurations() {
    let mut tally = Tally::default();
    let mut rng = SplitMix64::new(0x5eed_0001);
    let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    for case in 0..cases(10_000) {
        let width = match rng.below(4) {
            0 => rng.below(8) as usize,
            _ => 1 + rng.below(260) as usize,
        };
        let height = 1 + rng.below(200) as usize;
        let stride = width + rng.below(3) as usize * rng.below(9) as usize;
        let short = rng.below(8) == 0;
        let len =
            (stride * height).saturating_sub(if short { 1 + rng.below(4) as usize } else { 0 });
        let pixels = match rng.below(3) {
            0 => clatch::synthetic::noise(len, 1, case).unwrap_or_default(),
            _ => clatch::synthetic::rectangles(stride.max(1), height, case)
                .unwrap_or_default()
                .into_iter()
                .take(len)
                .collect(),
        };
        let describe =
            |what: &str| format!("case {case}: {what} on {width}x{height}, stride {stride}");
        let Some(image) = tally.call(
            || describe("GrayView::new"),
            || GrayView::new(&pixels, width, height, stride),
        ) else {
            continue;
        };
        // The checked accessors answer anywhere.
        for _ in 0..4 {
            let (x, y) = (
                rng.below(width as u64 + 3) as usize,
                rng.below(height as u64 + 3) as usize,
            );
            assert_eq!(image.get(x, y).is_some(), x < width && y < height);
            assert_eq!(image.get_row(y).is_some(), y < height);
            let _ = clatch::fast_score(&image, x, y);
        }
        // Coordinates at the far end of `usize` are outside, not wrapped round into the image.
        for far in [usize::MAX, usize::MAX - 2, usize::MAX / 2 + 1] {
            assert_eq!(clatch::fast_score(&image, far, 3), None);
            assert_eq!(clatch::fast_score(&image, 3, far), None);
        }
        let config = random_config(&mut rng);
        let Some(extractor) = tally.call(
            || describe(&format!("Extractor::new({config:?})")),
            || Extractor::new(Backend::Cpu, config.clone()),
        ) else {
            // An invalid configuration: the default extractor still gets the image.
            let keypoints = random_keypoints(&mut rng, width, height);
            if let Some(f) = tally.call(
                || describe("describe (default)"),
                || cpu.describe(&image, &keypoints),
            ) {
                check_partition(&f, &keypoints);
            }
            continue;
        };
        if let Some(detected) = tally.call(|| describe("detect"), || extractor.detect(&image)) {
            let max = config.detector.max_keypoints;
            assert!(detected.len() <= max);
            assert!(detected.iter().all(|k| k.x >= 0.0
                && k.y >= 0.0
                && k.x <= (width - 1) as f32
                && k.y <= (height - 1) as f32));
        }
        if let Some(f) = tally.call(
            || describe("detect_and_describe"),
            || extractor.detect_and_describe(&image),
        ) {
            assert_eq!(f.keypoints.len(), f.descriptors.len());
            assert!(f.skipped.is_empty());
            assert_eq!(f.descriptors.width(), config.descriptor.width);
        }
        let keypoints = random_keypoints(&mut rng, width, height);
        if let Some(f) = tally.call(
            || describe(&format!("describe({keypoints:?})")),
            || extractor.describe(&image, &keypoints),
        ) {
            check_partition(&f, &keypoints);
        }
        let latch = OpencvLatch::new(
            [1, 2, 3, 4, 8, 16, 32, 64, 65][rng.below(9) as usize],
            rng.below(2) == 0,
            rng.below(30) as usize,
            wild_f64(&mut rng),
        );
        if let Ok(latch) = latch
            && let Some(f) = tally.call(
                || describe(&format!("describe_opencv({latch:?})")),
                || extractor.describe_opencv(&latch, &image, &keypoints),
            )
        {
            check_partition(&f, &keypoints);
        }
    }
    tally.finish("images, keypoints and configurations");
}

fn wild_f64(rng: &mut SplitMix64) -> f64 {
    match rng.below(8) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => -(rng.below(400) as f64) / 100.0,
        3 => 0.0,
        4 => 1e300,
        _ => rng.below(400) as f64 / 100.0,
    }
}

#[test]
fn descriptor_sets_and_matching_against_the_references() {
    let mut tally = Tally::default();
    let mut rng = SplitMix64::new(0x5eed_0002);
    for case in 0..cases(20_000) {
        let bits_q = 8 * (1 + rng.below(64) as usize);
        let bits_t = if rng.below(10) == 0 {
            8 * (1 + rng.below(64) as usize)
        } else {
            bits_q
        };
        let words = |bits: usize, rng: &mut SplitMix64| {
            let w = bits.div_ceil(64);
            let rows = rng.below(40) as usize;
            let extra = if rng.below(10) == 0 { 1 } else { 0 };
            (0..rows * w + extra)
                .map(|_| match rng.below(4) {
                    // Few distinct values: many ties.
                    0 => rng.below(4),
                    _ => rng.next_u64(),
                })
                .collect::<Vec<u64>>()
        };
        let width_q = DescriptorWidth::from_bits(bits_q).unwrap();
        let width_t = DescriptorWidth::from_bits(bits_t).unwrap();
        let (wq, wt) = (words(bits_q, &mut rng), words(bits_t, &mut rng));
        let query = tally.call(
            || format!("case {case}: query set"),
            || DescriptorSet::from_words(width_q, wq.clone()),
        );
        let train = tally.call(
            || format!("case {case}: train set"),
            || DescriptorSet::from_words(width_t, wt.clone()),
        );
        let (Some(query), Some(train)) = (query, train) else {
            continue;
        };
        for i in [0, query.len(), usize::MAX] {
            assert_eq!(query.get(i).is_some(), i < query.len());
            assert_eq!(query.descriptor(i).is_some(), i < query.len());
        }
        let k = match rng.below(5) {
            0 => 0,
            1 => train.len() + 1,
            _ => 1 + rng.below(4) as usize,
        };
        let config = MatchConfig::default()
            .with_ratio(match rng.below(6) {
                0 => Some(wild_f32!(&mut rng, 0.8)),
                1 => None,
                _ => Some([0.5, 0.8, 1.0][rng.below(3) as usize]),
            })
            .with_cross_check(rng.below(2) == 0)
            .with_max_distance((rng.below(3) == 0).then(|| rng.below(100) as u32));
        let Some(matcher) = tally.call(
            || format!("case {case}: Matcher::new({config:?})"),
            || Matcher::new(Backend::Cpu, config.clone()),
        ) else {
            continue;
        };
        if let Some(knn) = tally.call(
            || format!("case {case}: knn k={k}"),
            || matcher.knn(&query, &train, k),
        ) {
            assert_eq!(knn.as_slice(), naive_knn(&query, &train, k), "case {case}");
            assert_eq!(knn.len(), query.len());
            assert_eq!(knn.neighbours(knn.len()), None);
            // An index whose product with k wraps round is past the end, not query 0 again.
            if k > 1 {
                assert_eq!(knn.neighbours(usize::MAX / k + 1), None, "k = {k}");
            }
            assert_eq!(knn.neighbours(usize::MAX), None);
        }
        if let Some(matches) = tally.call(
            || format!("case {case}: match_descriptors"),
            || matcher.match_descriptors(&query, &train),
        ) {
            assert_eq!(matches, naive_match(&query, &train, &config), "case {case}");
        }
        // Hand-built kNN lists: any k and length is accepted or refused, never a panic.
        let k = rng.below(4) as usize;
        let list: Vec<Match> = (0..rng.below(9))
            .map(|i| Match {
                query: i as u32,
                train: rng.below(5) as u32,
                distance: 0,
            })
            .collect();
        let n = list.len();
        match KnnMatches::new(k, list) {
            Some(knn) => assert_eq!(knn.len() * k, n),
            None => assert!(k == 0 || !n.is_multiple_of(k)),
        }
    }
    tally.finish("descriptor sets and matching");
}

#[test]
fn descriptors_and_synthetic_images_at_their_limits() {
    let d = clatch::Descriptor([u64::MAX; 8]);
    assert_eq!(d.bit(511), Some(true));
    assert_eq!(d.bit(512), None);
    assert_eq!(d.bit(usize::MAX), None);
    let mut rng = SplitMix64::new(3);
    assert_eq!(rng.below(0), 0);
    for (w, h) in [(0, 0), (0, 5), (5, 0), (1, 1)] {
        assert_eq!(clatch::synthetic::rectangles(w, h, 1).unwrap().len(), w * h);
        assert_eq!(clatch::synthetic::noise(w, h, 1).unwrap().len(), w * h);
    }
    for (w, h) in [
        (usize::MAX, 2),
        (2, usize::MAX),
        (clatch::MAX_IMAGE_SIDE + 1, 1),
    ] {
        assert!(matches!(
            clatch::synthetic::rectangles(w, h, 1),
            Err(Error::ImageTooLarge { .. })
        ));
        assert!(matches!(
            clatch::synthetic::noise(w, h, 1),
            Err(Error::ImageTooLarge { .. })
        ));
    }
}

#[test]
fn colmap_records_from_hostile_values() {
    use clatch::colmap::{Database, MatchList, PinholeCamera, image_ids_of_pair, pair_id};
    let mut tally = Tally::default();
    let mut rng = SplitMix64::new(0x5eed_0004);
    let dir = std::env::temp_dir().join(format!("clatch-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("hostile.db");
    std::fs::remove_file(&path).ok();
    let mut db = Database::create(&path).unwrap();
    let texts = [
        "",
        "1 2 3",
        "nan 0 1 0 nan 1 0 0 1",
        "1e400 0 1 0 1 1 0 0 1",
        "5 0 2 0 5 2 0 0 1",
        "5 1 2 0 5 2 0 0 1",
    ];
    let mut images = Vec::new();
    for case in 0..cases(2_000) {
        let (w, h) = (rng.next_u64() as u32 % 5000, rng.next_u64() as u32 % 5000);
        let text = texts[rng.below(texts.len() as u64) as usize];
        let camera = match rng.below(3) {
            0 => PinholeCamera::from_k_text(text, w, h).map_err(|e| e.to_string()),
            _ => PinholeCamera::guess(w, h).map_err(|e| e.to_string()),
        };
        tally.calls += 1;
        let Ok(camera) = camera else { continue };
        let camera_id = match db.add_camera(&camera) {
            Ok(id) => id,
            Err(_) => continue,
        };
        let name = match rng.below(5) {
            0 => String::new(),
            1 => "/absolute.png".into(),
            2 => "has space.png".into(),
            _ => format!("img{}.png", rng.below(50)),
        };
        let Ok(id) = db.add_image(&name, camera_id) else {
            continue;
        };
        let keypoints: Vec<KeyPoint> = (0..rng.below(20))
            .map(|_| KeyPoint::new(wild_f32!(&mut rng, 3.0), 4.0))
            .collect();
        let _ = db.set_keypoints(id, &keypoints);
        images.push((id, keypoints.len(), name));
        if images.len() >= 2 {
            let a = &images[rng.below(images.len() as u64) as usize];
            let b = &images[rng.below(images.len() as u64) as usize];
            let matches: Vec<Match> = (0..rng.below(6))
                .map(|_| Match {
                    query: rng.below(a.1 as u64 + 3) as u32,
                    train: rng.below(b.1 as u64 + 3) as u32,
                    distance: 1,
                })
                .collect();
            let _ = db.add_matches(a.0, b.0, &matches);
            let mut list = MatchList::new(Vec::new());
            let _ = list.add_pair(&a.2, &b.2, &matches);
        }
        let (x, y) = (rng.next_u64() as u32, rng.next_u64() as u32);
        let _ = image_ids_of_pair(rng.next_u64());
        if x.max(y) < 2_147_483_647 {
            assert_eq!(
                image_ids_of_pair(pair_id(x, y)),
                (x.min(y), x.max(y)),
                "case {case}"
            );
        }
        let _ = clatch::colmap::keypoints_blob(&random_keypoints(&mut rng, 10, 10));
    }
    tally.call(
        || "finish".into(),
        || db.finish().map_err(|_| Error::EmptyGallery),
    );
    std::fs::remove_dir_all(&dir).ok();
    tally.finish("COLMAP records");
}
