//! The multi-device scheduler's overhead on one GPU: `cargo bench --features cuda --bench gpu_pool`.
//!
//! `DevicePool` with CUDA device 0 listed as 1, 2 and 4 workers against the plain one-device calls,
//! on the same inputs in the same run: all pairs of 200 sets of 5000 random 512-bit descriptors
//! (19,900 pairs, ratio 0.8 + cross-check) through `Matcher::match_pairs`, and 64 synthetic 1080p
//! images (default configuration) through `Extractor::detect_and_describe_batch`. Wall time of the
//! whole call, median of the repeats after one warm-up run; every pool result is checked equal to the
//! one-device result. The ratio printed is pool / one device (1.00 = no overhead).
//! `CLATCH_POOL_SETS`, `CLATCH_POOL_DESCRIPTORS`, `CLATCH_POOL_IMAGES` and `CLATCH_POOL_REPEATS`
//! override the sizes. Built only with the `cuda` feature (`required-features`); without a device it
//! prints `skipped`.

mod common;

use std::time::Instant;

use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorSet, DescriptorWidth, DevicePool, Extractor, ExtractorConfig, GrayView,
    MatchConfig, Matcher,
};

const GPU: Backend = Backend::Cuda { device: 0 };

/// Median, fastest and slowest wall time of `repeats` runs after one warm-up run, and the last run's
/// result.
fn timed<T>(repeats: usize, mut f: impl FnMut() -> clatch::Result<T>) -> (f64, f64, f64, T) {
    f().expect("warm-up run");
    let mut walls = Vec::new();
    let mut last = None;
    for _ in 0..repeats {
        let t = Instant::now();
        last = Some(f().expect("timed run"));
        walls.push(t.elapsed().as_secs_f64());
    }
    walls.sort_by(f64::total_cmp);
    let result = last.expect("at least one run");
    (
        walls[walls.len() / 2],
        walls[0],
        walls[walls.len() - 1],
        result,
    )
}

fn main() {
    let setting = |name: &str, default: usize| {
        std::env::var(name)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let (set_count, per_set) = (
        setting("CLATCH_POOL_SETS", 200),
        setting("CLATCH_POOL_DESCRIPTORS", 5000),
    );
    let image_count = setting("CLATCH_POOL_IMAGES", 64);
    let repeats = setting("CLATCH_POOL_REPEATS", 3).max(1);

    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    // Matching: every pair of the collection.
    let width = DescriptorWidth::from_bits(512).unwrap();
    let mut rng = SplitMix64::new(11);
    let owned: Vec<DescriptorSet> = (0..set_count)
        .map(|_| {
            let words = (0..per_set * width.words())
                .map(|_| rng.next_u64())
                .collect();
            DescriptorSet::from_words(width, words).unwrap()
        })
        .collect();
    let sets: Vec<&DescriptorSet> = owned.iter().collect();
    let pairs = Matcher::all_pairs(set_count);
    let config = MatchConfig::default();
    let matcher = Matcher::new(GPU, config.clone()).unwrap();
    let (single, lo, hi, expected) = timed(repeats, || matcher.match_pairs(&sets, &pairs));
    let per_pair = |s: f64| s * 1e6 / pairs.len() as f64;
    println!(
        "match {set_count} sets of {per_set} (512 bits), {} pairs, ratio 0.8 + cross-check, median of \
         {repeats}:",
        pairs.len()
    );
    println!(
        "  Matcher::match_pairs (one device)       {single:8.3} s (min {lo:.3}, max {hi:.3})  {:7.1} us/pair",
        per_pair(single)
    );
    for workers in [1, 2, 4] {
        let pool = DevicePool::new(&vec![GPU; workers]).unwrap();
        let (wall, lo, hi, got) = timed(repeats, || pool.match_pairs(&config, &sets, &pairs));
        assert!(
            got == expected,
            "{workers} workers: results differ from one device"
        );
        println!(
            "  DevicePool, the GPU as {workers} worker(s)      {wall:8.3} s (min {lo:.3}, max {hi:.3})  {:7.1} \
             us/pair  pool / one device = {:.3}  (identical: yes)",
            per_pair(wall),
            wall / single
        );
    }
    drop(expected);

    // Extraction: synthetic 1080p frames.
    let (w, h) = (1920, 1080);
    let pixels: Vec<Vec<u8>> = (0..image_count)
        .map(|i| clatch::synthetic::rectangles(w, h, 100 + i as u64).unwrap())
        .collect();
    let images: Vec<GrayView> = pixels
        .iter()
        .map(|p| GrayView::new(p, w, h, w).unwrap())
        .collect();
    let config = ExtractorConfig::default();
    let extractor = Extractor::new(GPU, config.clone()).unwrap();
    let (single, lo, hi, expected) =
        timed(repeats, || extractor.detect_and_describe_batch(&images));
    let keypoints: usize = expected.iter().map(|f| f.keypoints.len()).sum();
    let per_image = |s: f64| s * 1e3 / image_count as f64;
    println!(
        "extract {image_count} synthetic {w}x{h} images (default configuration, {} keypoints each on \
         average), median of {repeats}:",
        keypoints / image_count.max(1)
    );
    println!(
        "  Extractor::detect_and_describe_batch    {:8.1} ms (min {:.1}, max {:.1})  {:7.3} ms/image",
        single * 1e3,
        lo * 1e3,
        hi * 1e3,
        per_image(single)
    );
    for workers in [1, 2, 4] {
        let pool = DevicePool::new(&vec![GPU; workers]).unwrap();
        let (wall, lo, hi, got) =
            timed(repeats, || pool.detect_and_describe_batch(&config, &images));
        assert!(
            got == expected,
            "{workers} workers: features differ from one device"
        );
        println!(
            "  DevicePool, the GPU as {workers} worker(s)      {:8.1} ms (min {:.1}, max {:.1})  {:7.3} \
             ms/image  pool / one device = {:.3}  (identical: yes)",
            wall * 1e3,
            lo * 1e3,
            hi * 1e3,
            per_image(wall),
            wall / single
        );
    }
}
