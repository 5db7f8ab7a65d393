//! Brute-force Hamming matching: k nearest neighbours, Lowe's ratio test, mutual cross-check.
//!
//! Contract (every backend gives exactly these results):
//! - distance = popcount of the XOR of the packed words;
//! - the k neighbours of a query are the k smallest `(distance, train index)` pairs, so **ties go to the
//!   lowest train index**; they are listed nearest first;
//! - ratio test: the best match is kept iff `(d1 as f32) < ratio * (d2 as f32)`, one correctly rounded
//!   `f32` multiplication (so `ratio = 0.8` keeps `d1 = 4, d2 = 5` out, as the decimal reading says);
//! - cross-check: kept iff the query is also the nearest query (lowest index on ties) of its train
//!   descriptor;
//! - max distance: kept iff `d1 <= max_distance`.

pub mod cpu;

use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};

/// Most neighbours per query the CUDA backend returns (`crate::cuda::MAX_K`; equal to
/// `CLATCH_MATCH_MAX_K` of `kernels/clatch.h`, checked in the layout tests).
pub const GPU_MAX_K: usize = 8;

/// A correspondence between query descriptor `query` and gallery descriptor `train`, as in OpenCV's
/// `DMatch` (without the image index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(C)]
pub struct Match {
    /// Index in the query set.
    pub query: u32,
    /// Index in the gallery (train) set.
    pub train: u32,
    /// Hamming distance in bits.
    pub distance: u32,
}

/// Which matches [`crate::Matcher::match_descriptors`] keeps (every rule, ties included:
/// [`crate::numerics`], section 5).
#[derive(Clone, Debug, PartialEq)]
pub struct MatchConfig {
    /// Lowe's ratio test: keep the best match only if `d1 < ratio · d2`. `None` turns it off; otherwise
    /// a finite value in `(0, 1]`. Needs at least two gallery descriptors. Default `Some(0.8)`.
    pub ratio: Option<f32>,
    /// Keep only mutual nearest neighbours. Default `true`.
    pub cross_check: bool,
    /// Drop matches farther than this many bits. Default `None`.
    pub max_distance: Option<u32>,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self {
            ratio: Some(0.8),
            cross_check: true,
            max_distance: None,
        }
    }
}

/// The k nearest neighbours of every query, query-major: neighbours of query `q` are
/// `as_slice()[q * k .. (q + 1) * k]`, nearest first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KnnMatches {
    k: usize,
    matches: Vec<Match>,
}

impl KnnMatches {
    /// `k` neighbours per query, query-major. `None` when `k` is 0 or `matches` is not a whole number
    /// of queries.
    pub fn new(k: usize, matches: Vec<Match>) -> Option<Self> {
        (k > 0 && matches.len().is_multiple_of(k)).then_some(Self { k, matches })
    }

    /// Neighbours per query.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Number of queries.
    pub fn len(&self) -> usize {
        self.matches.len() / self.k
    }

    /// True when there are no queries.
    pub fn is_empty(&self) -> bool {
        self.matches.is_empty()
    }

    /// The neighbours of query `q`, nearest first; `None` past the last query.
    pub fn neighbours(&self, q: usize) -> Option<&[Match]> {
        self.matches.get(q * self.k..(q + 1) * self.k)
    }

    /// Iterates over the queries' neighbour lists.
    pub fn iter(&self) -> std::slice::ChunksExact<'_, Match> {
        self.matches.chunks_exact(self.k)
    }

    /// All neighbours, `k` per query.
    pub fn as_slice(&self) -> &[Match] {
        &self.matches
    }

    /// All neighbours, `k` per query.
    pub fn into_vec(self) -> Vec<Match> {
        self.matches
    }
}

impl KnnMatches {
    /// Built by a backend: `k > 0` and whole queries by construction.
    pub(crate) fn from_parts(k: usize, matches: Vec<Match>) -> Self {
        debug_assert!(k > 0 && matches.len().is_multiple_of(k));
        Self { k, matches }
    }
}

/// The checks every matching entry point makes before a backend runs: equal widths, a gallery, and
/// `1 <= k <= gallery`.
pub fn check_sets(query: &DescriptorSet, train: &DescriptorSet, k: usize) -> Result<()> {
    if query.width() != train.width() {
        return Err(Error::DescriptorWidthMismatch {
            query_bits: query.width().bits(),
            train_bits: train.width().bits(),
        });
    }
    if train.is_empty() {
        return Err(Error::EmptyGallery);
    }
    if k == 0 || k > train.len() {
        return Err(Error::InvalidK {
            k,
            gallery: train.len(),
        });
    }
    Ok(())
}
