//! GPU verification throughput against the CPU backend in the same run:
//! `cargo bench --features cuda --bench gpu_verify`.
//!
//! Batches of synthetic pairs of 850 putative matches, 40 % outliers, 0.5 px noise (general 3-D
//! scenes; uncalibrated, F and H, and calibrated, E, F and H), COLMAP 3.8's default settings. For the
//! GPU: the kernel time of one launch over the batch (CUDA events, after warm-up; the median of the
//! repeats) and the wall time of `Verifier::verify_pairs` (packing, upload, kernel, download); for the
//! CPU backend (rayon, every thread of the machine) the wall time of the same call, median of the
//! repeats. Pairs per second, and the GPU/CPU ratio. Every GPU result is checked equal to the CPU's.

#[cfg(feature = "cuda")]
mod common;
#[cfg(feature = "cuda")]
#[path = "../tests/common/scene_pair.rs"]
mod scene_pair;
#[cfg(feature = "cuda")]
#[path = "../tests/common/two_view.rs"]
mod two_view;

#[cfg(feature = "cuda")]
use clatch::synthetic::SplitMix64;

#[cfg(not(feature = "cuda"))]
fn main() {
    println!("skipped: no CUDA device (built without the `cuda` feature)");
}

#[cfg(feature = "cuda")]
fn main() {
    use std::time::Instant;

    use clatch::verify::{VerifyConfig, ViewPair};
    use clatch::{Backend, Verifier};
    use scene_pair::ScenePair;
    use two_view::{Shape, scene};

    const MATCHES: usize = 850;
    const OUTLIERS: f64 = 0.4;
    const WARMUP: usize = 2;
    const REPEATS: usize = 7;

    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    let gpu_pairs: usize = std::env::var("CLATCH_BENCH_PAIRS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8192);
    let cpu_pairs = (gpu_pairs / 16).max(64);
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    for calibrated in [false, true] {
        let owned: Vec<ScenePair> = (0..gpu_pairs as u64)
            .map(|seed| {
                let pair = ScenePair::new(&scene(seed, Shape::General, MATCHES, OUTLIERS, 0.5));
                if calibrated {
                    pair
                } else {
                    pair.without_intrinsics()
                }
            })
            .collect();
        let pairs: Vec<ViewPair<'_>> = owned
            .iter()
            .enumerate()
            .map(|(i, o)| {
                ViewPair::new(&o.a, &o.b, &o.matches)
                    .with_cameras(&o.cameras.0, &o.cameras.1)
                    .with_key(i as u64)
            })
            .collect();
        let config = VerifyConfig::default();
        let what = if calibrated {
            "calibrated (E, F, H)"
        } else {
            "uncalibrated (F, H)"
        };

        let kernel_ms = median(
            clatch::cuda::hooks::time_verify_kernel(&dev, &pairs, &config, WARMUP, REPEATS)
                .expect("timed kernel")
                .into_iter()
                .map(f64::from)
                .collect(),
        );
        let gpu = Verifier::new(Backend::Cuda { device: 0 }, config.clone()).expect("gpu");
        let cpu = Verifier::new(Backend::Cpu, config.clone()).expect("cpu");
        let mut gpu_wall = Vec::new();
        let mut got = Vec::new();
        for _ in 0..3 {
            let t = Instant::now();
            got = gpu.verify_pairs(&pairs).expect("gpu verification");
            gpu_wall.push(t.elapsed().as_secs_f64());
        }
        let gpu_wall = median(gpu_wall);
        let mut cpu_wall = Vec::new();
        let mut want = Vec::new();
        for _ in 0..3 {
            let t = Instant::now();
            want = cpu
                .verify_pairs(&pairs[..cpu_pairs])
                .expect("cpu verification");
            cpu_wall.push(t.elapsed().as_secs_f64());
        }
        let cpu_wall = median(cpu_wall);
        let differing = want.iter().zip(&got).filter(|(w, g)| w != g).count();
        assert_eq!(
            differing, 0,
            "{differing} of {cpu_pairs} pairs differ between GPU and CPU"
        );
        let kernel_rate = gpu_pairs as f64 / (kernel_ms / 1e3);
        let gpu_rate = gpu_pairs as f64 / gpu_wall;
        let cpu_rate = cpu_pairs as f64 / cpu_wall;
        println!(
            "{what}, {MATCHES} matches, {:.0} % outliers: GPU kernel {kernel_ms:.1} ms for {gpu_pairs} pairs = \
             {kernel_rate:.0} pairs/s; GPU verify_pairs {:.1} ms = {gpu_rate:.0} pairs/s; CPU ({} threads) \
             {:.1} ms for {cpu_pairs} pairs = {cpu_rate:.0} pairs/s; GPU/CPU {:.1}x (kernel {:.1}x); \
             {cpu_pairs} pairs compared, 0 differ",
            OUTLIERS * 100.0,
            gpu_wall * 1e3,
            rayon::current_num_threads(),
            cpu_wall * 1e3,
            gpu_rate / cpu_rate,
            kernel_rate / cpu_rate,
        );
    }
}
