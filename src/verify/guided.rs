//! Guided matching (COLMAP 3.8's `guided_matching`): once a pair's geometry is verified, its
//! descriptors are matched again, each keypoint of the first image only against the keypoints of
//! the second that the geometry allows, and the matches found so are the pair's new inliers. It
//! recovers correct matches that matching without the geometry dropped: a ratio test failed
//! because the second-nearest descriptor was a look-alike elsewhere in the image (one window over
//! on a facade), which the geometry puts out of reach.
//!
//! The rule, the specification every backend follows (section 7.8 ("Guided matching") of
//! [`crate::numerics`]):
//! - the **constraint** is the residual verification counts inliers by, under its threshold `t`
//!   (`r ≤ t · t`): for [`GeometryConfig::Calibrated`] and [`GeometryConfig::Uncalibrated`] the
//!   squared Sampson distance to F's epipolar lines (a band of about `t` pixels around the line),
//!   for [`GeometryConfig::PlanarOrPanoramic`] the squared transfer distance under H (a disc of
//!   radius `t` around the mapped point). Positions are the keypoints' `f32` coordinates widened to
//!   `f64`; the residuals are the very operations, in the same order, that LO-RANSAC evaluates (F
//!   times the first point and Fᵀ times the second, `H a` and its division, computed once per
//!   keypoint: the same numbers). Other configurations, or a configuration whose model is missing,
//!   have no guided step;
//! - among the candidates that satisfy it, matching follows [`crate::MatchConfig`]'s rules exactly
//!   as the matcher applies them ([`crate::numerics`], section "Matching"): the nearest and
//!   second-nearest train descriptor by `(Hamming distance, train index)`, the ratio test, the
//!   cross-check (the nearest query of that train descriptor among the queries whose constraint it
//!   satisfies, lowest index on ties), the distance limit. A query with a single candidate has no
//!   rival: the ratio test compares with the descriptor's width in bits, the largest distance there
//!   is (COLMAP's guided matcher gives every excluded descriptor the largest distance too);
//! - the guided matches, in query order, are the new inliers: each satisfies the geometry by
//!   construction. With [`GuidedMatching::neighbour_consistency`] they pass that neighbour rule
//!   first ([`super::NeighbourConsistency`], integers): a band along an epipolar line can hold a
//!   repeated structure's twin one period off, which only the neighbours tell apart. The geometry's
//!   configuration, models and RANSAC counts stay.
//!
//! On a GPU this is one thread (or warp) per query scanning the second image's keypoints in index
//! order, with the reverse nearest as the `(distance << 32 | query)` minimum per train keypoint, as
//! the matcher's kernels fold it.

use super::geometry::{GeometryConfig, TwoViewGeometry};
use super::linalg::{Mat3, mul3_vec, mul3t_vec};
use crate::descriptor::{DescriptorSet, hamming};
use crate::error::{Error, Result};
use crate::keypoint::KeyPoint;
use crate::matching::cpu::{insert_neighbour, passes};
use crate::matching::{Match, MatchConfig};

/// The settings of guided matching: the matching rules (the matcher's, [`MatchConfig`]) and the
/// threshold of the geometric constraint.
///
/// `#[non_exhaustive]`: start from [`GuidedMatching::default`] and change what differs with the
/// `with_*` methods.
///
/// ```
/// use clatch::MatchConfig;
/// use clatch::verify::GuidedMatching;
///
/// let guided = GuidedMatching::default().with_max_error(2.0);
/// assert_eq!((guided.max_error, &guided.rules), (2.0, &MatchConfig::default()));
/// ```
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct GuidedMatching {
    /// Which matches are kept among the candidates (ratio test, cross-check, distance limit).
    /// Default: [`MatchConfig::default`], the matcher's.
    pub rules: MatchConfig,
    /// The constraint's threshold in pixels: the Sampson distance for F, the transfer distance for
    /// H; verification's threshold ([`super::VerifyConfig::max_error`]) is the natural choice.
    /// Default 4.
    pub max_error: f64,
    /// The neighbour rule the guided matches pass too ([`super::NeighbourConsistency`], as the
    /// putative matches do before RANSAC with [`super::VerifyConfig::neighbour_consistency`]): a
    /// band along an epipolar line holds the twins of a repeated structure, one period off, that
    /// only the neighbours tell apart. Default `None`.
    pub neighbour_consistency: Option<super::NeighbourConsistency>,
}

impl Default for GuidedMatching {
    fn default() -> Self {
        Self {
            rules: MatchConfig::default(),
            max_error: 4.0,
            neighbour_consistency: None,
        }
    }
}

impl GuidedMatching {
    with_methods! {
        /// The same settings with these matching rules ([`GuidedMatching::rules`]).
        with_rules => rules: MatchConfig;
        /// The same settings with this threshold ([`GuidedMatching::max_error`], pixels).
        with_max_error => max_error: f64;
        /// The same settings with this neighbour rule ([`GuidedMatching::neighbour_consistency`]).
        with_neighbour_consistency => neighbour_consistency: Option<super::NeighbourConsistency>;
    }

    /// `Error::InvalidConfig` for a setting out of its range.
    fn check(&self) -> Result<()> {
        self.rules.check()?;
        if !(self.max_error.is_finite() && self.max_error > 0.0) {
            return Err(Error::InvalidConfig {
                field: "max_error",
                value: self.max_error.to_string(),
                reason: "must be finite and positive",
            });
        }
        Ok(())
    }
}

/// What guided matching found for a pair: the matches (`query` indexes the first image's
/// keypoints, `train` the second's, in query order) and the geometry whose inliers are all of them
/// (`inliers` indexes `matches`). Hand both to [`crate::colmap::TwoViewGeometry::from_verified`] in
/// place of the putative matches and their geometry (a folder writer's `add_guided_geometry` does,
/// and writes the putative matches into COLMAP's `matches` as COLMAP does).
#[derive(Clone, Debug, PartialEq)]
pub struct GuidedMatches {
    /// The guided matches.
    pub matches: Vec<Match>,
    /// The verified geometry with `inliers` = `0 .. matches.len()`.
    pub geometry: TwoViewGeometry,
}

/// The geometric constraint of a verified pair, evaluated per (query, train) keypoint pair.
enum Constraint {
    /// Sampson distance to F's lines: `F a` per first-image point, `Fᵀ b` per second-image point.
    Epipolar {
        lines_a: Vec<[f64; 3]>,
        lines_b: Vec<[f64; 3]>,
    },
    /// Transfer distance: `π(H a)` per first-image point.
    Transfer { mapped: Vec<[f64; 2]> },
}

impl Constraint {
    /// The constraint of `geometry`, `None` for a configuration without one (or its model missing).
    fn of(geometry: &TwoViewGeometry, a: &[[f64; 2]], b: &[[f64; 2]]) -> Option<Self> {
        let homogeneous = |p: &[f64; 2]| [p[0], p[1], 1.0];
        match geometry.config {
            GeometryConfig::Calibrated | GeometryConfig::Uncalibrated => {
                let f = geometry.f?;
                Some(Self::Epipolar {
                    lines_a: a.iter().map(|p| mul3_vec(&f, &homogeneous(p))).collect(),
                    lines_b: b.iter().map(|p| mul3t_vec(&f, &homogeneous(p))).collect(),
                })
            }
            GeometryConfig::PlanarOrPanoramic => {
                let h = geometry.h?;
                Some(Self::Transfer {
                    mapped: a.iter().map(|p| mapped(&h, *p)).collect(),
                })
            }
            _ => None,
        }
    }

    /// The squared residual of keypoint `i` of the first image against keypoint `j` (at `b`) of the
    /// second: bit for bit [`super::fundamental::sampson_error_squared`] or
    /// [`super::homography::transfer_error_squared`], whose per-keypoint parts are computed once.
    #[cfg(test)]
    fn residual(&self, i: usize, j: usize, b: [f64; 2]) -> f64 {
        match self {
            Self::Epipolar { lines_a, lines_b } => sampson(lines_a[i], lines_b[j], b),
            Self::Transfer { mapped } => transfer(mapped[i], b),
        }
    }

    /// Appends to `out`, in increasing order, the second-image keypoints (at `b`) whose residual
    /// against keypoint `i` of the first image is at most `max_residual` (a NaN residual never
    /// is): [`Constraint::residual`] of each, first all of them into `residuals` (a loop that
    /// vectorises), then the comparisons.
    fn candidates(
        &self,
        i: usize,
        b: &[[f64; 2]],
        max_residual: f64,
        residuals: &mut Vec<f64>,
        out: &mut Vec<u32>,
    ) {
        residuals.clear();
        match self {
            Self::Epipolar { lines_a, lines_b } => {
                let fa = lines_a[i];
                residuals.extend(b.iter().zip(lines_b).map(|(p, ftb)| sampson(fa, *ftb, *p)));
            }
            Self::Transfer { mapped } => {
                let m = mapped[i];
                residuals.extend(b.iter().map(|p| transfer(m, *p)));
            }
        }
        out.clear();
        for (t, &r) in residuals.iter().enumerate() {
            if r <= max_residual {
                out.push(t as u32);
            }
        }
    }
}

/// The squared Sampson error of `b` under `F` from `F a` and `Fᵀ b`, in
/// [`super::fundamental::sampson_error_squared`]'s order.
#[inline(always)]
fn sampson(fa: [f64; 3], ftb: [f64; 3], b: [f64; 2]) -> f64 {
    let btfa = b[0] * fa[0] + b[1] * fa[1] + fa[2];
    btfa * btfa / (fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1])
}

/// The squared transfer error of `b` from `π(H a)`, in
/// [`super::homography::transfer_error_squared`]'s order.
#[inline(always)]
fn transfer(mapped: [f64; 2], b: [f64; 2]) -> f64 {
    let dx = b[0] - mapped[0];
    let dy = b[1] - mapped[1];
    dx * dx + dy * dy
}

/// `π(H a)` as [`super::homography::transfer_error_squared`] computes it: `(u · (1/w), v · (1/w))`.
fn mapped(h: &Mat3, a: [f64; 2]) -> [f64; 2] {
    let u = h[0][0] * a[0] + h[0][1] * a[1] + h[0][2];
    let v = h[1][0] * a[0] + h[1][1] * a[1] + h[1][2];
    let w = h[2][0] * a[0] + h[2][1] * a[1] + h[2][2];
    let inverse_w = 1.0 / w;
    [u * inverse_w, v * inverse_w]
}

/// The positions of `keypoints` in `f64`; `Error::InvalidInput` for one not finite, for a count
/// other than the descriptors', or more keypoints than `u32` indexes.
fn positions(
    keypoints: &[KeyPoint],
    descriptors: &DescriptorSet,
    image: &str,
) -> Result<Vec<[f64; 2]>> {
    if keypoints.len() != descriptors.len() {
        return Err(Error::InvalidInput {
            what: "guided matching",
            reason: format!(
                "image {image} has {} keypoints and {} descriptors; one descriptor per keypoint",
                keypoints.len(),
                descriptors.len()
            ),
        });
    }
    if u32::try_from(keypoints.len()).is_err() {
        return Err(Error::InvalidInput {
            what: "guided matching",
            reason: format!(
                "image {image} has {} keypoints; at most 2^32 - 1",
                keypoints.len()
            ),
        });
    }
    keypoints
        .iter()
        .enumerate()
        .map(|(i, k)| {
            if k.x.is_finite() && k.y.is_finite() {
                Ok([f64::from(k.x), f64::from(k.y)])
            } else {
                Err(Error::InvalidInput {
                    what: "keypoint",
                    reason: format!(
                        "keypoint {i} of image {image} is at ({}, {}), not finite",
                        k.x, k.y
                    ),
                })
            }
        })
        .collect()
}

/// Matches the descriptors of a verified pair again under its geometry (the module's rule) and
/// returns the guided matches with the geometry whose inliers they are; `None` when the geometry's
/// configuration has no constraint (degenerate, watermark, a model missing): the pair keeps its
/// verified inliers. `geometry` is what [`super::verify_pair`] found for these keypoints (matrices
/// in clatch's pixel coordinates); keypoint `i` is described by row `i` of its image's descriptors.
///
/// Errors: `Error::InvalidConfig` for a ratio or threshold out of range, `Error::InvalidInput` for
/// keypoint and descriptor counts that differ or a keypoint at a non-finite position,
/// `Error::DescriptorWidthMismatch` for descriptors of two widths.
///
/// ```
/// use clatch::verify::{GeometryConfig, GuidedMatching, InlierCounts, TwoViewGeometry, guided_matches};
/// use clatch::{DescriptorSet, DescriptorWidth, KeyPoint};
///
/// // The second image is the first shifted 20 px to the left (H a translation). Keypoints 0 and 1
/// // of the first image carry the same descriptor: plain matching cannot tell them apart (ratio
/// // 1), but only one of them maps near each keypoint of the second image.
/// let a = [KeyPoint::new(100.0, 50.0), KeyPoint::new(300.0, 50.0)];
/// let b = [KeyPoint::new(80.0, 50.0), KeyPoint::new(280.0, 50.0)];
/// let width = DescriptorWidth::from_bits(64).unwrap();
/// let same = DescriptorSet::from_words(width, vec![0xFF, 0xFF])?;
/// let shift = [[1.0, 0.0, -20.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// let geometry = TwoViewGeometry { config: GeometryConfig::PlanarOrPanoramic, f: None, e: None,
///     h: Some(shift), inliers: vec![], inlier_counts: InlierCounts::default() };
/// let guided = guided_matches(&a, &b, &same, &same, &geometry, &GuidedMatching::default())?.unwrap();
/// let pairs: Vec<(u32, u32)> = guided.matches.iter().map(|m| (m.query, m.train)).collect();
/// assert_eq!(pairs, [(0, 0), (1, 1)]);
/// assert_eq!(guided.geometry.inliers, [0, 1]);
/// # Ok::<(), clatch::Error>(())
/// ```
pub fn guided_matches(
    keypoints_a: &[KeyPoint],
    keypoints_b: &[KeyPoint],
    descriptors_a: &DescriptorSet,
    descriptors_b: &DescriptorSet,
    geometry: &TwoViewGeometry,
    config: &GuidedMatching,
) -> Result<Option<GuidedMatches>> {
    config.check()?;
    if descriptors_a.width() != descriptors_b.width() {
        return Err(Error::DescriptorWidthMismatch {
            query_bits: descriptors_a.width().bits(),
            train_bits: descriptors_b.width().bits(),
        });
    }
    let a = positions(keypoints_a, descriptors_a, "A")?;
    let b = positions(keypoints_b, descriptors_b, "B")?;
    let Some(constraint) = Constraint::of(geometry, &a, &b) else {
        return Ok(None);
    };
    let mut matches = match_under(&constraint, &b, descriptors_a, descriptors_b, config);
    if let Some(rule) = &config.neighbour_consistency {
        let kept = rule.kept(keypoints_a, keypoints_b, &matches);
        matches = kept.iter().map(|&i| matches[i as usize]).collect();
    }
    let inliers = (0..matches.len() as u32).collect();
    Ok(Some(GuidedMatches {
        matches,
        geometry: TwoViewGeometry {
            inliers,
            ..geometry.clone()
        },
    }))
}

/// The matches of the rule among the (query, train) pairs that satisfy `constraint` (checked
/// inputs).
fn match_under(
    constraint: &Constraint,
    b: &[[f64; 2]],
    descriptors_a: &DescriptorSet,
    descriptors_b: &DescriptorSet,
    config: &GuidedMatching,
) -> Vec<Match> {
    let rules = &config.rules;
    let max_residual = config.max_error * config.max_error;
    let k = rules.neighbours_needed();
    let rows_b: Vec<&[u64]> = descriptors_b.rows().collect();
    // (distance << 32 | query): the smallest is the nearest query, then the lowest index.
    let mut nearest = vec![u64::MAX; rows_b.len()];
    let mut lists = Vec::with_capacity(descriptors_a.len());
    let (mut residuals, mut candidates) = (Vec::with_capacity(b.len()), Vec::new());
    for (q, qd) in descriptors_a.rows().enumerate() {
        let mut best = Vec::with_capacity(k + 1);
        constraint.candidates(q, b, max_residual, &mut residuals, &mut candidates);
        for &t in &candidates {
            let t = t as usize;
            let distance = hamming(qd, rows_b[t]);
            nearest[t] = nearest[t].min(u64::from(distance) << 32 | q as u64);
            let candidate = Match {
                query: q as u32,
                train: t as u32,
                distance,
            };
            insert_neighbour(&mut best, k, candidate);
        }
        lists.push(best);
    }
    let no_rival = descriptors_a.width().bits() as u32;
    lists
        .iter()
        .filter_map(|best| {
            let first = *best.first()?;
            let second = best.get(1).map_or(no_rival, |m| m.distance);
            let nearest_query = rules
                .cross_check
                .then(|| nearest[first.train as usize] as u32);
            passes(first, second, nearest_query, rules).then_some(first)
        })
        .collect()
}

/// The precomputed residual of `a` against `b` and verification's own (for the tests).
#[cfg(test)]
fn residual_of(geometry: &TwoViewGeometry, a: [f64; 2], b: [f64; 2]) -> Option<(f64, f64)> {
    let constraint = Constraint::of(geometry, &[a], &[b])?;
    let reference = match &constraint {
        Constraint::Epipolar { .. } => {
            super::fundamental::sampson_error_squared(&geometry.f?, a, b)
        }
        Constraint::Transfer { .. } => {
            super::homography::transfer_error_squared(&geometry.h?, a, b)
        }
    };
    Some((constraint.residual(0, 0, b), reference))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DescriptorWidth;
    use crate::verify::InlierCounts;

    /// F of a camera moved sideways: horizontal epipolar lines, residual `(y_a − y_b)² / 2`.
    const SIDEWAYS: Mat3 = [[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]];
    /// F of a camera moved up: vertical epipolar lines.
    const UPWARDS: Mat3 = [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]];

    fn geometry(config: GeometryConfig, f: Option<Mat3>, h: Option<Mat3>) -> TwoViewGeometry {
        TwoViewGeometry {
            config,
            f,
            e: None,
            h,
            inliers: vec![7],
            inlier_counts: InlierCounts { e: 0, f: 30, h: 20 },
        }
    }

    fn set(words: &[u64]) -> DescriptorSet {
        DescriptorSet::from_words(DescriptorWidth::from_bits(64).unwrap(), words.to_vec()).unwrap()
    }

    fn keypoints(points: &[(f32, f32)]) -> Vec<KeyPoint> {
        points.iter().map(|&(x, y)| KeyPoint::new(x, y)).collect()
    }

    fn pairs(matches: &[Match]) -> Vec<(u32, u32)> {
        matches.iter().map(|m| (m.query, m.train)).collect()
    }

    /// A word with the lowest `n` bits set.
    fn bits(n: u32) -> u64 {
        (1u64 << n) - 1
    }

    #[test]
    fn a_match_the_ratio_test_dropped_is_recovered_inside_the_band() {
        // Query 0's true match (train 0, 4 bits off, on its epipolar line) has a look-alike
        // (train 1, 5 bits off) 100 px below: 4 < 0.8 · 5 fails, so the matcher drops it.
        let a = keypoints(&[(100.0, 50.0), (400.0, 300.0)]);
        let b = keypoints(&[(70.0, 51.0), (70.0, 150.0), (380.0, 300.0)]);
        let da = set(&[0, 0xFFFF_0000]);
        let db = set(&[bits(4), bits(5), 0xFFFF_0000]);
        let plain = crate::matching::cpu::match_descriptors(&da, &db, &MatchConfig::default());
        assert_eq!(pairs(&plain), [(1, 2)]);
        let g = geometry(GeometryConfig::Uncalibrated, Some(SIDEWAYS), None);
        let guided = guided_matches(&a, &b, &da, &db, &g, &GuidedMatching::default())
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(0, 0), (1, 2)]);
        assert_eq!(guided.matches[0].distance, 4);
        assert_eq!(guided.geometry.inliers, [0, 1]);
        assert_eq!(guided.geometry.inlier_counts, g.inlier_counts);
        assert_eq!((guided.geometry.config, guided.geometry.f), (g.config, g.f));
        // A tighter band (the look-alike 1 px off the line, threshold 0.5 px) loses it again.
        let b_near = keypoints(&[(70.0, 50.0), (70.0, 50.5), (380.0, 300.0)]);
        let tight = GuidedMatching::default().with_max_error(0.5);
        let guided = guided_matches(&a, &b_near, &da, &db, &g, &tight)
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(1, 2)]);
    }

    #[test]
    fn the_band_keeps_the_twin_on_the_line_and_excludes_the_one_a_period_off() {
        // Two rows of identical windows: every descriptor equal, so matching alone keeps none.
        let a = keypoints(&[(100.0, 50.0), (100.0, 150.0), (200.0, 50.0), (200.0, 150.0)]);
        let b = keypoints(&[(80.0, 150.0), (80.0, 50.0), (180.0, 150.0), (180.0, 50.0)]);
        let same = set(&[0xF0F0; 4]);
        assert!(
            crate::matching::cpu::match_descriptors(&same, &same, &MatchConfig::default())
                .is_empty()
        );
        // H (a 20 px shift) leaves each window a single candidate: its own.
        let shift = [[1.0, 0.0, -20.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let h = geometry(GeometryConfig::PlanarOrPanoramic, None, Some(shift));
        let guided = guided_matches(&a, &b, &same, &same, &h, &GuidedMatching::default())
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(0, 1), (1, 0), (2, 3), (3, 2)]);
        // Horizontal lines: the window of the other row is out of the band, but the neighbour
        // along the row is in it, an identical rival: the ratio test drops both.
        let f = geometry(GeometryConfig::Calibrated, Some(SIDEWAYS), None);
        let guided = guided_matches(&a, &b, &same, &same, &f, &GuidedMatching::default())
            .unwrap()
            .unwrap();
        assert!(guided.matches.is_empty());
        // Without the ratio test the twin along the row wins by index, the other row never.
        let no_ratio =
            GuidedMatching::default().with_rules(MatchConfig::default().with_ratio(None));
        let guided = guided_matches(&a, &b, &same, &same, &f, &no_ratio)
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(0, 1), (1, 0)]);
        // Vertical lines (a camera moved up) put every window of B out of the band of A's (20 px
        // aside): nothing.
        let up = geometry(GeometryConfig::Uncalibrated, Some(UPWARDS), None);
        let guided = guided_matches(&a, &b, &same, &same, &up, &no_ratio)
            .unwrap()
            .unwrap();
        assert!(guided.matches.is_empty());
    }

    #[test]
    fn the_neighbour_rule_drops_a_guided_match_its_neighbours_do_not_follow() {
        // Six keypoints along a row move 20 px left; query 5's look-alike sits 600 px further along
        // the same epipolar line, nearer in Hamming distance than its true match.
        let a: Vec<KeyPoint> = (0..6)
            .map(|i| KeyPoint::new(100.0 + 40.0 * i as f32, 50.0))
            .collect();
        let mut b: Vec<KeyPoint> = a.iter().map(|k| KeyPoint::new(k.x - 20.0, k.y)).collect();
        b.push(KeyPoint::new(900.0, 50.0));
        let words: Vec<u64> = (0..6).map(|i| 0xFFu64 << (8 * i)).collect();
        let mut train = words.clone();
        train[5] ^= 0xFF;
        train.push(words[5]);
        let (da, db) = (set(&words), set(&train));
        let g = geometry(GeometryConfig::Uncalibrated, Some(SIDEWAYS), None);
        let plain = guided_matches(&a, &b, &da, &db, &g, &GuidedMatching::default())
            .unwrap()
            .unwrap();
        assert_eq!(
            pairs(&plain.matches),
            [(0, 0), (1, 1), (2, 2), (3, 3), (4, 4), (5, 6)]
        );
        let ruled = GuidedMatching::default()
            .with_neighbour_consistency(Some(crate::verify::NeighbourConsistency::default()));
        let guided = guided_matches(&a, &b, &da, &db, &g, &ruled)
            .unwrap()
            .unwrap();
        assert_eq!(
            pairs(&guided.matches),
            [(0, 0), (1, 1), (2, 2), (3, 3), (4, 4)]
        );
        assert_eq!(guided.geometry.inliers, [0, 1, 2, 3, 4]);
    }

    #[test]
    fn the_cross_check_is_decided_among_the_queries_of_the_band() {
        // Train 0 is nearest to queries 0 (3 bits) and 1 (1 bit), both in its band; train 1 is
        // query 0's second candidate. Query 1 takes train 0, so query 0 loses it.
        let a = keypoints(&[(10.0, 20.0), (50.0, 20.0)]);
        let b = keypoints(&[(30.0, 20.0), (90.0, 20.0)]);
        let da = set(&[bits(3), bits(1)]);
        let db = set(&[0, bits(40)]);
        let g = geometry(GeometryConfig::Uncalibrated, Some(SIDEWAYS), None);
        let guided = guided_matches(&a, &b, &da, &db, &g, &GuidedMatching::default())
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(1, 0)]);
        let alone =
            GuidedMatching::default().with_rules(MatchConfig::default().with_cross_check(false));
        let guided = guided_matches(&a, &b, &da, &db, &g, &alone)
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(0, 0), (1, 0)]);
        // Equal distances: the lowest query index is the nearest.
        let tie = set(&[bits(2), bits(2)]);
        let guided = guided_matches(&a, &b, &tie, &db, &g, &GuidedMatching::default())
            .unwrap()
            .unwrap();
        assert_eq!(pairs(&guided.matches), [(0, 0)]);
    }

    #[test]
    fn without_a_constraint_it_is_the_matcher() {
        // A threshold that admits every pair: the matcher's result, ties and all.
        let mut state = 11u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            state >> 33
        };
        let width = DescriptorWidth::from_bits(16).unwrap();
        let words = |n: usize, next: &mut dyn FnMut() -> u64| {
            (0..n).map(|_| next() & 0xFFFF).collect::<Vec<_>>()
        };
        let (da, db) = (
            DescriptorSet::from_words(width, words(90, &mut next)).unwrap(),
            DescriptorSet::from_words(width, words(70, &mut next)).unwrap(),
        );
        let place = |n: usize, next: &mut dyn FnMut() -> u64| -> Vec<KeyPoint> {
            (0..n)
                .map(|_| KeyPoint::new((next() % 500) as f32, (next() % 400) as f32))
                .collect()
        };
        let (a, b) = (place(90, &mut next), place(70, &mut next));
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let g = geometry(GeometryConfig::PlanarOrPanoramic, None, Some(identity));
        for rules in [
            MatchConfig::default(),
            MatchConfig::default()
                .with_ratio(Some(0.9))
                .with_cross_check(false),
            MatchConfig::default()
                .with_ratio(None)
                .with_max_distance(Some(5)),
        ] {
            let config = GuidedMatching::default()
                .with_rules(rules.clone())
                .with_max_error(1e6);
            let guided = guided_matches(&a, &b, &da, &db, &g, &config)
                .unwrap()
                .unwrap();
            let plain = crate::matching::cpu::match_descriptors(&da, &db, &rules);
            assert!(!plain.is_empty());
            assert_eq!(guided.matches, plain, "{rules:?}");
        }
    }

    #[test]
    fn the_residuals_are_verification_s_bit_for_bit() {
        let f = [
            [1e-7, -3e-6, 2e-3],
            [4e-6, 2e-7, -0.011],
            [-1.9e-3, 0.0103, 0.37],
        ];
        let h = [
            [0.93, 0.04, 12.5],
            [-0.02, 1.07, -3.25],
            [1.1e-5, -2.3e-5, 1.0],
        ];
        for (i, (x, y)) in [(0.0, 0.0), (13.25, 799.5), (1599.0, 3.75), (640.125, 480.5)]
            .into_iter()
            .enumerate()
        {
            let (a, b) = ([x, y], [y * 0.7 + i as f64, x * 0.3 + 1.5]);
            for g in [
                geometry(GeometryConfig::Uncalibrated, Some(f), None),
                geometry(GeometryConfig::PlanarOrPanoramic, None, Some(h)),
            ] {
                let (ours, theirs) = residual_of(&g, a, b).unwrap();
                assert_eq!(
                    ours.to_bits(),
                    theirs.to_bits(),
                    "{a:?} {b:?} {:?}",
                    g.config
                );
            }
        }
    }

    #[test]
    fn empty_images_give_no_matches_and_other_configurations_no_step() {
        let g = geometry(GeometryConfig::Uncalibrated, Some(SIDEWAYS), None);
        let one = set(&[1]);
        let none = set(&[]);
        let k = keypoints(&[(1.0, 2.0)]);
        for (a, da, b, db) in [
            (&k[..0], &none, &k[..], &one),
            (&k[..], &one, &k[..0], &none),
            (&k[..0], &none, &k[..0], &none),
        ] {
            let guided = guided_matches(a, b, da, db, &g, &GuidedMatching::default())
                .unwrap()
                .unwrap();
            assert!(guided.matches.is_empty() && guided.geometry.inliers.is_empty());
        }
        for g in [
            geometry(GeometryConfig::Degenerate, Some(SIDEWAYS), Some(SIDEWAYS)),
            geometry(GeometryConfig::Watermark, Some(SIDEWAYS), Some(SIDEWAYS)),
            geometry(GeometryConfig::Undefined, Some(SIDEWAYS), Some(SIDEWAYS)),
            geometry(GeometryConfig::Calibrated, None, Some(SIDEWAYS)),
            geometry(GeometryConfig::PlanarOrPanoramic, Some(SIDEWAYS), None),
        ] {
            assert_eq!(
                guided_matches(&k, &k, &one, &one, &g, &GuidedMatching::default()).unwrap(),
                None
            );
        }
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        use crate::ErrorKind;
        let g = geometry(GeometryConfig::Uncalibrated, Some(SIDEWAYS), None);
        let k = keypoints(&[(1.0, 2.0)]);
        let one = set(&[1]);
        let run =
            |a: &[KeyPoint], da: &DescriptorSet, db: &DescriptorSet, config: &GuidedMatching| {
                guided_matches(a, &k, da, db, &g, config)
                    .unwrap_err()
                    .kind()
            };
        let ok = GuidedMatching::default();
        assert_eq!(run(&k, &set(&[1, 2]), &one, &ok), ErrorKind::InvalidInput);
        assert_eq!(
            run(&keypoints(&[(f32::NAN, 2.0)]), &one, &one, &ok),
            ErrorKind::InvalidInput
        );
        let wide = DescriptorSet::from_words(DescriptorWidth::from_bits(128).unwrap(), vec![1, 2])
            .unwrap();
        assert_eq!(
            run(&k, &one, &wide, &ok),
            ErrorKind::DescriptorWidthMismatch
        );
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(
                run(&k, &one, &one, &ok.clone().with_max_error(bad)),
                ErrorKind::InvalidConfig
            );
        }
        let ratio = ok.with_rules(MatchConfig::default().with_ratio(Some(1.5)));
        assert_eq!(run(&k, &one, &one, &ratio), ErrorKind::InvalidConfig);
    }
}
