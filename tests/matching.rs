//! The CPU matcher against naive O(N·M) references of the contract in `src/matching/mod.rs`, on random
//! descriptors with planted ties.

mod common;

use clatch::synthetic::SplitMix64;
use clatch::{Backend, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};
use common::reference::{naive_knn, naive_match, naive_match_sorted, naive_sorted};
use common::{flip_bits, match_configs, random_set};

const WIDTHS: [usize; 5] = [8, 64, 72, 256, 512];

fn cpu(config: MatchConfig) -> Matcher {
    Matcher::new(Backend::Cpu, config).unwrap()
}

/// A gallery with duplicated rows and near-duplicates, and queries that are (a) random, (b) copies of
/// duplicated gallery rows, (c) a few bits away from gallery rows, (d) equidistant to several rows.
fn tied_sets(
    bits: usize,
    n_query: usize,
    n_train: usize,
    seed: u64,
) -> (DescriptorSet, DescriptorSet) {
    let width = DescriptorWidth::from_bits(bits).unwrap();
    let per = width.words();
    let mut rng = SplitMix64::new(seed);
    let mask_row = |row: &mut [u64]| {
        if !bits.is_multiple_of(64) {
            row[per - 1] &= (1u64 << (bits % 64)) - 1;
        }
    };
    let base = random_set(width, n_train, &mut rng);
    let mut train: Vec<Vec<u64>> = base.rows().map(|r| r.to_vec()).collect();
    // Exact copies of earlier rows at later indices (and some earlier copies of later rows).
    for _ in 0..n_train / 4 {
        let from = rng.below(n_train as u64) as usize;
        let to = rng.below(n_train as u64) as usize;
        train[to] = train[from].clone();
    }
    // Rows at the same distance from a common centre: centre with 3 flipped bits, several times.
    let centre = train[0].clone();
    for _ in 0..n_train / 8 {
        let mut row = centre.clone();
        flip_bits(&mut row, bits, 3.min(bits), &mut rng);
        let at = rng.below(n_train as u64) as usize;
        train[at] = row;
    }
    let mut query: Vec<Vec<u64>> = Vec::new();
    for i in 0..n_query {
        let mut row = match i % 4 {
            0 => (0..per).map(|_| rng.next_u64()).collect(),
            1 => train[rng.below(n_train as u64) as usize].clone(),
            2 => {
                let mut r = train[rng.below(n_train as u64) as usize].clone();
                let flips = 1 + rng.below(4) as usize;
                flip_bits(&mut r, bits, flips, &mut rng);
                r
            }
            _ => centre.clone(), // equidistant (3 bits) to every planted row, 0 to train[0]'s copies
        };
        mask_row(&mut row);
        query.push(row);
    }
    let to_set = |rows: Vec<Vec<u64>>| DescriptorSet::from_words(width, rows.concat()).unwrap();
    (to_set(query), to_set(train))
}

/// Number of queries whose k-th and (k+1)-th nearest neighbours are at the same distance (so the tie
/// rule decides which train index is listed).
fn ties_at_cut(query: &DescriptorSet, train: &DescriptorSet, k: usize) -> usize {
    naive_sorted(query, train)
        .iter()
        .filter(|all| all.len() > k && all[k - 1].0 == all[k].0)
        .count()
}

#[test]
fn knn_equals_the_naive_reference() {
    let matcher = cpu(MatchConfig::default());
    for (i, &bits) in WIDTHS.iter().enumerate() {
        let (query, train) = tied_sets(bits, 120, 97, 100 + i as u64);
        for k in [1, 2, 3, 5] {
            let knn = matcher.knn(&query, &train, k).unwrap();
            assert_eq!(knn.k(), k);
            assert_eq!(knn.len(), query.len());
            let expected = naive_knn(&query, &train, k);
            assert_eq!(knn.as_slice(), expected, "bits {bits}, k {k}");
            for (q, neighbours) in knn.iter().enumerate() {
                assert_eq!(Some(neighbours), knn.neighbours(q));
            }
            // The test must exercise ties at the cut, or it proves nothing about the tie rule.
            assert!(
                ties_at_cut(&query, &train, k) >= 10,
                "bits {bits}, k {k}: only {} ties",
                ties_at_cut(&query, &train, k)
            );
        }
    }
}

#[test]
fn knn_on_plain_random_descriptors() {
    let matcher = cpu(MatchConfig::default());
    let mut rng = SplitMix64::new(7);
    for &bits in &WIDTHS {
        let width = DescriptorWidth::from_bits(bits).unwrap();
        let query = random_set(width, 50, &mut rng);
        let train = random_set(width, 300, &mut rng);
        for k in [1, 2, 3, 5] {
            assert_eq!(
                matcher.knn(&query, &train, k).unwrap().into_vec(),
                naive_knn(&query, &train, k),
                "bits {bits}, k {k}"
            );
        }
    }
}

#[test]
fn knn_with_k_equal_to_the_gallery_lists_everything_in_order() {
    let matcher = cpu(MatchConfig::default());
    for &bits in &WIDTHS {
        let (query, train) = tied_sets(bits, 20, 9, bits as u64);
        let knn = matcher.knn(&query, &train, 9).unwrap();
        assert_eq!(knn.as_slice(), naive_knn(&query, &train, 9), "bits {bits}");
    }
}

#[test]
fn knn_of_an_empty_query_set_is_empty() {
    let width = DescriptorWidth::from_bits(72).unwrap();
    let train = random_set(width, 5, &mut SplitMix64::new(1));
    let knn = cpu(MatchConfig::default())
        .knn(&DescriptorSet::empty(width), &train, 2)
        .unwrap();
    assert!(knn.is_empty());
    assert_eq!(knn.len(), 0);
    for config in match_configs() {
        assert!(
            cpu(config)
                .match_descriptors(&DescriptorSet::empty(width), &train)
                .unwrap()
                .is_empty()
        );
    }
}

#[test]
fn all_equal_gallery_gives_the_lowest_indices() {
    // Eight identical gallery rows: every query's k neighbours are train 0..k, whatever its distance.
    let width = DescriptorWidth::from_bits(256).unwrap();
    let mut rng = SplitMix64::new(3);
    let row = random_set(width, 1, &mut rng);
    let train = DescriptorSet::from_words(width, row.as_words().repeat(8)).unwrap();
    let query = random_set(width, 10, &mut rng);
    let knn = cpu(MatchConfig::default()).knn(&query, &train, 5).unwrap();
    for neighbours in knn.iter() {
        let trains: Vec<u32> = neighbours.iter().map(|m| m.train).collect();
        assert_eq!(trains, vec![0, 1, 2, 3, 4]);
        assert!(
            neighbours
                .iter()
                .all(|m| m.distance == neighbours[0].distance)
        );
    }
}

#[test]
fn match_descriptors_equals_the_naive_contract() {
    let mut rejected_by = [0usize; 3]; // how often each filter alone dropped something
    for (i, &bits) in WIDTHS.iter().enumerate() {
        let (query, train) = tied_sets(bits, 80, 61, 500 + i as u64);
        let (forward, backward) = (naive_sorted(&query, &train), naive_sorted(&train, &query));
        let naive = |ratio, cross_check, max_distance| {
            let config = MatchConfig::default()
                .with_ratio(ratio)
                .with_cross_check(cross_check)
                .with_max_distance(max_distance);
            naive_match_sorted(&forward, &backward, &config)
        };
        let all = naive(None, false, None).len();
        assert_eq!(all, query.len());
        for config in match_configs() {
            let got = cpu(config.clone())
                .match_descriptors(&query, &train)
                .unwrap();
            let expected = naive(config.ratio, config.cross_check, config.max_distance);
            assert_eq!(got, expected, "bits {bits}, {config:?}");
            rejected_by[0] += (naive(config.ratio, false, None).len() < all) as usize;
            rejected_by[1] += (naive(None, config.cross_check, None).len() < all) as usize;
            rejected_by[2] += (naive(None, false, config.max_distance).len() < all) as usize;
        }
    }
    assert!(
        rejected_by.iter().all(|&n| n > 0),
        "every filter must reject something somewhere: {rejected_by:?}"
    );
}

#[test]
fn match_descriptors_on_random_descriptors() {
    let mut rng = SplitMix64::new(99);
    for &bits in &WIDTHS {
        let width = DescriptorWidth::from_bits(bits).unwrap();
        let query = random_set(width, 70, &mut rng);
        let train = random_set(width, 90, &mut rng);
        for config in match_configs() {
            assert_eq!(
                cpu(config.clone())
                    .match_descriptors(&query, &train)
                    .unwrap(),
                naive_match(&query, &train, &config),
                "bits {bits}, {config:?}"
            );
        }
    }
}

#[test]
fn ratio_test_boundary_is_one_f32_product() {
    // d1 < ratio * d2 with exact f32 rounding: for every (d1, d2) with d1 <= d2 <= 64 and a few ratios.
    let width = DescriptorWidth::from_bits(64).unwrap();
    let ones = |n: u32| if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
    for ratio in [0.8f32, 0.75, 0.7, 0.9, 1.0, 0.3] {
        let config = MatchConfig::default()
            .with_ratio(Some(ratio))
            .with_cross_check(false)
            .with_max_distance(None);
        let matcher = cpu(config);
        let mut kept = 0;
        for d2 in 1..=64u32 {
            for d1 in 0..d2 {
                // Query 0; train rows with d1 and d2 low bits set: distances d1 and d2.
                let train = DescriptorSet::from_words(width, vec![ones(d1), ones(d2)]).unwrap();
                let query = DescriptorSet::from_words(width, vec![0]).unwrap();
                let got = matcher.match_descriptors(&query, &train).unwrap();
                let keep = (d1 as f32) < ratio * d2 as f32;
                assert_eq!(got.len(), keep as usize, "ratio {ratio}, d1 {d1}, d2 {d2}");
                kept += keep as usize;
            }
        }
        assert!(kept > 0);
    }
}
