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
///
/// `#[non_exhaustive]`: start from [`MatchConfig::default`] and set what differs with the `with_*`
/// methods (or assign the public fields of a value you hold).
///
/// ```
/// use clatch::MatchConfig;
///
/// let config = MatchConfig::default().with_ratio(Some(0.7)).with_max_distance(Some(64));
/// assert!(config.cross_check); // the default
/// let plain = MatchConfig::default().with_ratio(None).with_cross_check(false);
/// assert_eq!((plain.ratio, plain.max_distance), (None, None));
/// ```
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
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
        // Checked: a huge `q` must not wrap round to an early query's neighbours.
        let start = q.checked_mul(self.k)?;
        self.matches.get(start..start.checked_add(self.k)?)
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

impl MatchConfig {
    with_methods! {
        /// The same rules with this ratio test ([`MatchConfig::ratio`]; `None` turns it off).
        with_ratio => ratio: Option<f32>;
        /// The same rules with the mutual cross-check on or off ([`MatchConfig::cross_check`]).
        with_cross_check => cross_check: bool;
        /// The same rules with this distance bound ([`MatchConfig::max_distance`]; `None`: none).
        with_max_distance => max_distance: Option<u32>;
    }

    /// `Error::InvalidConfig` for a ratio that is not finite and in `(0, 1]`.
    pub(crate) fn check(&self) -> Result<()> {
        if let Some(ratio) = self.ratio
            && !(ratio.is_finite() && ratio > 0.0 && ratio <= 1.0)
        {
            return Err(Error::InvalidConfig {
                field: "ratio",
                value: ratio.to_string(),
                reason: "must be finite and in (0, 1]",
            });
        }
        Ok(())
    }

    /// How many nearest neighbours of each query these rules look at: 2 with the ratio test (it
    /// compares the best with the second best), else 1. A gallery needs at least this many
    /// descriptors to be matched against.
    ///
    /// ```
    /// use clatch::MatchConfig;
    ///
    /// assert_eq!(MatchConfig::default().neighbours_needed(), 2);
    /// let no_ratio = MatchConfig::default().with_ratio(None);
    /// assert_eq!(no_ratio.neighbours_needed(), 1);
    /// ```
    pub fn neighbours_needed(&self) -> usize {
        if self.ratio.is_some() { 2 } else { 1 }
    }

    /// Whether a query set of `query_len` descriptors against a gallery of `train_len` has anything
    /// to match under these rules: a query, and at least [`MatchConfig::neighbours_needed`] gallery
    /// descriptors. The many-pairs calls ([`crate::Matcher::match_pairs`],
    /// [`crate::DescriptorCollection`], [`crate::DevicePool`]) give a pair that cannot match no
    /// matches; [`crate::Matcher::match_descriptors`] gives an empty query set no matches and reports
    /// too small a gallery ([`crate::Error::EmptyGallery`], [`crate::Error::InvalidK`]).
    ///
    /// ```
    /// use clatch::MatchConfig;
    ///
    /// let config = MatchConfig::default(); // with the ratio test
    /// assert!(config.can_match(10, 2));
    /// assert!(!config.can_match(10, 1) && !config.can_match(0, 50));
    /// ```
    pub fn can_match(&self, query_len: usize, train_len: usize) -> bool {
        query_len > 0 && train_len >= self.neighbours_needed()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ratio_test_needs_two_neighbours_and_a_pair_a_query() {
        let ratio = MatchConfig::default();
        let plain = MatchConfig {
            ratio: None,
            cross_check: false,
            max_distance: Some(40),
        };
        assert_eq!((ratio.neighbours_needed(), plain.neighbours_needed()), (2, 1));
        for (query, train, with_ratio, without) in [
            (0, 0, false, false),
            (0, 5, false, false),
            (1, 0, false, false),
            (1, 1, false, true),
            (1, 2, true, true),
            (7, 300, true, true),
        ] {
            assert_eq!(ratio.can_match(query, train), with_ratio, "{query}x{train}");
            assert_eq!(plain.can_match(query, train), without, "{query}x{train}");
        }
    }
}
