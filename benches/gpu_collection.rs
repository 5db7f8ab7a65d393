//! Exhaustive matching of a collection on the GPU: `cargo bench --features cuda --bench gpu_collection`.
//!
//! 1000 sets of 5000 (and of 2000) random 512-bit descriptors in a device-resident
//! `DescriptorCollection` (uploaded once), every pair `(a, b)`, `a < b` (499,500 pairs), ratio 0.8 and
//! cross-check (the default configuration), through `DescriptorCollection::match_all_pairs`; each
//! pair's matches are counted and dropped as they come back. Wall time of the whole call (the upload
//! apart), median of the repeats after a warm-up run on the first 100 sets; pairs per second and
//! descriptor pairs per second, against the rate of one 64k x 64k `match_descriptors` (same
//! configuration, device time, CUDA events) and of the 64k x 64k kNN kernels (k = 2) measured in the
//! same run. A few pairs are checked equal to the CPU's `match_descriptors`.
//! `tools/peers.py --collection` runs the PyTorch baseline of the same sizes (batched +-1 fp16 `bmm`,
//! `topk(2)` and a column max). `CLATCH_COLLECTION_SETS` (1000), `CLATCH_COLLECTION_DESCRIPTORS`
//! (`5000,2000`) and `CLATCH_COLLECTION_REPEATS` (3) override the sizes. Built only with the `cuda`
//! feature; without a device it prints `skipped`.

mod common;

use std::time::Instant;

use clatch::cuda::hooks::MatchKernel;
use clatch::synthetic::SplitMix64;
use clatch::{Backend, DescriptorCollection, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};

const GPU: Backend = Backend::Cuda { device: 0 };

fn setting(name: &str, default: &str) -> String {
    std::env::var(name).unwrap_or_else(|_| default.to_string())
}

fn random_set(n: usize, rng: &mut SplitMix64) -> DescriptorSet {
    let w = DescriptorWidth::FULL;
    DescriptorSet::from_words(w, (0..n * w.words()).map(|_| rng.next_u64()).collect())
        .expect("whole rows")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let sets: usize = setting("CLATCH_COLLECTION_SETS", "1000")
        .parse()
        .expect("a count");
    let sizes: Vec<usize> = setting("CLATCH_COLLECTION_DESCRIPTORS", "5000,2000")
        .split(',')
        .map(|s| s.trim().parse().expect("a size"))
        .collect();
    let repeats: usize = setting("CLATCH_COLLECTION_REPEATS", "3")
        .parse::<usize>()
        .expect("a count")
        .max(1);
    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    let config = MatchConfig::default();

    // The single-pair rates at 64k x 64k, in this run: the reference the grouped path is read against.
    let mut rng = SplitMix64::new(2024);
    let big = 1 << 16;
    let (query, train) = (random_set(big, &mut rng), random_set(big, &mut rng));
    let families: Vec<MatchKernel> = if dev.has_tensor_matcher() {
        vec![MatchKernel::Popcount, MatchKernel::Tensor]
    } else {
        vec![MatchKernel::Popcount]
    };
    let mut reference = 0.0f64;
    for &family in &families {
        let ms = |times: Vec<f32>| median(times.into_iter().map(f64::from).collect());
        let knn =
            ms(
                clatch::cuda::hooks::time_knn_kernel(&dev, &query, &train, 2, Some(family), (2, 7))
                    .expect("kNN kernel"),
            );
        let matched = ms(clatch::cuda::hooks::time_match_kernels(
            &dev,
            &query,
            &train,
            &config,
            Some(family),
            (2, 7),
        )
        .expect("match kernels"));
        let rate = |ms: f64| (big * big) as f64 / (ms * 1e-3) / 1e9;
        reference = reference.max(rate(matched));
        println!(
            "64k x 64k {:<8}: kNN k=2 {knn:8.3} ms {:6.1} G pairs/s; match_descriptors (ratio 0.8, cross-check) \
             {matched:8.3} ms {:6.1} G pairs/s",
            format!("{family:?}"),
            rate(knn),
            rate(matched)
        );
    }
    drop((query, train));

    let matcher = Matcher::new(GPU, config.clone()).expect("GPU matcher");
    let cpu = Matcher::new(Backend::Cpu, config).expect("CPU matcher");
    for &n in &sizes {
        let owned: Vec<DescriptorSet> = (0..sets).map(|_| random_set(n, &mut rng)).collect();
        let refs: Vec<&DescriptorSet> = owned.iter().collect();
        let t = Instant::now();
        let mut collection =
            DescriptorCollection::new(&matcher, DescriptorWidth::FULL).expect("collection");
        collection.add(&refs).expect("upload");
        let upload = t.elapsed().as_secs_f64();

        let warm: Vec<(usize, usize)> = Matcher::all_pairs(sets.min(100));
        collection
            .match_pairs_each(&warm, |_, _| {})
            .expect("warm-up run");
        let pairs = Matcher::all_pairs(sets);
        let checked = [0, pairs.len() / 2, pairs.len() - 1];
        let mut walls = Vec::new();
        let mut kept = 0usize;
        for _ in 0..repeats {
            kept = 0;
            let mut samples = Vec::new();
            let t = Instant::now();
            collection
                .match_all_pairs_each(|p, m| {
                    kept += m.len();
                    if checked.contains(&p) {
                        samples.push((p, m));
                    }
                })
                .expect("exhaustive matching");
            walls.push(t.elapsed().as_secs_f64());
            for (p, m) in samples {
                let (a, b) = pairs[p];
                let want = cpu.match_descriptors(&owned[a], &owned[b]).expect("CPU");
                assert_eq!(m, want, "pair ({a}, {b}) differs from the CPU");
            }
        }
        let (lo, hi) = (
            walls.iter().copied().fold(f64::MAX, f64::min),
            walls.iter().copied().fold(0.0, f64::max),
        );
        let wall = median(walls);
        let descriptor_pairs = pairs.len() as f64 * (n * n) as f64;
        let rate = descriptor_pairs / wall / 1e9;
        println!(
            "exhaustive {sets} sets x {n} (512 bits, ratio 0.8, cross-check), {} pairs: median {wall:8.3} s \
             (min {lo:.3}, max {hi:.3}, {repeats} runs), {:9.0} pairs/s, {rate:6.1} G descriptor pairs/s = \
             {:5.1}% of the best 64k x 64k match_descriptors rate; upload {upload:.3} s; {kept} matches kept; \
             pairs {checked:?} equal to the CPU",
            pairs.len(),
            pairs.len() as f64 / wall,
            100.0 * rate / reference
        );
    }
}
