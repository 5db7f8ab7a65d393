//! The reference matcher (see the parent module for the contract).
//!
//! [`scan`] and [`neighbours`] are the specification: every query against every gallery row in
//! increasing index, one insertion at a time. Where the CPU has AVX512F and AVX512-VPOPCNTDQ (checked at
//! run time) [`knn`] and [`knn_and_reverse`] take the [`avx512`] kernels instead, which give the same
//! results (tested against the scalar code over random sets with planted ties, every width and size);
//! elsewhere the scalar code, compiled with POPCNT where the CPU has it.

#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
mod avx512;

use crate::parallel::*;

use super::{KnnMatches, Match, MatchConfig};
use crate::descriptor::{DescriptorSet, hamming};

/// Inserts `(distance, train)` into a list sorted by distance, keeping at most `k` entries. Candidates
/// arrive in increasing train order, so a strict comparison keeps the lowest index among equals.
#[inline]
pub(crate) fn insert_neighbour(best: &mut Vec<Match>, k: usize, candidate: Match) {
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
    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
    if let Some(simd) = avx512::Avx512::detect() {
        return knn_avx512(simd, query, train, k, false).0;
    }
    knn_scalar(query, train, k)
}

/// [`knn`] by the scalar code, whatever the CPU has.
fn knn_scalar(query: &DescriptorSet, train: &DescriptorSet, k: usize) -> KnnMatches {
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

/// The nearest query of every gallery descriptor (lowest query index on ties), by the scalar code.
#[cfg(test)]
fn nearest_query_of_each_train(query: &DescriptorSet, train: &DescriptorSet) -> Vec<u32> {
    knn_scalar(train, query, 1)
        .matches
        .iter()
        .map(|m| m.train)
        .collect()
}

/// Queries per block of [`knn_and_reverse`]: each block keeps its own nearest query per gallery row.
const QUERY_BLOCK: usize = 64;

/// [`knn`] and, in the same pass over the distance matrix, the nearest query of every gallery row
/// (lowest query index on ties), as [`knn`] of the gallery against the queries would give it: each
/// distance is computed once instead of twice. Integer comparisons only, so the same result.
pub fn knn_and_reverse(
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
) -> (KnnMatches, Vec<u32>) {
    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
    if let Some(simd) = avx512::Avx512::detect() {
        let (matches, reverse) = knn_avx512(simd, query, train, k, true);
        return (matches, reverse.unwrap_or_default());
    }
    knn_and_reverse_scalar(query, train, k)
}

/// [`knn`] (and, with `reverse`, the nearest query of every gallery row) by the AVX-512 kernels, in the
/// query blocks of [`knn_and_reverse_scalar`].
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
fn knn_avx512(
    simd: avx512::Avx512,
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
    reverse: bool,
) -> (KnnMatches, Option<Vec<u32>>) {
    let gallery = avx512::Gallery::new(train);
    let padded = train.len().div_ceil(avx512::LANES) * avx512::LANES;
    let rows: Vec<&[u64]> = query.rows().collect();
    let blocks: Vec<(Vec<Match>, Vec<u64>)> = (0..rows.len().div_ceil(QUERY_BLOCK))
        .into_par_iter()
        .map(|b| {
            let first = b * QUERY_BLOCK;
            let block = &rows[first..(first + QUERY_BLOCK).min(rows.len())];
            let mut nearest = if reverse { vec![u64::MAX; padded] } else { Vec::new() };
            let mut matches = Vec::with_capacity(block.len() * k);
            let nearest_rows = reverse.then_some(nearest.as_mut_slice());
            simd.scan_block(first as u32, block, &gallery, k, nearest_rows, &mut matches);
            (matches, nearest)
        })
        .collect();
    let mut matches = Vec::with_capacity(rows.len() * k);
    let mut nearest = vec![u64::MAX; if reverse { padded } else { 0 }];
    for (block_matches, block_nearest) in blocks {
        matches.extend(block_matches);
        for (n, b) in nearest.iter_mut().zip(block_nearest) {
            *n = (*n).min(b);
        }
    }
    let reverse = reverse.then(|| nearest[..train.len()].iter().map(|&n| n as u32).collect());
    (KnnMatches::from_parts(k, matches), reverse)
}

/// [`knn_and_reverse`] by the scalar code, whatever the CPU has.
fn knn_and_reverse_scalar(
    query: &DescriptorSet,
    train: &DescriptorSet,
    k: usize,
) -> (KnnMatches, Vec<u32>) {
    let popcnt = has_popcnt();
    let rows: Vec<&[u64]> = query.rows().collect();
    let blocks: Vec<(Vec<Match>, Vec<u64>)> = (0..rows.len().div_ceil(QUERY_BLOCK))
        .into_par_iter()
        .map(|b| {
            // (distance << 32 | query): the smallest is the nearest, then the lowest query index.
            let mut nearest = vec![u64::MAX; train.len()];
            let mut matches = Vec::with_capacity(QUERY_BLOCK * k);
            let first = b * QUERY_BLOCK;
            let block = &rows[first..(first + QUERY_BLOCK).min(rows.len())];
            for (q, qd) in (first as u32..).zip(block) {
                if popcnt {
                    // SAFETY: the CPU has the POPCNT instruction (checked at run time above).
                    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
                    {
                        matches.extend(unsafe { scan_popcnt(q, qd, train, k, &mut nearest) });
                        continue;
                    }
                }
                matches.extend(scan(q, qd, train, k, &mut nearest));
            }
            (matches, nearest)
        })
        .collect();
    let mut nearest = vec![u64::MAX; train.len()];
    let mut matches = Vec::with_capacity(rows.len() * k);
    for (block_matches, block_nearest) in blocks {
        matches.extend(block_matches);
        for (n, b) in nearest.iter_mut().zip(block_nearest) {
            *n = (*n).min(b);
        }
    }
    let reverse = nearest.iter().map(|&n| n as u32).collect();
    (KnnMatches::from_parts(k, matches), reverse)
}

/// [`neighbours`] of query `q`, also lowering `nearest[t]` to `(distance << 32 | q)` where that is
/// smaller.
#[inline(always)]
fn scan(q: u32, qd: &[u64], train: &DescriptorSet, k: usize, nearest: &mut [u64]) -> Vec<Match> {
    let mut best = Vec::with_capacity(k + 1);
    for ((t, td), n) in train.rows().enumerate().zip(nearest.iter_mut()) {
        let distance = hamming(qd, td);
        *n = (*n).min((distance as u64) << 32 | q as u64);
        insert_neighbour(
            &mut best,
            k,
            Match {
                query: q,
                train: t as u32,
                distance,
            },
        );
    }
    best
}

/// [`scan`] compiled with POPCNT (the same integers, so the same result).
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
#[target_feature(enable = "popcnt")]
fn scan_popcnt(
    q: u32,
    qd: &[u64],
    train: &DescriptorSet,
    k: usize,
    nearest: &mut [u64],
) -> Vec<Match> {
    scan(q, qd, train, k, nearest)
}

/// Applies ratio test, cross-check and distance limit (validated configuration).
pub fn match_descriptors(
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Vec<Match> {
    match_with((knn, knn_and_reverse), query, train, config)
}

/// [`match_descriptors`] by the scalar code whatever the CPU has: the named baseline of the matching
/// bench (`benches/matching.rs`).
#[cfg(any(test, feature = "internals"))]
pub fn match_descriptors_scalar(
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Vec<Match> {
    match_with(
        (knn_scalar, knn_and_reverse_scalar),
        query,
        train,
        config,
    )
}

/// The kNN (and kNN with the reverse 1-NN) that [`match_with`] uses.
type KnnPaths = (
    fn(&DescriptorSet, &DescriptorSet, usize) -> KnnMatches,
    fn(&DescriptorSet, &DescriptorSet, usize) -> (KnnMatches, Vec<u32>),
);

/// [`match_descriptors`] with the given kNN paths.
fn match_with(
    (knn, knn_and_reverse): KnnPaths,
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Vec<Match> {
    let k = config.neighbours_needed();
    if config.cross_check {
        let (neighbours, reverse) = knn_and_reverse(query, train, k);
        select(&neighbours, Some(&reverse), config)
    } else {
        select(&knn(query, train, k), None, config)
    }
}

/// The best matches of `neighbours` that pass the rules of `config` (with `reverse`, the nearest query
/// of every gallery row, when it cross-checks).
fn select(neighbours: &KnnMatches, reverse: Option<&[u32]>, config: &MatchConfig) -> Vec<Match> {
    neighbours
        .iter()
        .filter_map(|n| {
            let best = n[0];
            let second = if config.ratio.is_some() { n[1].distance } else { 0 };
            let nearest_query = reverse.map(|reverse| reverse[best.train as usize]);
            passes(best, second, nearest_query, config).then_some(best)
        })
        .collect()
}

/// Whether the nearest neighbour `best` of its query passes the rules of `config`: the ratio test
/// against the second-nearest distance `second` (read only with a ratio), the cross-check against
/// `nearest_query`, the nearest query of `best.train` (`None`: no cross-check), the distance limit.
pub(crate) fn passes(
    best: Match,
    second: u32,
    nearest_query: Option<u32>,
    config: &MatchConfig,
) -> bool {
    if let Some(ratio) = config.ratio {
        // One correctly rounded f32 product, so every backend decides alike.
        if best.distance as f32 >= ratio * second as f32 {
            return false;
        }
    }
    if nearest_query.is_some_and(|nearest| nearest != best.query) {
        return false;
    }
    config.max_distance.is_none_or(|max| best.distance <= max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_pass_equals_the_two_directions() {
        // Narrow descriptors make equal distances (ties) common; sizes straddle the query block.
        let mut state = 5u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            state >> 11
        };
        for (bits, nq, nt) in [(8usize, 130, 70), (16, 64, 1), (64, 1, 40), (512, 200, 300), (8, 65, 129)] {
            let width = crate::DescriptorWidth::from_bits(bits).unwrap();
            let random = |n: usize, next: &mut dyn FnMut() -> u64| {
                let words: Vec<u64> = (0..n * width.words())
                    .map(|_| next() & if bits < 64 { (1u64 << bits) - 1 } else { u64::MAX })
                    .collect();
                DescriptorSet::from_words(width, words).unwrap()
            };
            let query = random(nq, &mut next);
            let train = random(nt, &mut next);
            for k in [1, 2.min(nt)] {
                let (neighbours, reverse) = knn_and_reverse_scalar(&query, &train, k);
                assert_eq!(neighbours, knn_scalar(&query, &train, k), "{bits} bits, {nq}x{nt}, k {k}");
                assert_eq!(reverse, nearest_query_of_each_train(&query, &train), "{bits} bits, {nq}x{nt}");
            }
        }
    }
    use crate::descriptor::DescriptorWidth;

    /// Random descriptors of `bits` bits with planted ties: a third of the rows are copies of earlier
    /// rows (equal distances to every query, so ties between gallery rows and, for the cross-check,
    /// between queries), some one bit away from a copy, placed across block (8) and tile (256) edges.
    fn planted(bits: usize, n: usize, pool: &[u64], rng: &mut crate::synthetic::SplitMix64) -> DescriptorSet {
        let width = DescriptorWidth::from_bits(bits).unwrap();
        let w = width.words();
        let tail = |i: usize| if bits.is_multiple_of(64) || i + 1 < w { u64::MAX } else { (1u64 << (bits % 64)) - 1 };
        let mut words = Vec::with_capacity(n * w);
        for i in 0..n {
            let r = rng.next_u64();
            let start = words.len();
            match r % 6 {
                // a copy of an earlier row of this set, or of a row of the pool (the other set)
                0 | 1 if i > 0 => {
                    let j = (r >> 8) as usize % i;
                    words.extend_from_within(j * w..(j + 1) * w);
                }
                2 if pool.len() >= w => {
                    let j = (r >> 8) as usize % (pool.len() / w);
                    words.extend_from_slice(&pool[j * w..(j + 1) * w]);
                }
                _ => words.extend((0..w).map(|i| rng.next_u64() & tail(i))),
            }
            if r.is_multiple_of(11) {
                // one bit away from what was written: distances differing by one near a tie
                let bit = (r >> 20) as usize % bits;
                words[start + bit / 64] ^= 1 << (bit % 64);
            }
        }
        DescriptorSet::from_words(width, words).unwrap()
    }

    /// The dispatched matcher (AVX-512 where the CPU has it) equals the scalar reference: neighbours,
    /// nearest queries and kept matches, over widths of every word count, sizes around the block, group,
    /// query-block and tile edges, several k, with planted ties.
    #[test]
    fn every_path_equals_the_scalar_reference() {
        #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
        eprintln!("AVX-512 kernels under test: {}", avx512::Avx512::detect().is_some());
        let mut rng = crate::synthetic::SplitMix64::new(9);
        let configs = [
            MatchConfig::default(),
            MatchConfig { ratio: None, cross_check: true, max_distance: None },
            MatchConfig { ratio: Some(0.9), cross_check: false, max_distance: Some(200) },
            MatchConfig { ratio: None, cross_check: false, max_distance: None },
        ];
        let sizes = [
            (1, 1), (1, 2), (3, 7), (4, 8), (5, 9), (63, 255), (64, 256), (65, 257), (130, 300),
            (7, 513), (200, 16), (9, 600),
        ];
        for bits in [8, 16, 64, 72, 128, 192, 256, 320, 384, 448, 504, 512] {
            for &(nq, nt) in &sizes {
                let train = planted(bits, nt, &[], &mut rng);
                let query = planted(bits, nq, train.as_words(), &mut rng);
                let at = format!("{bits} bits, {nq}x{nt}");
                for k in [1, 2, 3, 9].into_iter().filter(|&k| k <= nt) {
                    let expected = knn_scalar(&query, &train, k);
                    assert_eq!(knn(&query, &train, k), expected, "knn, {at}, k {k}");
                    let (neighbours, reverse) = knn_and_reverse(&query, &train, k);
                    assert_eq!(neighbours, expected, "knn_and_reverse, {at}, k {k}");
                    assert_eq!(reverse, nearest_query_of_each_train(&query, &train), "reverse, {at}");
                }
                for config in configs.iter().filter(|c| nt >= c.neighbours_needed()) {
                    let k = config.neighbours_needed();
                    let reverse = nearest_query_of_each_train(&query, &train);
                    let expected = select(
                        &knn_scalar(&query, &train, k),
                        config.cross_check.then_some(reverse.as_slice()),
                        config,
                    );
                    assert_eq!(match_descriptors(&query, &train, config), expected, "{at}, {config:?}");
                    assert_eq!(match_descriptors_scalar(&query, &train, config), expected, "{at}, {config:?}");
                }
            }
        }
    }

    #[test]
    fn planted_ties_reach_the_tie_rules() {
        // The test sets above must exercise ties: equal best and second distances, and gallery rows
        // whose nearest distance is shared by several queries.
        let mut rng = crate::synthetic::SplitMix64::new(9);
        let train = planted(512, 300, &[], &mut rng);
        let query = planted(512, 130, train.as_words(), &mut rng);
        let knn2 = knn_scalar(&query, &train, 2);
        assert!(knn2.iter().filter(|n| n[0].distance == n[1].distance).count() > 10);
        let back = knn_scalar(&train, &query, 2);
        assert!(back.iter().filter(|n| n[0].distance == n[1].distance).count() > 10);
    }

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
