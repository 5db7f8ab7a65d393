//! Naive O(N·M) references of the matching contract (`clatch::numerics`, section 5), written out
//! directly, for the matcher suites.

use clatch::{DescriptorSet, Match, MatchConfig};

use super::naive_hamming;

/// All `(distance, train)` pairs of every query, sorted: the reference kNN order.
pub fn naive_sorted(query: &DescriptorSet, train: &DescriptorSet) -> Vec<Vec<(u32, u32)>> {
    let bits = query.width().bits();
    query
        .rows()
        .map(|q| {
            let mut all: Vec<(u32, u32)> = train
                .rows()
                .enumerate()
                .map(|(t, row)| (naive_hamming(q, row, bits), t as u32))
                .collect();
            all.sort();
            all
        })
        .collect()
}

pub fn naive_knn(query: &DescriptorSet, train: &DescriptorSet, k: usize) -> Vec<Match> {
    naive_sorted(query, train)
        .into_iter()
        .enumerate()
        .flat_map(|(q, all)| {
            all.into_iter().take(k).map(move |(distance, train)| Match {
                query: q as u32,
                train,
                distance,
            })
        })
        .collect()
}

/// The documented `match_descriptors` contract, written out directly.
pub fn naive_match(
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Vec<Match> {
    naive_match_sorted(
        &naive_sorted(query, train),
        &naive_sorted(train, query),
        config,
    )
}

/// [`naive_match`] from the sorted pair lists of both directions.
pub fn naive_match_sorted(
    forward: &[Vec<(u32, u32)>],
    backward: &[Vec<(u32, u32)>],
    config: &MatchConfig,
) -> Vec<Match> {
    let mut out = Vec::new();
    for (q, all) in forward.iter().enumerate() {
        let (d1, t) = all[0];
        if let Some(ratio) = config.ratio {
            let d2 = all[1].0;
            let keep = (d1 as f32) < ratio * (d2 as f32);
            if !keep {
                continue;
            }
        }
        if config.cross_check && backward[t as usize][0].1 != q as u32 {
            continue;
        }
        if let Some(max) = config.max_distance
            && d1 > max
        {
            continue;
        }
        out.push(Match {
            query: q as u32,
            train: t,
            distance: d1,
        });
    }
    out
}
