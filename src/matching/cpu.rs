//! The reference matcher (see the parent module for the contract).

use crate::parallel::*;

use super::{KnnMatches, Match, MatchConfig};
use crate::descriptor::{DescriptorSet, hamming};

/// Inserts `(distance, train)` into a list sorted by distance, keeping at most `k` entries. Candidates
/// arrive in increasing train order, so a strict comparison keeps the lowest index among equals.
#[inline]
fn insert_neighbour(best: &mut Vec<Match>, k: usize, candidate: Match) {
    if best.len() == k && candidate.distance >= best[k - 1].distance {
        return;
    }
    let at = best.partition_point(|m| m.distance <= candidate.distance);
    if best.len() == k {
        best.pop();
    }
    best.insert(at, candidate);
}

/// The `k` nearest gallery descriptors of every query (validated: same width, `1 <= k <= train.len()`).
pub fn knn(query: &DescriptorSet, train: &DescriptorSet, k: usize) -> KnnMatches {
    let popcnt = has_popcnt();
    let matches = query
        .rows()
        .collect::<Vec<_>>()
        .par_iter()
        .enumerate()
        .flat_map_iter(|(q, qd)| {
            if popcnt {
                // SAFETY: the CPU has the POPCNT instruction (checked at run time just above).
                #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
                return unsafe { neighbours_popcnt(q as u32, qd, train, k) };
            }
            neighbours(q as u32, qd, train, k)
        })
        .collect();
    KnnMatches::from_parts(k, matches)
}

/// Whether `count_ones` can be the POPCNT instruction: the baseline x86-64 target lacks it, and its
/// bit-twiddling replacement made this loop about twice as slow.
fn has_popcnt() -> bool {
    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
    return std::arch::is_x86_feature_detected!("popcnt");
    #[cfg(not(all(target_arch = "x86_64", feature = "cpu")))]
    false
}

/// The `k` nearest gallery rows of query `q`, scanned in increasing train index.
#[inline(always)]
fn neighbours(q: u32, qd: &[u64], train: &DescriptorSet, k: usize) -> Vec<Match> {
    let mut best = Vec::with_capacity(k + 1);
    for (t, td) in train.rows().enumerate() {
        let candidate = Match {
            query: q,
            train: t as u32,
            distance: hamming(qd, td),
        };
        insert_neighbour(&mut best, k, candidate);
    }
    best
}

/// [`neighbours`] compiled with POPCNT (the same integers, so the same result).
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
#[target_feature(enable = "popcnt")]
fn neighbours_popcnt(q: u32, qd: &[u64], train: &DescriptorSet, k: usize) -> Vec<Match> {
    neighbours(q, qd, train, k)
}

/// The nearest query of every gallery descriptor (lowest query index on ties).
fn nearest_query_of_each_train(query: &DescriptorSet, train: &DescriptorSet) -> Vec<u32> {
    knn(train, query, 1)
        .matches
        .iter()
        .map(|m| m.train)
        .collect()
}

/// Applies ratio test, cross-check and distance limit (validated configuration).
pub fn match_descriptors(
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Vec<Match> {
    let k = if config.ratio.is_some() { 2 } else { 1 };
    let neighbours = knn(query, train, k);
    let reverse = config
        .cross_check
        .then(|| nearest_query_of_each_train(query, train));
    neighbours
        .iter()
        .filter_map(|n| {
            let best = n[0];
            if let Some(ratio) = config.ratio {
                // One correctly rounded f32 product, so every backend decides alike.
                if best.distance as f32 >= ratio * n[1].distance as f32 {
                    return None;
                }
            }
            if let Some(reverse) = &reverse
                && reverse[best.train as usize] != best.query
            {
                return None;
            }
            if config.max_distance.is_some_and(|max| best.distance > max) {
                return None;
            }
            Some(best)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::descriptor::DescriptorWidth;

    fn set(rows: &[u64]) -> DescriptorSet {
        DescriptorSet::from_words(DescriptorWidth::from_bits(64).unwrap(), rows.to_vec()).unwrap()
    }

    #[test]
    fn ties_go_to_the_lowest_train_index() {
        // Distances from query 0: 2, 1, 1, 1. The three nearest are the three ones, in train order;
        // with k = 2 the third one-bit neighbour (train 3) loses to the lower indices.
        let train = set(&[0b11, 0b01, 0b10, 0b100]);
        let query = set(&[0]);
        let pairs = |k| -> Vec<(u32, u32)> {
            knn(&query, &train, k)
                .matches
                .iter()
                .map(|m| (m.train, m.distance))
                .collect()
        };
        assert_eq!(pairs(3), vec![(1, 1), (2, 1), (3, 1)]);
        assert_eq!(pairs(2), vec![(1, 1), (2, 1)]);
        assert_eq!(pairs(4), vec![(1, 1), (2, 1), (3, 1), (0, 2)]);
    }

    #[test]
    fn ratio_test_is_strict_and_exact() {
        let train = set(&[0b1111, 0b11111]); // distances 4 and 5 from 0
        let query = set(&[0]);
        let cfg = |ratio| MatchConfig {
            ratio: Some(ratio),
            cross_check: false,
            max_distance: None,
        };
        assert!(
            match_descriptors(&query, &train, &cfg(0.8)).is_empty(),
            "0.8f32 * 5 rounds to exactly 4.0, and 4 < 4 is false"
        );
        assert_eq!(match_descriptors(&query, &train, &cfg(0.81)).len(), 1);
    }

    #[test]
    fn cross_check_and_max_distance() {
        // Query 1 (0b111) is nearer to train 0 (0b110) than query 0 is, so query 0 loses its match.
        let train = set(&[0b110, u64::MAX]);
        let query = set(&[0b000, 0b111]);
        let plain = MatchConfig {
            ratio: None,
            cross_check: false,
            max_distance: None,
        };
        assert_eq!(match_descriptors(&query, &train, &plain).len(), 2);
        let checked = MatchConfig {
            cross_check: true,
            ..plain.clone()
        };
        let kept = match_descriptors(&query, &train, &checked);
        assert_eq!(
            kept,
            vec![Match {
                query: 1,
                train: 0,
                distance: 1
            }]
        );
        let near = MatchConfig {
            max_distance: Some(1),
            ..plain
        };
        assert_eq!(
            match_descriptors(&query, &train, &near),
            vec![Match {
                query: 1,
                train: 0,
                distance: 1
            }]
        );
    }
}
