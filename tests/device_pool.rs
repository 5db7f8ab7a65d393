//! `DevicePool` with CPU workers standing in for devices: any number of workers and any tile give
//! exactly what one `Matcher::match_pairs` or `Extractor::detect_and_describe_batch` gives, in the
//! same order; every pair or image is reported once; bad input is refused before any work.

mod common;

use std::sync::Mutex;

use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorSet, DescriptorWidth, DevicePool, Error, Extractor, ExtractorConfig,
    MatchConfig, Matcher,
};
use common::{match_configs, random_set, scrambled_collection};

const WORKER_COUNTS: [usize; 4] = [1, 2, 3, 4];

/// A collection of `bits`-wide sets, an empty one and single-descriptor ones among them (too small a
/// gallery for the ratio test), with every pair both ways, each set with itself and repeats, in
/// scrambled order.
fn collection(bits: usize, seed: u64) -> (Vec<DescriptorSet>, Vec<(usize, usize)>) {
    let sizes = [300, 0, 1, 257, 64, 1000, 2, 450, 1];
    scrambled_collection(bits, &sizes, 20, &mut SplitMix64::new(seed))
}

/// How many times `done` named each index, from any thread.
struct Reported(Mutex<Vec<usize>>);

impl Reported {
    fn new(n: usize) -> Self {
        Self(Mutex::new(vec![0; n]))
    }

    fn record(&self, i: usize) {
        self.0.lock().unwrap()[i] += 1;
    }

    fn counts(self) -> Vec<usize> {
        self.0.into_inner().unwrap()
    }
}

#[test]
fn pairs_equal_one_device_for_every_worker_count_and_tile() {
    // 64-bit sets, and 16-bit ones where equal distances (ties) are everywhere.
    for (bits, seed) in [(64, 1), (16, 2)] {
        let (owned, pairs) = collection(bits, seed);
        let sets: Vec<&DescriptorSet> = owned.iter().collect();
        for config in match_configs().into_iter().step_by(5) {
            let matcher = Matcher::new(Backend::Cpu, config.clone()).unwrap();
            let expected = matcher.match_pairs(&sets, &pairs).unwrap();
            let found: usize = expected.iter().map(Vec::len).sum();
            assert!(found > 1000, "{bits} bits, {config:?}: {found} matches");
            for workers in WORKER_COUNTS {
                for tile in [1, 2, 3, 4, pairs.len() + 1] {
                    let pool = DevicePool::new(&vec![Backend::Cpu; workers])
                        .unwrap()
                        .with_tile(tile)
                        .unwrap();
                    let reported = Reported::new(pairs.len());
                    let got = pool
                        .match_pairs_with_progress(&config, &sets, &pairs, &|p| reported.record(p))
                        .unwrap();
                    let what = format!("{bits} bits, {config:?}, {workers} workers, tile {tile}");
                    assert_eq!(
                        reported.counts(),
                        vec![1; pairs.len()],
                        "{what}: each pair once"
                    );
                    assert_eq!(got.len(), expected.len(), "{what}");
                    for (p, (g, e)) in got.iter().zip(&expected).enumerate() {
                        assert_eq!(g, e, "{what}: pair {p} {:?}", pairs[p]);
                    }
                }
            }
        }
    }
}

#[test]
fn all_pairs_equal_one_device() {
    let (owned, _) = collection(64, 3);
    let sets: Vec<&DescriptorSet> = owned.iter().collect();
    let config = MatchConfig::default();
    let expected = Matcher::new(Backend::Cpu, config.clone())
        .unwrap()
        .match_pairs(&sets, &Matcher::all_pairs(sets.len()))
        .unwrap();
    for workers in WORKER_COUNTS {
        let pool = DevicePool::new(&vec![Backend::Cpu; workers]).unwrap();
        assert_eq!(pool.tile(), DevicePool::DEFAULT_TILE);
        assert_eq!(pool.workers().len(), workers);
        let reported = Reported::new(expected.len());
        let got = pool
            .match_pairs_with_progress(&config, &sets, &Matcher::all_pairs(sets.len()), &|p| {
                reported.record(p)
            })
            .unwrap();
        assert_eq!(got, expected, "{workers} workers");
        assert_eq!(reported.counts(), vec![1; expected.len()]);
    }
    let pool = DevicePool::new(&[Backend::Cpu; 2]).unwrap();
    assert!(pool.match_all_pairs(&config, &[]).unwrap().is_empty());
    assert!(
        pool.match_all_pairs(&config, &sets[..1])
            .unwrap()
            .is_empty()
    );
}

#[test]
fn a_batch_equals_one_device_for_every_worker_count() {
    let photo = common::astronaut();
    let images: Vec<common::Gray> = vec![
        photo.clone(),
        common::rectangles(300, 200, 9),
        common::Gray::new(vec![128u8; 100 * 100], 100, 100),
        common::rectangles(640, 480, 10),
        photo,
        common::rectangles(64, 64, 11),
    ];
    let views: Vec<clatch::GrayView> = images.iter().map(common::Gray::view).collect();
    for config in [ExtractorConfig::default(), ExtractorConfig::single_scale()] {
        let extractor = Extractor::new(Backend::Cpu, config.clone()).unwrap();
        let expected = extractor.detect_and_describe_batch(&views).unwrap();
        assert!(expected[0].keypoints.len() > 100 && expected[2].keypoints.is_empty());
        for workers in WORKER_COUNTS {
            let pool = DevicePool::new(&vec![Backend::Cpu; workers]).unwrap();
            let reported = Reported::new(views.len());
            let got = pool
                .detect_and_describe_batch_with_progress(&config, &views, &|i| reported.record(i))
                .unwrap();
            assert_eq!(reported.counts(), vec![1; views.len()], "{workers} workers");
            assert_eq!(got, expected, "{workers} workers, {config:?}");
        }
    }
    let pool = DevicePool::new(&[Backend::Cpu; 3]).unwrap();
    let none = pool
        .detect_and_describe_batch(&ExtractorConfig::default(), &[])
        .unwrap();
    assert!(none.is_empty());
}

#[test]
fn bad_pools_and_bad_input_are_refused_before_any_work() {
    assert_eq!(DevicePool::new(&[]), Err(Error::NoWorkers));
    // No build has 4097 CUDA devices; without the `cuda` feature none at all.
    let absent = Backend::Cuda { device: 4096 };
    match DevicePool::new(&[Backend::Cpu, absent]) {
        Err(
            ref error @ Error::Worker {
                worker: 1,
                ref backend,
                ref source,
            },
        ) => {
            assert_eq!(backend, "cuda:4096");
            assert!(
                matches!(**source, Error::BackendUnavailable { .. }),
                "{source}"
            );
            let message = error.to_string();
            assert!(
                message.contains("worker 1") && message.contains("cuda:4096"),
                "{message}"
            );
            let source = std::error::Error::source(error).expect("the worker's error");
            assert!(source.to_string().contains("unavailable"), "{source}");
        }
        other => panic!("{other:?}"),
    }
    let pool = DevicePool::new(&[Backend::Cpu; 2]).unwrap();
    assert!(matches!(
        pool.clone().with_tile(0),
        Err(Error::InvalidConfig { field: "tile", .. })
    ));

    let (owned, _) = collection(64, 4);
    let sets: Vec<&DescriptorSet> = owned.iter().collect();
    let config = MatchConfig::default();
    let called = Mutex::new(0);
    let count = |_| *called.lock().unwrap() += 1;
    assert_eq!(
        pool.match_pairs_with_progress(&config, &sets, &[(0, 1), (2, 9), (3, 3)], &count),
        Err(Error::PairOutOfRange {
            pair: 1,
            index: 9,
            sets: 9
        })
    );
    assert!(matches!(
        pool.match_pairs_with_progress(&config, &sets, &[(12, 0)], &count),
        Err(Error::PairOutOfRange {
            pair: 0,
            index: 12,
            ..
        })
    ));
    let narrow = random_set(
        DescriptorWidth::from_bits(8).unwrap(),
        10,
        &mut SplitMix64::new(5),
    );
    assert!(matches!(
        pool.match_pairs_with_progress(&config, &[sets[0], &narrow], &[(0, 0)], &count),
        Err(Error::DescriptorWidthMismatch { .. })
    ));
    let bad_ratio = MatchConfig::default().with_ratio(Some(1.5));
    assert!(matches!(
        pool.match_pairs_with_progress(&bad_ratio, &sets, &[(0, 1)], &count),
        Err(Error::InvalidConfig { field: "ratio", .. })
    ));
    assert_eq!(
        pool.match_pairs_with_progress(&config, &sets, &[], &count),
        Ok(vec![])
    );

    let photo = common::astronaut();
    let tiny = common::Gray::new(vec![0u8; 10 * 10], 10, 10);
    let images = [photo.view(), tiny.view(), photo.view()];
    assert!(matches!(
        pool.detect_and_describe_batch_with_progress(&ExtractorConfig::default(), &images, &count),
        Err(Error::ImageTooSmall { .. })
    ));
    let bad_pyramid = ExtractorConfig::default().with_pyramid(Some(clatch::Pyramid::new(0, 1.2)));
    assert!(matches!(
        pool.detect_and_describe_batch_with_progress(&bad_pyramid, &images[..1], &count),
        Err(Error::InvalidConfig { .. })
    ));
    assert_eq!(*called.lock().unwrap(), 0, "no work before the checks");
}
