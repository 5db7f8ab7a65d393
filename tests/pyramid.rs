//! The pyramid option end to end on the CPU: what it reports, that it leaves the default untouched,
//! and that it buys scale invariance (an image against itself scaled by 1/2 and by 2).

mod common;

use clatch::describe::SamplingFrame;
use clatch::{
    Backend, DetectorConfig, Extractor, ExtractorConfig, Features, MatchConfig, Matcher, Pyramid,
};
use common::{Gray, astronaut, rectangles};

fn extractor(pyramid: Option<Pyramid>) -> Extractor {
    Extractor::new(
        Backend::Cpu,
        ExtractorConfig::default()
            .with_pyramid(pyramid)
            // Whole pixels: these tests compare positions and descriptors with full-resolution ones.
            .with_detector(DetectorConfig::default().with_subpixel(clatch::Subpixel::None)),
    )
    .unwrap()
}

fn octave_two(levels: usize) -> Option<Pyramid> {
    Some(Pyramid::new(levels, 2.0))
}

/// `image` resized by `scale` with the `image` crate's Catmull-Rom filter: an independent resampler,
/// not the pyramid's own. Pixel centres map as `x' = (x + 1/2) scale - 1/2`.
fn resized(image: &Gray, scale: f64) -> Gray {
    let buffer = image::GrayImage::from_raw(
        image.width as u32,
        image.height as u32,
        image.pixels.clone(),
    )
    .unwrap();
    let (w, h) = (
        (image.width as f64 * scale).round() as u32,
        (image.height as f64 * scale).round() as u32,
    );
    let out = image::imageops::resize(&buffer, w, h, image::imageops::FilterType::CatmullRom);
    Gray::new(out.into_raw(), w as usize, h as usize)
}

/// Cross-checked, ratio-tested matches of `a` against `b` whose keypoints agree with the scale
/// (`b = (a + 1/2) scale - 1/2`) within `tolerance` pixels of the larger image; returns (correct, all).
fn correct_matches(a: &Features, b: &Features, scale: f64, tolerance: f64) -> (usize, usize) {
    let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
    let matches = matcher
        .match_descriptors(&a.descriptors, &b.descriptors)
        .unwrap();
    let to_larger = scale.max(1.0);
    let correct = matches
        .iter()
        .filter(|m| {
            let (p, q) = (a.keypoints[m.query as usize], b.keypoints[m.train as usize]);
            let ex = (p.x as f64 + 0.5) * scale - 0.5;
            let ey = (p.y as f64 + 0.5) * scale - 0.5;
            let error = (ex - q.x as f64).hypot(ey - q.y as f64) / scale * to_larger;
            error <= tolerance
        })
        .count();
    (correct, matches.len())
}

#[test]
fn a_one_level_pyramid_is_the_plain_detector() {
    let image = astronaut();
    let plain = extractor(None).detect_and_describe(&image.view()).unwrap();
    for factor in [2.0, 1.2] {
        let one = Some(Pyramid::new(1, factor));
        assert_eq!(
            extractor(one).detect_and_describe(&image.view()).unwrap(),
            plain
        );
    }
}

#[test]
fn levels_report_octave_size_and_level0_positions() {
    let image = rectangles(800, 600, 5);
    // The global budget: the strongest of all levels, so that a smaller budget keeps a prefix.
    let config = DetectorConfig::default()
        .with_level_budget(clatch::LevelBudget::Global)
        .with_subpixel(clatch::Subpixel::None);
    let e = Extractor::new(
        Backend::Cpu,
        ExtractorConfig::default()
            .with_detector(config.clone())
            .with_pyramid(Some(Pyramid::new(4, 1.5))),
    )
    .unwrap();
    let features = e.detect_and_describe(&image.view()).unwrap();
    assert_eq!(features.keypoints.len(), features.descriptors.len());
    assert_eq!(features.keypoints, e.detect(&image.view()).unwrap());
    let mut per_octave = [0usize; 4];
    for k in &features.keypoints {
        per_octave[k.octave as usize] += 1;
        assert_eq!(k.size, config.keypoint_size * 1.5f32.powi(k.octave));
        // The window the size stands for fits level 0, like every detected keypoint's.
        assert!(
            SamplingFrame::of(k).fits(image.width, image.height),
            "{k:?}"
        );
        // Positions on the 1/256 grid, inside the margin scaled to the level.
        assert_eq!((k.x * 256.0).fract(), 0.0);
        let m = config.margin() as f32;
        assert!(k.x >= m && k.y >= m && k.x < 800.0 - m && k.y < 600.0 - m);
    }
    assert!(per_octave.iter().all(|&n| n > 10), "{per_octave:?}");
    // Strongest first, across levels.
    assert!(
        features
            .keypoints
            .windows(2)
            .all(|p| p[0].response >= p[1].response)
    );
    // A top-N cut keeps a prefix.
    let few = Extractor::new(
        Backend::Cpu,
        e.config()
            .clone()
            .with_detector(config.with_max_keypoints(50)),
    )
    .unwrap()
    .detect_and_describe(&image.view())
    .unwrap();
    assert_eq!(few.keypoints, features.keypoints[..50]);
    for i in 0..50 {
        assert_eq!(few.descriptors.get(i), features.descriptors.get(i));
    }
}

#[test]
fn level0_keypoints_keep_their_plain_descriptors() {
    // Level-0 keypoints are described on the input image exactly as without the pyramid.
    let image = astronaut();
    let e = extractor(octave_two(3));
    let features = e.detect_and_describe(&image.view()).unwrap();
    let level0: Vec<usize> = (0..features.keypoints.len())
        .filter(|&i| features.keypoints[i].octave == 0)
        .collect();
    assert!(level0.len() > 100 && level0.len() < features.keypoints.len());
    let keypoints: Vec<_> = level0.iter().map(|&i| features.keypoints[i]).collect();
    let plain = extractor(None).describe(&image.view(), &keypoints).unwrap();
    for (row, &i) in level0.iter().enumerate() {
        assert_eq!(plain.descriptors.get(row), features.descriptors.get(i));
    }
}

/// (correct, all) matches of the astronaut against itself resized by `scale`, without and with
/// `pyramid`; printed for the record.
fn across_scale(scale: f64, pyramid: Pyramid, tolerance: f64) -> [(usize, usize); 2] {
    let image = astronaut();
    let other = resized(&image, scale);
    let counts = [None, Some(pyramid)].map(|p| {
        let e = extractor(p);
        let a = e.detect_and_describe(&image.view()).unwrap();
        let b = e.detect_and_describe(&other.view()).unwrap();
        correct_matches(&a, &b, scale, tolerance)
    });
    println!(
        "scale {scale:.4}, {pyramid:?}: (correct, matches) without pyramid {:?}, with {:?}",
        counts[0], counts[1]
    );
    counts
}

#[test]
fn the_pyramid_matches_across_scale_where_the_plain_detector_cannot() {
    // Measured: 1/2: 0 of 2 without, 467 of 470 with; 2: 3 of 6 without, 1645 of 1654 with.
    for scale in [0.5, 2.0] {
        let counts = across_scale(scale, octave_two(3).unwrap(), 4.0);
        let (plain, with) = (counts[0].0, counts[1].0);
        assert!(
            with >= 300 && with >= 20 * plain.max(1),
            "scale {scale}: {counts:?}"
        );
    }
}

#[test]
fn a_non_power_of_two_factor_matches_across_its_own_scale_steps() {
    // Scaled by 1/1.44 and by 1.44 = 1.2², two levels of a factor-1.2 pyramid apart. Measured:
    // 1/1.44: 13 of 23 without, 1230 of 1253 with; 1.44: 21 of 26 without, 1973 of 2009 with.
    let pyramid = Pyramid::new(5, 1.2);
    for scale in [1.0 / 1.44, 1.44] {
        let counts = across_scale(scale, pyramid, 3.0);
        let (plain, with) = (counts[0].0, counts[1].0);
        assert!(
            with >= 500 && with >= 20 * plain.max(1),
            "scale {scale}: {counts:?}"
        );
    }
}
