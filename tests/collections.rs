//! Collections in one call: `Matcher::match_pairs` equals one `match_descriptors` call per pair, and
//! `Extractor::detect_and_describe_batch` one `detect_and_describe` call per image.

mod common;

use std::sync::Mutex;

use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorSet, DescriptorWidth, Error, Extractor, ExtractorConfig, MatchConfig,
    Matcher,
};
use common::random_set;

fn sets(rng: &mut SplitMix64) -> Vec<DescriptorSet> {
    let width = DescriptorWidth::from_bits(64).unwrap();
    // Sizes include an empty set and a single descriptor (too small a gallery for the ratio test).
    [300, 0, 1, 257, 64, 1000]
        .iter()
        .map(|&n| random_set(width, n, rng))
        .collect()
}

#[test]
fn every_pair_equals_its_own_call() {
    let mut rng = SplitMix64::new(3);
    let owned = sets(&mut rng);
    let sets: Vec<&DescriptorSet> = owned.iter().collect();
    let mut pairs = Matcher::all_pairs(sets.len());
    pairs.extend([(3, 3), (5, 0), (0, 5)]);
    for config in [
        MatchConfig::default(),
        MatchConfig::default()
            .with_ratio(None)
            .with_cross_check(false)
            .with_max_distance(Some(20)),
    ] {
        let matcher = Matcher::new(Backend::Cpu, config.clone()).unwrap();
        let finished = Mutex::new(Vec::new());
        let all = matcher
            .match_pairs_with_progress(&sets, &pairs, &|p| finished.lock().unwrap().push(p))
            .unwrap();
        assert_eq!(all.len(), pairs.len());
        let mut finished = finished.into_inner().unwrap();
        finished.sort_unstable();
        assert_eq!(
            finished,
            (0..pairs.len()).collect::<Vec<_>>(),
            "each pair once"
        );
        let needed = if config.ratio.is_some() { 2 } else { 1 };
        let mut nonempty = 0;
        for (&(a, b), got) in pairs.iter().zip(&all) {
            if sets[a].is_empty() || sets[b].len() < needed {
                assert!(got.is_empty(), "({a}, {b})");
                continue;
            }
            assert_eq!(
                got,
                &matcher.match_descriptors(sets[a], sets[b]).unwrap(),
                "({a}, {b})"
            );
            nonempty += usize::from(!got.is_empty());
        }
        assert!(nonempty > 5, "{config:?}: matching found something");
    }
}

#[test]
fn bad_pairs_are_refused_before_any_work() {
    let mut rng = SplitMix64::new(4);
    let owned = sets(&mut rng);
    let sets: Vec<&DescriptorSet> = owned.iter().collect();
    let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
    let called = Mutex::new(0);
    let result = matcher
        .match_pairs_with_progress(&sets, &[(0, 1), (2, 6)], &|_| *called.lock().unwrap() += 1);
    assert!(
        matches!(
            result,
            Err(Error::PairOutOfRange {
                pair: 1,
                index: 6,
                sets: 6
            })
        ),
        "{result:?}"
    );
    assert_eq!(*called.lock().unwrap(), 0);
    let narrow = random_set(DescriptorWidth::from_bits(8).unwrap(), 10, &mut rng);
    let mixed = [sets[0], &narrow];
    assert!(matches!(
        matcher.match_pairs(&mixed, &[(0, 0)]),
        Err(Error::DescriptorWidthMismatch { .. })
    ));
    assert_eq!(
        matcher.match_pairs(&sets, &[]).unwrap(),
        Vec::<Vec<_>>::new()
    );
    assert_eq!(Matcher::all_pairs(0), vec![]);
    assert_eq!(Matcher::all_pairs(4).len(), 6);
}

#[test]
fn a_batch_equals_one_call_per_image() {
    let photo = common::astronaut();
    let small = common::rectangles(300, 200, 9);
    let flat = vec![128u8; 100 * 100];
    let images = [
        photo.view(),
        small.view(),
        clatch::GrayView::new(&flat, 100, 100, 100).unwrap(),
        photo.view(),
    ];
    for config in [ExtractorConfig::default(), ExtractorConfig::single_scale()] {
        let extractor = Extractor::new(Backend::Cpu, config).unwrap();
        let finished = Mutex::new(Vec::new());
        let all = extractor
            .detect_and_describe_batch_with_progress(&images, &|i| finished.lock().unwrap().push(i))
            .unwrap();
        let mut finished = finished.into_inner().unwrap();
        finished.sort_unstable();
        assert_eq!(finished, vec![0, 1, 2, 3]);
        for (image, got) in images.iter().zip(&all) {
            assert_eq!(got, &extractor.detect_and_describe(image).unwrap());
        }
        assert!(all[0].keypoints.len() > 100 && all[2].keypoints.is_empty());
        assert_eq!(all[0], all[3]);
    }
    // A bad image anywhere is refused before any work.
    let tiny = vec![0u8; 10 * 10];
    let with_tiny = [
        photo.view(),
        clatch::GrayView::new(&tiny, 10, 10, 10).unwrap(),
    ];
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    let called = Mutex::new(0);
    assert!(matches!(
        extractor
            .detect_and_describe_batch_with_progress(&with_tiny, &|_| *called.lock().unwrap() += 1),
        Err(Error::ImageTooSmall { .. })
    ));
    assert_eq!(*called.lock().unwrap(), 0);
}
