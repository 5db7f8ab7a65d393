//! Geometric verification on the CPU: `verify_pairs` over batches of synthetic pairs of ~850 putative
//! matches (a general 3-D scene, 0.5 px noise), with 30 % and 50 % outliers, uncalibrated (F and H)
//! and calibrated (E, F and H), COLMAP 3.8's default settings. Throughput in pairs per second, on
//! every rayon thread of the machine.
//!
//! `cargo bench --bench verify`

#[path = "../tests/common/scene_pair.rs"]
mod scene_pair;
#[path = "../tests/common/two_view.rs"]
mod two_view;

use std::hint::black_box;
use std::time::Duration;

use clatch::synthetic::SplitMix64;
use clatch::verify::{VerifyConfig, ViewPair, verify_pairs};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use scene_pair::ScenePair;
use two_view::{Shape, scene};

/// Pairs in a batch.
const PAIRS: usize = 8;
/// Putative matches per pair.
const MATCHES: usize = 850;

fn pair(seed: u64, outliers: f64) -> ScenePair {
    ScenePair::new(&scene(seed, Shape::General, MATCHES, outliers, 0.5))
}

fn verification(c: &mut Criterion) {
    let config = VerifyConfig::default();
    let mut group = c.benchmark_group(format!("verify_pairs, {MATCHES} matches"));
    group
        .measurement_time(Duration::from_secs(10))
        .sample_size(10);
    group.throughput(Throughput::Elements(PAIRS as u64));
    for outliers in [0.3, 0.5] {
        let pairs: Vec<ScenePair> = (0..PAIRS as u64).map(|k| pair(100 + k, outliers)).collect();
        for calibrated in [false, true] {
            let views: Vec<ViewPair<'_>> = pairs
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    let view = ViewPair::new(&p.a, &p.b, &p.matches).with_key(k as u64);
                    if calibrated {
                        view.with_cameras(&p.cameras.0, &p.cameras.1)
                    } else {
                        view
                    }
                })
                .collect();
            let name = format!(
                "{} {}% outliers",
                if calibrated {
                    "calibrated"
                } else {
                    "uncalibrated"
                },
                outliers * 100.0
            );
            group.bench_with_input(BenchmarkId::from_parameter(name), &views, |b, views| {
                b.iter(|| verify_pairs(black_box(views), &config).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, verification);
criterion_main!(benches);
