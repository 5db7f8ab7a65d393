//! Timing and fingerprints of the CPU verification on synthetic pairs, one thread, for comparing two
//! builds (`dev/`-style harness, not part of the API).
//!
//! `cargo run --release --example verify_timing -- time [reps]`: the bench's pairs (850 matches, 30 %
//! and 50 % outliers, uncalibrated and calibrated), each verified serially, median seconds per batch.
//! `cargo run --release --example verify_timing -- fingerprint`: one line of bits per pair over many
//! random pairs (shapes, sizes, outlier shares, noise, both paths), to diff against another build.

#[path = "../tests/common/scene_pair.rs"]
mod scene_pair;
#[path = "../tests/common/two_view.rs"]
mod two_view;

use std::time::Instant;

use clatch::synthetic::SplitMix64;
use clatch::verify::{TwoViewGeometry, VerifyConfig, ViewPair};
use scene_pair::ScenePair;
use two_view::{Shape, scene};

fn pair(seed: u64, shape: Shape, n: usize, outliers: f64, noise: f64) -> ScenePair {
    ScenePair::new(&scene(seed, shape, n, outliers, noise))
}

fn view(p: &ScenePair, calibrated: bool, key: u64) -> ViewPair<'_> {
    let v = ViewPair::new(&p.a, &p.b, &p.matches).with_key(key);
    if calibrated {
        v.with_cameras(&p.cameras.0, &p.cameras.1)
    } else {
        v
    }
}

fn line(g: &TwoViewGeometry) -> String {
    let matrices: Vec<String> = [g.f, g.e, g.h]
        .into_iter()
        .flat_map(|m| {
            m.into_iter()
                .flatten()
                .flatten()
                .map(|v| format!("{:x}", v.to_bits()))
        })
        .collect();
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for &i in &g.inliers {
        hash = (hash ^ u64::from(i)).wrapping_mul(0x0100_0000_01b3);
    }
    format!(
        "{} {:?} n={} h={:016x} {}",
        g.config.colmap_code(),
        [g.inlier_counts.e, g.inlier_counts.f, g.inlier_counts.h],
        g.inliers.len(),
        hash,
        matrices.join(",")
    )
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mode = args.get(1).map_or("time", String::as_str);
    let config = VerifyConfig::default();
    match mode {
        "fingerprint" => {
            let shapes = [Shape::General, Shape::Planar, Shape::Rotation];
            let mut k = 0u64;
            for (si, shape) in shapes.into_iter().enumerate() {
                for &n in &[12usize, 30, 90, 300] {
                    for &outliers in &[0.0, 0.2, 0.5, 0.75] {
                        for &noise in &[0.0, 0.7, 3.0] {
                            let p = pair(1000 + k, shape, n, outliers, noise);
                            for calibrated in [false, true] {
                                let g = view(&p, calibrated, k).verify(&config).unwrap();
                                println!("{si} {n} {outliers} {noise} {calibrated} {}", line(&g));
                            }
                            k += 1;
                        }
                    }
                }
            }
            // Larger pairs, as the bench's.
            for seed in 0..6 {
                let p = pair(
                    5000 + seed,
                    Shape::General,
                    850,
                    0.3 + 0.05 * seed as f64,
                    0.5,
                );
                for calibrated in [false, true] {
                    let g = view(&p, calibrated, seed).verify(&config).unwrap();
                    println!("big {seed} {calibrated} {}", line(&g));
                }
            }
        }
        _ => {
            let reps: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
            for outliers in [0.3, 0.5] {
                let pairs: Vec<ScenePair> = (0..8u64)
                    .map(|k| pair(100 + k, Shape::General, 850, outliers, 0.5))
                    .collect();
                for calibrated in [false, true] {
                    let mut times = Vec::new();
                    for _ in 0..reps {
                        let start = Instant::now();
                        for (k, p) in pairs.iter().enumerate() {
                            std::hint::black_box(
                                view(p, calibrated, k as u64).verify(&config).unwrap(),
                            );
                        }
                        times.push(start.elapsed().as_secs_f64());
                    }
                    times.sort_by(f64::total_cmp);
                    println!(
                        "{} {}% outliers: median {:.3} s per 8 pairs ({:.1} pairs/s), min {:.3}",
                        if calibrated {
                            "calibrated  "
                        } else {
                            "uncalibrated"
                        },
                        outliers * 100.0,
                        times[reps / 2],
                        8.0 / times[reps / 2],
                        times[0]
                    );
                }
            }
        }
    }
}
