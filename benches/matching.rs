//! Brute-force Hamming matching of random 512-bit descriptors: the k = 2 nearest neighbours at 1000x1000,
//! 4000x4000, 5000x5000 and 8000x8000, and `match_descriptors` with the default configuration (ratio test
//! and cross-check, one pass) at 5000x5000 and 8000x8000, the sizes of `clatch colmap`'s image pairs
//! (throughput in descriptor pairs compared per second, N·M). The `scalar` rows are the same calls by the
//! scalar reference code (POPCNT, no AVX-512: `matching::cpu::match_descriptors_scalar`), the named
//! baseline in the same run.
//!
//! `cargo bench --bench matching`

use std::hint::black_box;
use std::time::Duration;

use clatch::synthetic::SplitMix64;
use clatch::{Backend, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

fn random_set(count: usize, rng: &mut SplitMix64) -> DescriptorSet {
    let width = DescriptorWidth::FULL;
    let words = (0..count * width.words()).map(|_| rng.next_u64()).collect();
    DescriptorSet::from_words(width, words).unwrap()
}

fn matching(c: &mut Criterion) {
    let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
    let mut rng = SplitMix64::new(5);
    let mut group = c.benchmark_group("knn k=2, 512 bits");
    group
        .measurement_time(Duration::from_secs(5))
        .sample_size(10);
    for n in [1000, 4000, 5000, 8000] {
        let query = random_set(n, &mut rng);
        let train = random_set(n, &mut rng);
        group.throughput(Throughput::Elements((n * n) as u64));
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{n}x{n}")),
            &(query, train),
            |b, (query, train)| {
                b.iter(|| matcher.knn(black_box(query), black_box(train), 2).unwrap())
            },
        );
    }
    group.finish();
    let mut group = c.benchmark_group("match ratio 0.8 + cross-check, 512 bits");
    group
        .measurement_time(Duration::from_secs(5))
        .sample_size(10);
    for n in [5000, 8000] {
        let query = random_set(n, &mut rng);
        let train = random_set(n, &mut rng);
        let sets = (query, train);
        group.throughput(Throughput::Elements((n * n) as u64));
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{n}x{n}")),
            &sets,
            |b, (query, train)| {
                b.iter(|| {
                    matcher
                        .match_descriptors(black_box(query), black_box(train))
                        .unwrap()
                })
            },
        );
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{n}x{n} scalar")),
            &sets,
            |b, (query, train)| {
                b.iter(|| {
                    clatch::matching::cpu::match_descriptors_scalar(
                        black_box(query),
                        black_box(train),
                        &MatchConfig::default(),
                    )
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, matching);
criterion_main!(benches);
