//! Many pairs of descriptor sets in one call: the collection path (every pair of a photo collection, or
//! a given pair list), as structure from motion needs it.

use super::DescriptorCollection;
use crate::backend::Backend;
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::matcher::Matcher;
use crate::matching::{self, Match};
use crate::parallel::*;

impl Matcher {
    /// The pairs `(i, j)`, `i < j`, of `n` sets in order: `(0, 1), (0, 2), …, (1, 2), …`.
    ///
    /// ```
    /// assert_eq!(clatch::Matcher::all_pairs(3), vec![(0, 1), (0, 2), (1, 2)]);
    /// ```
    pub fn all_pairs(n: usize) -> Vec<(usize, usize)> {
        (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .collect()
    }

    /// The matches of every pair, in pair order: `pairs[p] = (a, b)` matches `sets[a]` (queries)
    /// against `sets[b]` (gallery) exactly as [`Matcher::match_descriptors`] does. A pair with no
    /// query or too small a gallery (none, or one descriptor under the ratio test) gets no matches
    /// rather than an error, so that one featureless photo does not stop a collection. Every index and
    /// width is checked before any work.
    ///
    /// The CPU backend spreads the pairs over its threads; the CUDA backend uploads each set once into
    /// a [`DescriptorCollection`] and matches many pairs per kernel launch, blocks of pairs one after
    /// another.
    ///
    /// This is the convention of every many-items call ([`crate::Extractor::detect_and_describe_batch`],
    /// [`DescriptorCollection`], [`crate::DevicePool`]): the plain call returns every result in input
    /// order; its `*_with_progress` twin ([`Matcher::match_pairs_with_progress`]) also reports each
    /// finished item; and where all the results of a large collection need not be held at once, the
    /// collection's `*_each` calls ([`DescriptorCollection::match_pairs_each`]) hand each result over
    /// as it is ready instead.
    ///
    /// ```
    /// use clatch::{Backend, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};
    ///
    /// let width = DescriptorWidth::from_bits(64)?;
    /// let set = |seed: u64| {
    ///     let words = (0..100).map(|i| (i as u64 + seed).wrapping_mul(0x9E37_79B9_7F4A_7C15)).collect();
    ///     DescriptorSet::from_words(width, words)
    /// };
    /// let (a, b, c) = (set(0)?, set(50)?, set(7)?);
    /// let matcher = Matcher::new(Backend::Cpu, MatchConfig::default())?;
    /// let sets = [&a, &b, &c];
    /// let pairs = Matcher::all_pairs(sets.len());
    /// let matches = matcher.match_pairs(&sets, &pairs)?;
    /// assert_eq!(matches.len(), 3);
    /// assert_eq!(matches[0], matcher.match_descriptors(&a, &b)?);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn match_pairs(
        &self,
        sets: &[&DescriptorSet],
        pairs: &[(usize, usize)],
    ) -> Result<Vec<Vec<Match>>> {
        self.match_pairs_with_progress(sets, pairs, &|_| {})
    }

    /// [`Matcher::match_pairs`], calling `progress(p)` once per finished pair `p` (in any order and
    /// from any thread on the CPU, in pair order on the GPU), e.g. for a progress bar. The results
    /// are the same.
    ///
    /// ```
    /// use std::sync::atomic::{AtomicUsize, Ordering};
    /// use clatch::{Backend, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};
    ///
    /// let width = DescriptorWidth::from_bits(64)?;
    /// let set = |seed: u64| DescriptorSet::from_words(width, (0..50).map(|i| i * seed).collect());
    /// let (a, b, c) = (set(3)?, set(5)?, set(7)?);
    /// let matcher = Matcher::new(Backend::Cpu, MatchConfig::default())?;
    /// let finished = AtomicUsize::new(0);
    /// let pairs = Matcher::all_pairs(3);
    /// let matches = matcher.match_pairs_with_progress(&[&a, &b, &c], &pairs, &|_pair| {
    ///     finished.fetch_add(1, Ordering::Relaxed);
    /// })?;
    /// assert_eq!(finished.into_inner(), 3);
    /// assert_eq!(matches, matcher.match_pairs(&[&a, &b, &c], &pairs)?);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn match_pairs_with_progress(
        &self,
        sets: &[&DescriptorSet],
        pairs: &[(usize, usize)],
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<Vec<Vec<Match>>> {
        self.check_pairs(sets, pairs)?;
        let matchable = |&pair: &(usize, usize)| self.matchable(sets, pair);
        match self.backend() {
            Backend::Cpu => Ok(pairs
                .par_iter()
                .enumerate()
                .map(|(p, pair)| {
                    let found = if matchable(pair) {
                        matching::cpu::match_descriptors(sets[pair.0], sets[pair.1], self.config())
                    } else {
                        Vec::new()
                    };
                    progress(p);
                    found
                })
                .collect()),
            Backend::Cuda { .. } => {
                let Some(first) = sets.first() else {
                    return Ok(Vec::new()); // no sets, so no pairs (checked above)
                };
                let mut collection = DescriptorCollection::new(self, first.width())?;
                collection.add(sets)?;
                let mut results = Vec::with_capacity(pairs.len());
                collection.match_pairs_each(pairs, |p, matches| {
                    results.push(matches);
                    progress(p);
                })?;
                Ok(results)
            }
        }
    }

    /// Whether pair `(a, b)` (in range) is matched at all ([`crate::MatchConfig::can_match`]).
    /// Other pairs get no matches.
    pub(super) fn matchable(&self, sets: &[&DescriptorSet], (a, b): (usize, usize)) -> bool {
        self.config().can_match(sets[a].len(), sets[b].len())
    }

    /// Every pair's indices in range and every set of one width.
    pub(super) fn check_pairs(
        &self,
        sets: &[&DescriptorSet],
        pairs: &[(usize, usize)],
    ) -> Result<()> {
        for (p, &(a, b)) in pairs.iter().enumerate() {
            for index in [a, b] {
                if index >= sets.len() {
                    return Err(Error::PairOutOfRange {
                        pair: p,
                        index,
                        sets: sets.len(),
                    });
                }
            }
        }
        if let Some(first) = sets.first() {
            for set in sets {
                if set.width() != first.width() {
                    return Err(Error::DescriptorWidthMismatch {
                        query_bits: first.width().bits(),
                        train_bits: set.width().bits(),
                    });
                }
            }
        }
        Ok(())
    }
}
