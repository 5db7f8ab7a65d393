//! AVX-512 matcher (x86-64 with AVX512F and AVX512-VPOPCNTDQ): the same neighbours and nearest queries
//! as the scalar reference ([`super::scan`]), ties included, from integer operations only.
//!
//! Layout: the gallery is copied once into blocks of [`LANES`] rows, word-major inside a block (word
//! `w` of rows `8b..8b + 8` is one 512-bit register), so `VPOPCNTQ` counts eight distances at once with
//! no horizontal sums: a distance is `Σ_w popcount(query[w] ^ row[w])`, added lane by lane.
//! [`GROUP`] queries share every gallery load, and the gallery is visited in tiles of [`TILE`] rows
//! that stay in L1 while the whole query block of the caller passes over them.
//!
//! Equal results: each query still sees the gallery rows in increasing index, and a row reaches
//! [`super::insert_neighbour`] (the reference's own insertion) unless its distance is at least the
//! query's current k-th distance, which the reference would reject too (the k-th distance only falls,
//! so a threshold read at the start of a block is never too strict). The nearest query of a row is the
//! minimum of `(distance << 32 | query)`, the reference's own key; a minimum does not depend on order.
//!
//! Why `unsafe`: the intrinsics need AVX512F and AVX512-VPOPCNTDQ, which [`Avx512::detect`] checks at run
//! time (holding an [`Avx512`] value is the proof); loads and stores go through raw pointers into
//! buffers whose lengths are checked once per call ([`Gallery::new`], [`Avx512::scan_block`]).

use std::arch::x86_64::*;

use super::Match;
use crate::descriptor::DescriptorSet;

/// Gallery rows per block: one 64-bit lane each.
pub(super) const LANES: usize = 8;
/// Queries that share each gallery load.
const GROUP: usize = 4;
/// Gallery rows per tile (a multiple of [`LANES`]): 256 rows of 512 bits are 16 KiB.
const TILE: usize = 256;

/// Proof that the CPU runs AVX512F and AVX512-VPOPCNTDQ (only [`Avx512::detect`] makes one).
#[derive(Clone, Copy, Debug)]
pub(super) struct Avx512(());

/// The gallery in blocks of [`LANES`] rows, word-major inside a block; rows past the end are zero.
pub(super) struct Gallery {
    words: usize,
    rows: usize,
    blocks: Vec<u64>,
}

impl Gallery {
    /// Copies `train` into blocks.
    pub(super) fn new(train: &DescriptorSet) -> Self {
        let words = train.width().words();
        let rows = train.len();
        let mut blocks = vec![0u64; rows.div_ceil(LANES) * LANES * words];
        for (t, row) in train.rows().enumerate() {
            let (b, lane) = (t / LANES, t % LANES);
            for (w, &word) in row.iter().enumerate() {
                blocks[(b * words + w) * LANES + lane] = word;
            }
        }
        Self {
            words,
            rows,
            blocks,
        }
    }

    /// Number of gallery rows.
    pub(super) fn len(&self) -> usize {
        self.rows
    }

    /// Number of blocks of [`LANES`] rows (the last may be partly padding).
    fn block_count(&self) -> usize {
        self.rows.div_ceil(LANES)
    }
}

impl Avx512 {
    /// `Some` iff the CPU reports AVX512F and AVX512-VPOPCNTDQ.
    pub(super) fn detect() -> Option<Self> {
        (is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vpopcntdq"))
            .then_some(Avx512(()))
    }

    /// The `k` nearest gallery rows of each query of `queries` (numbered from `first`), appended to
    /// `matches` query-major, and, when `nearest` is given (one entry per gallery row, rounded up to a
    /// whole block), `nearest[t]` lowered to `(distance << 32 | query)` where that is smaller: exactly
    /// what [`super::scan`] gives query by query.
    pub(super) fn scan_block(
        self,
        first: u32,
        queries: &[&[u64]],
        gallery: &Gallery,
        k: usize,
        nearest: Option<&mut [u64]>,
        matches: &mut Vec<Match>,
    ) {
        assert!(k >= 1 && k <= gallery.len() && gallery.words <= 8);
        assert!(queries.iter().all(|q| q.len() == gallery.words));
        if let Some(nearest) = &nearest {
            assert!(nearest.len() >= gallery.block_count() * LANES);
        }
        assert!(gallery.blocks.len() == gallery.block_count() * LANES * gallery.words);
        // SAFETY: AVX512F and AVX512-VPOPCNTDQ are present (self); the buffer lengths were checked just
        // above, which is all the kernel's pointer reads and writes rely on.
        unsafe {
            match gallery.words {
                8 => scan_block::<8>(first, queries, gallery, k, nearest, matches),
                4 => scan_block::<4>(first, queries, gallery, k, nearest, matches),
                w => scan_block_words(w, first, queries, gallery, k, nearest, matches),
            }
        }
    }
}

/// [`scan_block_words`] for a width known at compile time (the common 512- and 256-bit widths).
///
/// # Safety
/// As [`scan_block_words`].
#[target_feature(enable = "avx512f,avx512vpopcntdq")]
unsafe fn scan_block<const W: usize>(
    first: u32,
    queries: &[&[u64]],
    gallery: &Gallery,
    k: usize,
    nearest: Option<&mut [u64]>,
    matches: &mut Vec<Match>,
) {
    // SAFETY: the caller's contract.
    unsafe { scan_block_words(W, first, queries, gallery, k, nearest, matches) }
}

/// See [`Avx512::scan_block`].
///
/// # Safety
/// AVX512F and AVX512-VPOPCNTDQ; `words == gallery.words`, every query has `words` words,
/// `gallery.blocks` holds whole blocks, and `nearest` (if any) has an entry for every block lane.
#[target_feature(enable = "avx512f,avx512vpopcntdq")]
#[inline]
unsafe fn scan_block_words(
    words: usize,
    first: u32,
    queries: &[&[u64]],
    gallery: &Gallery,
    k: usize,
    mut nearest: Option<&mut [u64]>,
    matches: &mut Vec<Match>,
) {
    let mut best: Vec<Vec<Match>> = (0..queries.len())
        .map(|_| Vec::with_capacity(k + 1))
        .collect();
    let blocks = gallery.block_count();
    let tile_blocks = TILE / LANES;
    let last_lanes = gallery.rows - (blocks - 1) * LANES;
    let mut lane_distances = [0u64; LANES];
    for tile in (0..blocks).step_by(tile_blocks) {
        let tile_end = (tile + tile_blocks).min(blocks);
        for (g, group) in queries.chunks(GROUP).enumerate() {
            let q0 = g * GROUP;
            // A short group repeats its last query: same keys for `nearest`, results dropped.
            let member = |j: usize| group[j.min(group.len() - 1)];
            // Word `w` of member `j` at `[w][j]`: words past the width stay zero.
            let member_words: [[u64; GROUP]; 8] =
                std::array::from_fn(|w| std::array::from_fn(|j| member(j).get(w).copied().unwrap_or(0)));
            let ids: [u32; GROUP] = std::array::from_fn(|j| first + (q0 + j.min(group.len() - 1)) as u32);
            let id_lanes: [__m512i; GROUP] = ids.map(|q| _mm512_set1_epi64(q as i64));
            // A row is a candidate for member `j` iff its distance is below `limits[j]`: the k-th
            // distance of a full list, anything while it fills, nothing for a repeated member.
            let limit = |list: &Vec<Match>| {
                let below = if list.len() < k { u64::MAX } else { list[k - 1].distance as u64 };
                _mm512_set1_epi64(below as i64)
            };
            let mut limits: [__m512i; GROUP] = std::array::from_fn(|j| {
                if j < group.len() {
                    limit(&best[q0 + j])
                } else {
                    _mm512_setzero_si512()
                }
            });
            for b in tile..tile_end {
                // SAFETY: block `b` < `blocks` is `words` whole registers inside `gallery.blocks`.
                let base = unsafe { gallery.blocks.as_ptr().add(b * words * LANES) };
                let mut acc = [_mm512_setzero_si512(); GROUP];
                for (w, query_words) in member_words.iter().enumerate().take(words) {
                    // SAFETY: word `w` < `words` of block `b` (see `base`).
                    let row = unsafe { _mm512_loadu_si512(base.add(w * LANES) as *const __m512i) };
                    for (sum, &word) in acc.iter_mut().zip(query_words) {
                        let x = _mm512_xor_si512(row, _mm512_set1_epi64(word as i64));
                        *sum = _mm512_add_epi64(*sum, _mm512_popcnt_epi64(x));
                    }
                }
                let valid: __mmask8 = if b + 1 == blocks {
                    ((1u32 << last_lanes) - 1) as u8
                } else {
                    0xff
                };
                let candidates: [__mmask8; GROUP] =
                    std::array::from_fn(|j| _mm512_mask_cmplt_epu64_mask(valid, acc[j], limits[j]));
                // Rare once each list is full: one test for the group.
                if candidates.iter().any(|&c| c != 0) {
                    for j in 0..group.len() {
                        let mut lanes = candidates[j];
                        if lanes == 0 {
                            continue;
                        }
                        let list = &mut best[q0 + j];
                        // SAFETY: `lane_distances` holds exactly one register.
                        unsafe {
                            _mm512_storeu_si512(lane_distances.as_mut_ptr() as *mut __m512i, acc[j])
                        };
                        while lanes != 0 {
                            let lane = lanes.trailing_zeros() as usize;
                            lanes &= lanes - 1;
                            super::insert_neighbour(
                                list,
                                k,
                                Match {
                                    query: ids[j],
                                    train: (b * LANES + lane) as u32,
                                    distance: lane_distances[lane] as u32,
                                },
                            );
                        }
                        limits[j] = limit(list);
                    }
                }
                if let Some(nearest) = nearest.as_deref_mut() {
                    let mut key = _mm512_set1_epi64(-1);
                    for j in 0..GROUP {
                        let own = _mm512_or_si512(_mm512_slli_epi64::<32>(acc[j]), id_lanes[j]);
                        key = _mm512_min_epu64(key, own);
                    }
                    // SAFETY: `nearest` has an entry for every lane of every block (the contract).
                    unsafe {
                        let at = nearest.as_mut_ptr().add(b * LANES) as *mut __m512i;
                        _mm512_storeu_si512(at, _mm512_min_epu64(_mm512_loadu_si512(at), key));
                    }
                }
            }
        }
    }
    for list in best {
        matches.extend(list);
    }
}
