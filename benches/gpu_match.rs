//! GPU matching timings: `cargo bench --features cuda --bench gpu_match`.
//!
//! Brute-force kNN of random 512-bit descriptors, k = 2, N x N for N = 1k, 16k, 64k, 128k: kernel time
//! from CUDA events around the launches (kNN and, when the gallery is split, the merge), after warm-up;
//! the median of the repeats, descriptor pairs per second, and the fraction of a POPC bound read off the
//! device (SMs x SM clock x 16 POPC per SM and clock on Hopper; 8 popcounts of 64 bits per 512-bit pair,
//! as the CLATCH paper counts; a 64-bit popcount is two 32-bit POPC instructions in SASS, so the bound of
//! the plain instruction count is half that). Then the device time of `match_descriptors` (kNN, fused
//! reverse 1-NN for the cross-check, filter, compaction), the kernel alternatives of
//! kernels/bench_knn_variants.cu, and the end-to-end `Matcher::match_descriptors` wall time (uploads
//! included).

#[cfg(feature = "cuda")]
mod common;

#[cfg(not(feature = "cuda"))]
fn main() {
    println!("skipped: no CUDA device (built without the `cuda` feature)");
}

#[cfg(feature = "cuda")]
fn main() {
    use std::time::Instant;

    use clatch::cuda::hooks::MatchKernel;
    use clatch::synthetic::SplitMix64;
    use clatch::{Backend, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};

    const REPEATS: usize = 15;
    const WARMUP: usize = 3;

    let start = Instant::now();
    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!(
        "device: {} (context and kernel modules loaded in {:.0} ms)",
        dev.name(),
        start.elapsed().as_secs_f64() * 1e3
    );
    let (sms, clock_khz) =
        clatch::cuda::hooks::multiprocessors_and_clock_khz(&dev).expect("attributes");
    let popc_per_s = sms as f64 * clock_khz as f64 * 1e3 * 16.0;
    let bound = popc_per_s / 8.0;
    println!(
        "POPC bound: {sms} SMs x {:.0} MHz x 16 POPC/SM/clock / 8 per pair = {:.1} G pairs/s \
         ({:.1} G pairs/s at 16 32-bit POPC per pair)",
        clock_khz as f64 / 1e3,
        bound / 1e9,
        bound / 2e9
    );
    // Dense int8 tensor throughput per SM and clock on Hopper: 1979 dense INT8 TOPS for the H100 SXM
    // (NVIDIA H100 datasheet) over 132 SMs at 1.83 GHz = 8192 operations = 4096 multiply-adds; a
    // 512-bit pair is 512 multiply-adds of +-1 bytes.
    let tensor_bound = sms as f64 * clock_khz as f64 * 1e3 * 4096.0 / 512.0;
    println!(
        "tensor bound: {sms} SMs x {:.0} MHz x 4096 int8 MAC/SM/clock / 512 per pair = {:.1} G pairs/s",
        clock_khz as f64 / 1e3,
        tensor_bound / 1e9
    );
    if dev.has_tensor_matcher() {
        for blocks_per_sm in [4, 1] {
            let rate =
                clatch::cuda::hooks::measure_mma_s8_rate(&dev, blocks_per_sm).expect("mma rate");
            println!(
                "int8 mma.sync measured, {} warps per SM: {:.1} T multiply-adds/s = {:.1} G pairs/s at 512 per \
                 pair ({:.0}% of the dense tensor figure above)",
                8 * blocks_per_sm,
                rate / 1e12,
                rate / 512.0 / 1e9,
                100.0 * rate / 512.0 / tensor_bound
            );
        }
    }
    let families: Vec<MatchKernel> = if dev.has_tensor_matcher() {
        vec![MatchKernel::Popcount, MatchKernel::Tensor]
    } else {
        vec![MatchKernel::Popcount]
    };
    let median = |mut v: Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2] as f64
    };
    let random_set = |n: usize, rng: &mut SplitMix64| {
        let w = DescriptorWidth::FULL;
        DescriptorSet::from_words(w, (0..n * w.words()).map(|_| rng.next_u64()).collect()).unwrap()
    };
    let mut rng = SplitMix64::new(2024);
    let mut sets = Vec::new();
    for n in [1usize << 10, 1 << 14, 1 << 16, 1 << 17] {
        let (query, train) = (random_set(n, &mut rng), random_set(n, &mut rng));
        for &family in &families {
            let times = clatch::cuda::hooks::time_knn_kernel(
                &dev,
                &query,
                &train,
                2,
                Some(family),
                (WARMUP, REPEATS),
            )
            .expect("kNN kernel");
            let (lo, hi) = (
                times.iter().copied().fold(f32::MAX, f32::min),
                times.iter().copied().fold(0.0, f32::max),
            );
            let ms = median(times);
            let rate = (n * n) as f64 / (ms * 1e-3);
            let (fraction, of) = match family {
                MatchKernel::Popcount => (rate / bound, "POPC"),
                MatchKernel::Tensor => (rate / tensor_bound, "tensor"),
            };
            println!(
                "knn k=2 512 bits {n:>6} x {n:<6} {:<8}: median {ms:9.3} ms (min {lo:.3}, max {hi:.3}, \
                 {REPEATS} runs)  {:7.1} G pairs/s  {:5.1}% of the {of} bound",
                format!("{family:?}"),
                rate / 1e9,
                100.0 * fraction
            );
        }
        sets.push((n, query, train));
    }

    for (n, query, train) in &sets {
        for (name, config) in [
            ("ratio 0.8, cross-check", MatchConfig::default()),
            (
                "ratio 0.8, no cross-check",
                MatchConfig::default().with_cross_check(false),
            ),
        ] {
            for &family in &families {
                let times = clatch::cuda::hooks::time_match_kernels(
                    &dev,
                    query,
                    train,
                    &config,
                    Some(family),
                    (WARMUP, REPEATS),
                )
                .expect("match kernels");
                let ms = median(times);
                println!(
                    "match_descriptors device time, {name:<25} {n:>6} x {n:<6} {:<8}: median {ms:9.3} ms  \
                     {:7.1} G pairs/s",
                    format!("{family:?}"),
                    (n * n) as f64 / (ms * 1e-3) / 1e9
                );
            }
        }
    }

    for (n, query, train) in sets.iter().filter(|(n, ..)| [1 << 14, 1 << 16].contains(n)) {
        println!("kernel alternatives, {n} x {n} (all checked equal to the production kernel):");
        let variants = clatch::cuda::hooks::time_knn_variants(&dev, query, train, WARMUP, 10)
            .expect("kNN variants");
        for (name, times) in variants {
            let ms = median(times);
            println!(
                "  {name:<30} median {ms:9.3} ms  {:7.1} G pairs/s",
                (n * n) as f64 / (ms * 1e-3) / 1e9
            );
        }
    }

    let matcher = Matcher::new(Backend::Cuda { device: 0 }, MatchConfig::default()).unwrap();
    for (n, query, train) in sets.iter().filter(|(n, ..)| [1 << 14, 1 << 16].contains(n)) {
        let mut walls = Vec::new();
        let mut kept = 0;
        for _ in 0..7 {
            let t = Instant::now();
            kept = matcher.match_descriptors(query, train).unwrap().len();
            walls.push(t.elapsed().as_secs_f32() * 1e3);
        }
        println!(
            "match_descriptors (ratio 0.8, cross-check) {n} x {n}, end to end: median {:.3} ms, {kept} kept",
            median(walls)
        );
    }
    // Collections: every pair of `sets` feature sets, through one match_descriptors call per
    // pair (blocking) and through Matcher::match_pairs (the library's streams, pairs in flight), with
    // the CPU backend's match_pairs beside them; wall clock of the whole call, after one warm-up run.
    for (n, count) in [(2000usize, 40usize), (5000, 24)] {
        let width = DescriptorWidth::from_bits(512).unwrap();
        let mut rng = SplitMix64::new(n as u64);
        let owned: Vec<DescriptorSet> = (0..count)
            .map(|_| {
                let words = (0..n * width.words()).map(|_| rng.next_u64()).collect();
                DescriptorSet::from_words(width, words).unwrap()
            })
            .collect();
        let sets: Vec<&DescriptorSet> = owned.iter().collect();
        let pairs = Matcher::all_pairs(count);
        let gpu = Matcher::new(Backend::Cuda { device: 0 }, MatchConfig::default()).unwrap();
        let cpu = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
        let time = |f: &mut dyn FnMut() -> Vec<Vec<clatch::Match>>| {
            f();
            let t = Instant::now();
            let result = f();
            (t.elapsed().as_secs_f64(), result)
        };
        let (one_by_one, expected) = time(&mut || {
            pairs
                .iter()
                .map(|&(a, b)| gpu.match_descriptors(sets[a], sets[b]).unwrap())
                .collect()
        });
        let (batched, got) = time(&mut || gpu.match_pairs(&sets, &pairs).unwrap());
        assert_eq!(got, expected, "match_pairs equals the per-pair calls");
        let (on_cpu, cpu_result) = time(&mut || cpu.match_pairs(&sets, &pairs).unwrap());
        assert_eq!(cpu_result, expected, "the CPU backend agrees");
        let per_pair = |s: f64| s * 1e6 / pairs.len() as f64;
        println!(
            "collection of {count} sets of {n} (512 bits), {} pairs, ratio 0.8 + cross-check: \
             per-pair calls {:.1} us/pair, match_pairs {:.1} us/pair ({:.2}x), CPU match_pairs ({} threads) \
             {:.1} us/pair",
            pairs.len(),
            per_pair(one_by_one),
            per_pair(batched),
            one_by_one / batched,
            rayon::current_num_threads(),
            per_pair(on_cpu)
        );
    }
}
