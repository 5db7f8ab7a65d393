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
//! detect <n>                            n keypoints of ExtractorConfig::single_scale(), in output order:
//! <x> <y> <angle> <response>            f32 values printed by Rust's `Display` (shortest exact form)
//! describe <section> <bits> <n>         n = length of the keypoint list (the same list in every section)
//! <i> <x> <y> <size> <angle> <result>   keypoint i of the list; result is `skipped`, or the descriptor:
//!                                       its 64-bit words, word 0 first, each as 16 hex digits (most
//!                                       significant first), joined by `_`; bit t = bit t%64 of word t/64
//! ```
//!
//! Sections: `latch7x7` (default weights) at 512 and 136 bits, `uniform` (all weights 1) at 512 bits.
//!
//! Last, `extract-default <n>`: the n keypoints of `ExtractorConfig::default()`'s `detect_and_describe`
//! (8-level pyramid, level shares, sub-pixel positions), one line each:
//! `<x> <y> <size> <angle> <response> <octave> <word 0 of its descriptor, 16 hex digits>`.
//!
//! The test also checks the file itself for plausibility with independent, direct code: every golden
//! keypoint's response is its FAST-9 score and a local maximum, its angle is within half a bin of the
//! intensity-centroid direction, and every descriptor of a size-64 keypoint at an integer position with a
//! right angle is recomputed bit by bit from the image pixels and the triplet table.

mod common;

use clatch::Backend;
use clatch::describe::triplets::TRIPLETS;
use common::golden::{golden_path, keypoint_list, parse_hex_row, render, sections};
use common::{Gray, astronaut};

fn blessing() -> bool {
    std::env::var("CLATCH_BLESS").is_ok_and(|v| v == "1")
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
    /// `[x, y, size, angle, response, octave]` of each keypoint of the default extraction.
    extracted: Vec<[f32; 6]>,
}

fn parse(text: &str) -> Golden {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let mut golden = Golden {
        detected: Vec::new(),
        described: Vec::new(),
        extracted: Vec::new(),
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
            "extract-default" => {
                let n: usize = fields[1].parse().unwrap();
                for line in lines.by_ref().take(n) {
                    let f: Vec<&str> = line.split(' ').collect();
                    let v = floats(&f[..6]);
                    assert_eq!(f[6].len(), 16, "64 bits of descriptor");
                    golden.extracted.push([v[0], v[1], v[2], v[3], v[4], v[5]]);
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
    let text = render(&image, Backend::Cpu);
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
    let config = clatch::ExtractorConfig::single_scale().detector;
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

    // ---- the default extraction ----
    let default = clatch::ExtractorConfig::default();
    let pyramid = default.pyramid.unwrap();
    assert!(
        golden.extracted.len() > 1000 && golden.extracted.len() <= default.detector.max_keypoints
    );
    let mut octaves = vec![0usize; pyramid.levels];
    let mut refined = 0;
    for &[x, y, size, _angle, response, octave] in &golden.extracted {
        let level = octave as usize;
        octaves[level] += 1;
        let expected = default.detector.keypoint_size * pyramid.scale_factor.powi(octave as i32);
        assert!(
            (size - expected).abs() < 1e-3 * expected,
            "size {size} on level {level}"
        );
        assert!(response > f32::from(default.detector.threshold));
        // Positions on the 1/256 grid (16.16 rounded to 24.8), within the image.
        assert_eq!(((x * 256.0).fract(), (y * 256.0).fract()), (0.0, 0.0));
        assert!((0.0..512.0).contains(&x) && (0.0..512.0).contains(&y));
        refined += usize::from(level == 0 && (x.fract(), y.fract()) != (0.0, 0.0));
    }
    // ORB's shares reach the coarse levels; sub-pixel offsets move full-resolution keypoints.
    assert!(
        octaves.iter().filter(|&&n| n > 0).count() >= 6,
        "{octaves:?}"
    );
    assert!(
        refined > 100,
        "{refined} level-0 keypoints off the pixel grid"
    );

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
