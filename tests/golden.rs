//! Golden results on the embedded photograph (`assets/astronaut.png`, 512x512 gray): the detected
//! keypoints and the descriptor bits of a fixed keypoint list must equal `tests/golden/astronaut.txt`
//! exactly. Any backend (the CUDA one included) must reproduce this file.
//!
//! Regenerate (only after a deliberate change of the numeric contract):
//! `CLATCH_BLESS=1 cargo test --test golden`, which rewrites the file instead of comparing.
//!
//! # File format (text, one record per line, `#` starts a comment line)
//!
//! ```text
//! detect <n>                            n keypoints of the default DetectorConfig, in output order:
//! <x> <y> <angle> <response>            f32 values printed by Rust's `Display` (shortest exact form)
//! describe <section> <bits> <n>         n = length of the keypoint list (the same list in every section)
//! <i> <x> <y> <size> <angle> <result>   keypoint i of the list; result is `skipped`, or the descriptor:
//!                                       its 64-bit words, word 0 first, each as 16 hex digits (most
//!                                       significant first), joined by `_`; bit t = bit t%64 of word t/64
//! ```
//!
//! Sections: `latch7x7` (default weights) at 512 and 136 bits, `uniform` (all weights 1) at 512 bits.
//!
//! The test also checks the file itself for plausibility with independent, direct code: every golden
//! keypoint's response is its FAST-9 score and a local maximum, its angle is within half a bin of the
//! intensity-centroid direction, and every descriptor of a size-64 keypoint at an integer position with a
//! right angle is recomputed bit by bit from the image pixels and the triplet table.

mod common;

use std::fmt::Write as _;
use std::path::PathBuf;

use clatch::describe::triplets::TRIPLETS;
use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorConfig, DescriptorWidth, DetectorConfig, Extractor, ExtractorConfig,
    KeyPoint, PatchWeights,
};
use common::{Gray, astronaut};

fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/astronaut.txt")
}

fn blessing() -> bool {
    std::env::var("CLATCH_BLESS").is_ok_and(|v| v == "1")
}

/// The committed keypoint list: integer and sub-pixel positions, many angles and sizes, and keypoints
/// near and over the border (some of which are skipped).
fn keypoint_list() -> Vec<KeyPoint> {
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

fn sections() -> Vec<(&'static str, PatchWeights, usize)> {
    vec![
        ("latch7x7", PatchWeights::latch_7x7(), 512),
        ("latch7x7", PatchWeights::latch_7x7(), 136),
        ("uniform", PatchWeights::uniform(), 512),
    ]
}

fn hex_row(words: &[u64]) -> String {
    words
        .iter()
        .map(|w| format!("{w:016x}"))
        .collect::<Vec<_>>()
        .join("_")
}

fn parse_hex_row(text: &str) -> Vec<u64> {
    text.split('_')
        .map(|w| u64::from_str_radix(w, 16).expect("hex word"))
        .collect()
}

/// The golden text of the current implementation.
fn render(image: &Gray) -> String {
    let view = image.view();
    let mut out = String::new();
    writeln!(out, "# Golden results of tests/golden.rs on assets/astronaut.png; the format is documented there.").unwrap();
    writeln!(out, "# Regenerate only for a deliberate contract change: CLATCH_BLESS=1 cargo test --test golden").unwrap();
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    let detected = extractor.detect(&view).unwrap();
    writeln!(out, "detect {}", detected.len()).unwrap();
    for k in &detected {
        writeln!(out, "{} {} {} {}", k.x, k.y, k.angle, k.response).unwrap();
    }
    let list = keypoint_list();
    for (name, weights, bits) in sections() {
        let config = ExtractorConfig {
            descriptor: DescriptorConfig {
                width: DescriptorWidth::from_bits(bits).unwrap(),
                weights,
            },
            ..ExtractorConfig::default()
        };
        let described = Extractor::new(Backend::Cpu, config)
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
    out
}

/// One keypoint of a `describe` section: `[x, y, size, angle]` and its descriptor words (`None` =
/// skipped).
type GoldenRow = ([f32; 4], Option<Vec<u64>>);

/// Parsed golden file.
struct Golden {
    /// `[x, y, angle, response]` of each detected keypoint.
    detected: Vec<[f32; 4]>,
    /// Sections: name, bits, one row per keypoint of the list.
    described: Vec<(String, usize, Vec<GoldenRow>)>,
}

fn parse(text: &str) -> Golden {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let mut golden = Golden {
        detected: Vec::new(),
        described: Vec::new(),
    };
    let floats =
        |fields: &[&str]| -> Vec<f32> { fields.iter().map(|f| f.parse().expect("f32")).collect() };
    while let Some(header) = lines.next() {
        let fields: Vec<&str> = header.split(' ').collect();
        match fields[0] {
            "detect" => {
                let n: usize = fields[1].parse().unwrap();
                for line in lines.by_ref().take(n) {
                    let v = floats(&line.split(' ').collect::<Vec<_>>());
                    golden.detected.push([v[0], v[1], v[2], v[3]]);
                }
            }
            "describe" => {
                let (bits, n): (usize, usize) =
                    (fields[2].parse().unwrap(), fields[3].parse().unwrap());
                let mut rows = Vec::new();
                for line in lines.by_ref().take(n) {
                    let f: Vec<&str> = line.split(' ').collect();
                    let v = floats(&f[1..5]);
                    let words = (f[5] != "skipped").then(|| parse_hex_row(f[5]));
                    rows.push(([v[0], v[1], v[2], v[3]], words));
                }
                golden.described.push((fields[1].to_string(), bits, rows));
            }
            other => panic!("unexpected golden line {other:?}"),
        }
    }
    golden
}

/// FAST-9 score written out plainly: one more than the largest t such that nine contiguous circle
/// pixels are all > p + t or all < p - t (0 if there is no such t >= 0). `arc(t)` is monotone in t, so the
/// largest t is found by bisection.
fn direct_fast_score(img: &Gray, x: usize, y: usize) -> i32 {
    const CIRCLE: [(i32, i32); 16] = [
        (0, -3),
        (1, -3),
        (2, -2),
        (3, -1),
        (3, 0),
        (3, 1),
        (2, 2),
        (1, 3),
        (0, 3),
        (-1, 3),
        (-2, 2),
        (-3, 1),
        (-3, 0),
        (-3, -1),
        (-2, -2),
        (-1, -3),
    ];
    let p = img.at(x, y) as i32;
    let c: Vec<i32> = CIRCLE
        .iter()
        .map(|&(dx, dy)| img.at((x as i32 + dx) as usize, (y as i32 + dy) as usize) as i32)
        .collect();
    let arc = |t: i32| {
        (0..16).any(|k| {
            (0..9).all(|j| c[(k + j) % 16] > p + t) || (0..9).all(|j| c[(k + j) % 16] < p - t)
        })
    };
    if !arc(0) {
        return 0;
    }
    let (mut lo, mut hi) = (0, 255); // arc(lo) holds, arc(hi) does not
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if arc(mid) { lo = mid } else { hi = mid }
    }
    lo + 1
}

#[test]
fn golden_file() {
    let image = astronaut();
    assert_eq!((image.width, image.height), (512, 512));
    let text = render(&image);
    let path = golden_path();
    if blessing() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &text).unwrap();
        // Written past the test harness's output capture, so the rewrite is always visible.
        use std::io::Write as _;
        writeln!(
            std::io::stderr(),
            "CLATCH_BLESS=1: rewrote {} ({} bytes) instead of comparing",
            path.display(),
            text.len()
        )
        .unwrap();
    } else {
        let expected = std::fs::read_to_string(&path).unwrap_or_else(|e| {
            panic!("{}: {e} (generate it with CLATCH_BLESS=1)", path.display())
        });
        let mismatches: Vec<String> = expected
            .lines()
            .zip(text.lines())
            .enumerate()
            .filter(|(_, (e, g))| e != g)
            .map(|(n, (e, g))| {
                let (ef, gf): (Vec<&str>, Vec<&str>) =
                    (e.split(' ').collect(), g.split(' ').collect());
                let bits = match (ef.get(5), gf.get(5)) {
                    (Some(e), Some(g))
                        if e.contains('_') && g.contains('_') && ef[..5] == gf[..5] =>
                    {
                        let differing: Vec<usize> = parse_hex_row(e)
                            .iter()
                            .zip(parse_hex_row(g))
                            .enumerate()
                            .flat_map(|(w, (a, b))| {
                                (0..64)
                                    .filter(move |t| ((a ^ b) >> t) & 1 == 1)
                                    .map(move |t| 64 * w + t)
                            })
                            .collect();
                        format!(" (bits {differing:?} differ)")
                    }
                    _ => String::new(),
                };
                format!("line {}: expected `{e}`, got `{g}`{bits}", n + 1)
            })
            .collect();
        assert!(
            mismatches.is_empty() && expected.lines().count() == text.lines().count(),
            "{} differs from the implementation ({} vs {} lines); first mismatches:\n{}",
            path.display(),
            expected.lines().count(),
            text.lines().count(),
            mismatches
                .iter()
                .take(20)
                .cloned()
                .collect::<Vec<_>>()
                .join("\n")
        );
    }
    // The file's own contents must be plausible whatever produced them: check what is on disk now.
    check_plausible(&image, &parse(&std::fs::read_to_string(&path).unwrap()));
}

fn check_plausible(image: &Gray, golden: &Golden) {
    // ---- detection ----
    let config = DetectorConfig::default();
    let m = config.margin();
    assert!(
        golden.detected.len() > 200,
        "a photograph has hundreds of corners"
    );
    assert!(golden.detected.len() <= config.max_keypoints);
    let score = |x: usize, y: usize| {
        if (m..512 - m).contains(&x) && (m..512 - m).contains(&y) {
            let s = direct_fast_score(image, x, y);
            if s > config.threshold as i32 { s } else { 0 }
        } else {
            0
        }
    };
    let mut previous: Option<(f32, f32, f32)> = None;
    for &[x, y, angle, response] in &golden.detected {
        assert_eq!((x.fract(), y.fract()), (0.0, 0.0));
        let (xi, yi) = (x as usize, y as usize);
        let s = score(xi, yi);
        assert_eq!(s as f32, response, "FAST score at ({x}, {y})");
        for (dx, dy) in [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ] {
            let n = score((xi as i32 + dx) as usize, (yi as i32 + dy) as usize);
            let earlier = dy < 0 || (dy == 0 && dx < 0);
            assert!(
                if earlier { s > n } else { s >= n },
                "({x}, {y}) is not a local maximum"
            );
        }
        // Strongest first, then raster order.
        if let Some(p) = previous {
            assert!((-p.2, p.1, p.0) < (-response, y, x), "order at ({x}, {y})");
        }
        previous = Some((x, y, response));
        // Orientation: within half a bin (1/16 degree) of the intensity centroid's direction.
        let (mut m10, mut m01) = (0f64, 0f64);
        for dy in -15i32..=15 {
            for dx in -15i32..=15 {
                if dx * dx + dy * dy <= 225 {
                    let v = image.at((xi as i32 + dx) as usize, (yi as i32 + dy) as usize) as f64;
                    m10 += dx as f64 * v;
                    m01 += dy as f64 * v;
                }
            }
        }
        let exact = m01.atan2(m10).to_degrees().rem_euclid(360.0);
        let diff = (exact - angle as f64 + 180.0).rem_euclid(360.0) - 180.0;
        assert!(
            diff.abs() <= 1.0 / 16.0 + 1e-9,
            "angle {angle} vs centroid {exact} at ({x}, {y})"
        );
        assert_eq!((angle * 8.0).fract(), 0.0);
        assert!((0.0..360.0).contains(&angle));
    }

    // ---- description ----
    let list = keypoint_list();
    assert_eq!(golden.described.len(), sections().len());
    let (mut checked, mut hand_described, mut hand_skipped) = (0, 0, 0);
    for ((name, weights, bits), (golden_name, golden_bits, rows)) in
        sections().iter().zip(&golden.described)
    {
        assert_eq!((name, bits), (&golden_name.as_str(), golden_bits));
        assert_eq!(rows.len(), list.len());
        let weights = weights.as_array();
        let skipped = rows.iter().filter(|r| r.1.is_none()).count();
        assert!(
            (10..list.len() / 2).contains(&skipped),
            "{skipped} skipped in {name} {bits}"
        );
        for (k, (params, words)) in list.iter().zip(rows) {
            assert_eq!(
                *params,
                [k.x, k.y, k.size, k.angle],
                "the keypoint list changed: re-bless"
            );
            // Hand-check: size 64, integer position, a right angle.
            let right = (k.angle as f64).rem_euclid(90.0) == 0.0;
            if k.size != 64.0 || k.x.fract() != 0.0 || k.y.fract() != 0.0 || !right {
                continue;
            }
            let turns = ((k.angle as f64).rem_euclid(360.0) / 90.0) as i64;
            let (c, s) = [(1, 0), (0, 1), (-1, 0), (0, -1)][turns as usize];
            // Window pixel (u, v) is image pixel o + (u - 32)(c, s) + (v - 32)(-s, c).
            let fits = [0i64, 63].iter().all(|&u| {
                [0i64, 63].iter().all(|&v| {
                    let px = k.x as i64 + (u - 32) * c - (v - 32) * s;
                    let py = k.y as i64 + (u - 32) * s + (v - 32) * c;
                    (0..512).contains(&px) && (0..512).contains(&py)
                })
            });
            assert_eq!(words.is_some(), fits, "{k:?}");
            hand_described += fits as usize;
            hand_skipped += !fits as usize;
            let Some(words) = words else { continue };
            let pixel = |u: usize, v: usize| {
                let (du, dv) = (u as i64 - 32, v as i64 - 32);
                image.at(
                    (k.x as i64 + du * c - dv * s) as usize,
                    (k.y as i64 + du * s + dv * c) as usize,
                ) as i64
            };
            for (t, &[ax, ay, bx, by, cx, cy]) in TRIPLETS[..*bits].iter().enumerate() {
                let (mut ssd_ab, mut ssd_cb) = (0i64, 0i64);
                for r in 0..8 {
                    for q in 0..8 {
                        let w = weights[r * 8 + q] as i64;
                        let a = pixel(ax as usize + q, ay as usize + r);
                        let b = pixel(bx as usize + q, by as usize + r);
                        let cc = pixel(cx as usize + q, cy as usize + r);
                        ssd_ab += w * (a - b) * (a - b);
                        ssd_cb += w * (cc - b) * (cc - b);
                    }
                }
                let bit = (words[t / 64] >> (t % 64)) & 1 == 1;
                assert_eq!(bit, ssd_ab < ssd_cb, "{name} {bits}: bit {t} of {k:?}");
                checked += 1;
            }
            // Bits past the width are zero.
            assert_eq!(words.len(), bits.div_ceil(64));
            if bits % 64 != 0 {
                assert_eq!(words[words.len() - 1] >> (bits % 64), 0);
            }
        }
    }
    // Per section: 4 positions x 6 right angles, angle 3600, and the 4 integer border keypoints that just
    // fit are recomputed; the 3 integer ones that just miss are checked to be skipped.
    assert_eq!(hand_described, 3 * (4 * 6 + 1 + 4));
    assert_eq!(hand_skipped, 3 * 3);
    assert_eq!(checked, (4 * 6 + 1 + 4) * (512 + 136 + 512));

    // The 136-bit descriptors are the first 136 bits of the 512-bit ones.
    let (full, short) = (&golden.described[0].2, &golden.described[1].2);
    for (f, s) in full.iter().zip(short) {
        match (&f.1, &s.1) {
            (Some(f), Some(s)) => assert_eq!(s, &vec![f[0], f[1], f[2] & 0xFF]),
            (None, None) => {}
            _ => panic!("a keypoint is skipped at one width only"),
        }
    }
    // Right angles agree with their +360 / -270 aliases.
    for (_, _, rows) in &golden.described {
        for group in rows[..24].chunks(6) {
            assert_eq!(group[0].1, group[5].1, "0 and 360 degrees");
            assert_eq!(group[3].1, group[4].1, "270 and -90 degrees");
        }
    }
}
