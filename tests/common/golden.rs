//! The golden file's content, computed by any backend (tests/golden.rs documents the format).

use std::fmt::Write as _;

use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorConfig, DescriptorWidth, Extractor, ExtractorConfig, KeyPoint, PatchWeights,
    Smoothing,
};

use super::Gray;

/// Where the golden file lives: in this checkout, or (for a test binary carried to another machine)
/// under the current directory.
pub fn golden_path() -> std::path::PathBuf {
    let relative = "tests/golden/astronaut.txt";
    let built = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(relative);
    if built.exists() {
        built
    } else {
        relative.into()
    }
}

/// The committed keypoint list: integer and sub-pixel positions, many angles and sizes, and keypoints
/// near and over the border (some of which are skipped).
pub fn keypoint_list() -> Vec<KeyPoint> {
    let kp = |x: f32, y: f32, size: f32, angle: f32| {
        KeyPoint::new(x, y).with_size(size).with_angle(angle)
    };
    let mut list = Vec::new();
    // Size 64 at integer positions and right angles: recomputed by hand below.
    for (x, y) in [
        (256.0, 256.0),
        (100.0, 300.0),
        (317.0, 141.0),
        (420.0, 77.0),
    ] {
        for angle in [0.0, 90.0, 180.0, 270.0, -90.0, 360.0] {
            list.push(kp(x, y, 64.0, angle));
        }
    }
    // Many angles at one integer and one sub-pixel position, several sizes.
    let angles = [
        45.0, 0.125, 359.875, -1.0, 1000.3, 0.0625, 0.1875, 30.0, 123.456, -200.7, 3600.0, 1e6,
    ];
    for (x, y) in [(200.0, 220.0), (250.25, 180.5)] {
        for size in [16.0, 31.0, 64.0, 100.0] {
            for angle in angles {
                list.push(kp(x, y, size, angle));
            }
        }
    }
    // Sub-pixel positions, including values that are not multiples of 2^-16.
    for (x, y) in [
        (123.4567, 321.9876),
        (255.999, 256.001),
        (300.5, 300.5),
        (99.75, 411.125),
    ] {
        list.push(kp(x, y, 64.0, 0.0));
        list.push(kp(x, y, 47.3, 77.7));
    }
    // Borders. Size 64, angle 0 spans x - 32 ..= x + 31: x = 32 and 480 just fit, 31, 481 and 480.5 do not.
    for (x, y) in [
        (32.0, 200.0),
        (31.0, 200.0),
        (480.0, 200.0),
        (481.0, 200.0),
        (480.5, 200.0),
        (200.0, 32.0),
        (200.0, 31.5),
        (200.0, 480.0),
        (200.0, 481.0),
    ] {
        list.push(kp(x, y, 64.0, 0.0));
    }
    // At 45 degrees the window's corners reach 44.5 pixels left and right, 45.25 up and 43.8 down.
    for (x, y) in [
        (44.0, 256.0),
        (45.0, 256.0),
        (466.0, 256.0),
        (467.0, 256.0),
        (256.0, 45.0),
        (256.0, 46.0),
        (256.0, 467.0),
        (256.0, 468.0),
    ] {
        list.push(kp(x, y, 64.0, 45.0));
    }
    // Corners of the image, large windows, tiny windows at the border.
    for (x, y, size) in [
        (0.0, 0.0, 16.0),
        (511.0, 511.0, 64.0),
        (256.0, 256.0, 1024.0),
        (256.0, 256.0, 362.0),
        (0.5, 300.0, 1.0),
        (511.0, 0.0, 1.0),
        (510.0, 3.0, 1.0),
    ] {
        list.push(kp(x, y, size, 10.0));
    }
    // Random keypoints over the whole image (many of them near a border are skipped).
    let mut rng = SplitMix64::new(2024);
    let mut unit = || (rng.next_u64() >> 40) as f32 / (1u32 << 24) as f32;
    for _ in 0..48 {
        let x = unit() * 511.0;
        let y = unit() * 511.0;
        let size = 16.0 + unit() * 84.0;
        let angle = unit() * 1440.0 - 720.0;
        list.push(kp(x, y, size, angle));
    }
    list
}

pub fn sections() -> Vec<(&'static str, PatchWeights, usize)> {
    vec![
        ("latch7x7", PatchWeights::latch_7x7(), 512),
        ("latch7x7", PatchWeights::latch_7x7(), 136),
        ("uniform", PatchWeights::uniform(), 512),
    ]
}

pub fn hex_row(words: &[u64]) -> String {
    words
        .iter()
        .map(|w| format!("{w:016x}"))
        .collect::<Vec<_>>()
        .join("_")
}

pub fn parse_hex_row(text: &str) -> Vec<u64> {
    text.split('_')
        .map(|w| u64::from_str_radix(w, 16).expect("hex word"))
        .collect()
}

/// The golden text computed by `backend`.
pub fn render(image: &Gray, backend: Backend) -> String {
    let view = image.view();
    let mut out = String::new();
    writeln!(out, "# Golden results of tests/golden.rs on assets/astronaut.png; the format is documented there.").unwrap();
    writeln!(out, "# Regenerate only for a deliberate contract change: CLATCH_BLESS=1 cargo test --test golden").unwrap();
    // The single-scale preset: whole-pixel keypoints that check_plausible recomputes directly (the
    // default pyramid is held to the CPU reference by tests/pyramid.rs and tests/cuda_pyramid.rs).
    let extractor = Extractor::new(backend, ExtractorConfig::single_scale()).unwrap();
    let detected = extractor.detect(&view).unwrap();
    writeln!(out, "detect {}", detected.len()).unwrap();
    for k in &detected {
        writeln!(out, "{} {} {} {}", k.x, k.y, k.angle, k.response).unwrap();
    }
    let list = keypoint_list();
    for (name, weights, bits) in sections() {
        let config = ExtractorConfig::default().with_descriptor(
            DescriptorConfig::default()
                .with_width(DescriptorWidth::from_bits(bits).unwrap())
                .with_weights(weights)
                // The golden file holds the unsmoothed bits.
                .with_smoothing(Smoothing::None),
        );
        let described = Extractor::new(backend, config)
            .unwrap()
            .describe(&view, &list)
            .unwrap();
        writeln!(out, "describe {name} {bits} {}", list.len()).unwrap();
        let mut rows = vec![None; list.len()];
        for (row, &i) in described.keypoint_index.iter().enumerate() {
            rows[i] = Some(described.descriptors.get(row).unwrap());
        }
        // Cross-check the two index lists against each other before they are flattened into one.
        assert_eq!(
            described.skipped.len() + described.keypoint_index.len(),
            list.len()
        );
        for s in &described.skipped {
            assert!(rows[s.keypoint].is_none());
        }
        for (i, (k, row)) in list.iter().zip(rows).enumerate() {
            let result = row.map_or_else(|| "skipped".to_string(), hex_row);
            writeln!(out, "{i} {} {} {} {} {result}", k.x, k.y, k.size, k.angle).unwrap();
        }
    }
    // The default extraction (pyramid, level shares, sub-pixel positions) and the first bits of each
    // descriptor: keypoints and descriptors of every level, on any backend.
    let features = Extractor::new(backend, ExtractorConfig::default())
        .unwrap()
        .detect_and_describe(&view)
        .unwrap();
    writeln!(out, "extract-default {}", features.keypoints.len()).unwrap();
    for (i, k) in features.keypoints.iter().enumerate() {
        let words = features.descriptors.get(i).unwrap();
        writeln!(
            out,
            "{} {} {} {} {} {} {:016x}",
            k.x, k.y, k.size, k.angle, k.response, k.octave, words[0]
        )
        .unwrap();
    }
    out
}
