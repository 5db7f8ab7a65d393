//! Neighbour consistency: a putative match is kept only if the matches around it in the first image
//! move with it into the second image. On repeated structure (a facade of near-identical windows) a
//! keypoint matched to the neighbouring window moves one period further than the matches around it;
//! the fundamental matrix explains both, so RANSAC cannot drop it, but its neighbours can.
//!
//! The rule, the specification every backend follows (integers only, so every backend decides alike):
//! - every keypoint position is taken in sixteenths of a pixel, `round(16 · x)` (an exact `f32`
//!   product, rounded half away from zero: [`f32::round`]); differences and sums below are `i64`;
//! - the **neighbours** of match `m` are the other matches `n` whose first-image keypoints lie within
//!   `radius` of `m`'s: `dxA² + dyA² <= (16 · radius)²`, with `(dxA, dyA) = a(n) − a(m)`;
//! - neighbour `n` **agrees** with `m` when its move differs from `m`'s by at most
//!   `tolerance + |dxA| + |dyA|` scaled by `relative / 16` (L1 norms):
//!   `16 · (|dxB − dxA| + |dyB − dyA|) <= 16 · 16 · tolerance + relative · (|dxA| + |dyA|)`, with
//!   `(dxB, dyB) = b(n) − b(m)`;
//! - `m` is kept when it has fewer than `min_neighbours` neighbours (nothing to judge it by), or when
//!   `100 · agreeing >= min_share_percent · neighbours`.
//!
//! Every match is judged against all the others (not only the kept ones), so the order of the matches
//! does not change the result. It runs on the CPU after matching, before RANSAC; on a GPU it would be
//! one thread per match over the matches of the pair sorted by `x` (the same integer comparisons).

use crate::keypoint::KeyPoint;
use crate::matching::Match;

/// The settings of the neighbour-consistency rule (see the module's documentation for the rule).
///
/// ```
/// use clatch::verify::NeighbourConsistency;
///
/// let rule = NeighbourConsistency::default();
/// assert_eq!((rule.radius, rule.min_share_percent, rule.passes), (160, 20, 2));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct NeighbourConsistency {
    /// Neighbourhood radius in the first image, pixels. Default 160.
    pub radius: u32,
    /// Absolute part of the tolerance on the difference of the moves, pixels (L1). Default 24.
    pub tolerance: u32,
    /// Relative part of the tolerance, sixteenths of the neighbour's offset in the first image (L1).
    /// Default 6 (three eighths).
    pub relative: u32,
    /// Fewest neighbours for the rule to judge a match; below that it is kept. Default 4.
    pub min_neighbours: u32,
    /// Share of agreeing neighbours that keeps a match in the first pass, percent (the putative
    /// matches hold outliers, which agree with nobody). Default 20.
    pub min_share_percent: u32,
    /// Passes: each later one judges the matches the previous kept against each other only (the
    /// outliers gone, a true match's neighbours are mostly true). Default 2.
    pub passes: u32,
    /// Share of agreeing neighbours that keeps a match in the passes after the first, percent.
    /// Default 50.
    pub later_share_percent: u32,
}

impl Default for NeighbourConsistency {
    fn default() -> Self {
        Self {
            radius: 160,
            tolerance: 24,
            relative: 6,
            min_neighbours: 4,
            min_share_percent: 20,
            passes: 2,
            later_share_percent: 50,
        }
    }
}

/// A position in sixteenths of a pixel (exact product, then rounded).
fn fixed(v: f32) -> i64 {
    (v * 16.0).round() as i64
}

impl NeighbourConsistency {
    /// The indices (into `matches`, increasing) of the matches this rule keeps. `matches` must name
    /// keypoints of `keypoints_a` (query) and `keypoints_b` (train) at finite positions.
    pub fn kept(
        &self,
        keypoints_a: &[KeyPoint],
        keypoints_b: &[KeyPoint],
        matches: &[Match],
    ) -> Vec<u32> {
        let at = |k: &KeyPoint| (fixed(k.x), fixed(k.y));
        let a: Vec<(i64, i64)> = matches
            .iter()
            .map(|m| at(&keypoints_a[m.query as usize]))
            .collect();
        let b: Vec<(i64, i64)> = matches
            .iter()
            .map(|m| at(&keypoints_b[m.train as usize]))
            .collect();
        let mut kept: Vec<u32> = (0..matches.len() as u32).collect();
        for pass in 0..self.passes.max(1) {
            let share = if pass == 0 {
                self.min_share_percent
            } else {
                self.later_share_percent
            };
            let pa: Vec<(i64, i64)> = kept.iter().map(|&i| a[i as usize]).collect();
            let pb: Vec<(i64, i64)> = kept.iter().map(|&i| b[i as usize]).collect();
            kept = self
                .pass(&pa, &pb, share)
                .into_iter()
                .map(|i| kept[i as usize])
                .collect();
        }
        kept
    }

    /// One pass: the indices of the matches (first-image positions `a`, second-image `b`, sixteenths
    /// of a pixel) that `min_share_percent` of their neighbours agree with.
    fn pass(&self, a: &[(i64, i64)], b: &[(i64, i64)], min_share_percent: u32) -> Vec<u32> {
        // Sorted by x in the first image, so that each match scans only the band |dxA| <= radius.
        let mut order: Vec<u32> = (0..a.len() as u32).collect();
        order.sort_by_key(|&i| (a[i as usize].0, i));
        let xs: Vec<i64> = order.iter().map(|&i| a[i as usize].0).collect();
        let r = 16 * i64::from(self.radius);
        let tol = 256 * i64::from(self.tolerance);
        let rel = i64::from(self.relative);
        (0..a.len())
            .filter(|&m| {
                let (ax, ay) = a[m];
                let (bx, by) = b[m];
                let first = xs.partition_point(|&x| x < ax - r);
                let last = xs.partition_point(|&x| x <= ax + r);
                let (mut neighbours, mut agreeing) = (0u64, 0u64);
                for &n in &order[first..last] {
                    let n = n as usize;
                    if n == m {
                        continue;
                    }
                    let (dxa, dya) = (a[n].0 - ax, a[n].1 - ay);
                    if dxa * dxa + dya * dya > r * r {
                        continue;
                    }
                    neighbours += 1;
                    let (dxb, dyb) = (b[n].0 - bx, b[n].1 - by);
                    let moved = (dxb - dxa).abs() + (dyb - dya).abs();
                    if 16 * moved <= tol + rel * (dxa.abs() + dya.abs()) {
                        agreeing += 1;
                    }
                }
                neighbours < u64::from(self.min_neighbours)
                    || 100 * agreeing >= u64::from(min_share_percent) * neighbours
            })
            .map(|m| m as u32)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kp(x: f32, y: f32) -> KeyPoint {
        KeyPoint::new(x, y)
    }

    /// One pass, radius 120 px, tolerance 24 px + a quarter of the offset.
    fn one_pass(min_neighbours: u32, min_share_percent: u32) -> NeighbourConsistency {
        NeighbourConsistency {
            radius: 120,
            tolerance: 24,
            relative: 4,
            min_neighbours,
            min_share_percent,
            passes: 1,
            later_share_percent: 50,
        }
    }

    /// A grid of matches moved by (30, 5), with one match moved a period (200 px) further.
    #[test]
    fn a_match_one_period_off_is_dropped_and_the_others_kept() {
        let mut a = Vec::new();
        let mut b = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                let (x, y) = (100.0 + 20.0 * i as f32, 100.0 + 20.0 * j as f32);
                a.push(kp(x, y));
                b.push(kp(x + 30.0, y + 5.0));
            }
        }
        b[45].x += 200.0;
        let matches: Vec<Match> = (0..100)
            .map(|i| Match {
                query: i,
                train: i,
                distance: 0,
            })
            .collect();
        let rule = NeighbourConsistency::default();
        let kept = rule.kept(&a, &b, &matches);
        assert_eq!(kept.len(), 99);
        assert!(!kept.contains(&45));
        // The order of the matches does not change what is kept.
        let reversed: Vec<Match> = matches.iter().rev().copied().collect();
        let kept_reversed: Vec<u32> = rule
            .kept(&a, &b, &reversed)
            .into_iter()
            .map(|i| 99 - i)
            .rev()
            .collect();
        assert_eq!(kept_reversed, kept);
    }

    #[test]
    fn a_shifted_majority_wins_and_isolated_matches_are_kept() {
        // Five matches together, three moved by 0 and two by a period; a sixth far away, with no
        // neighbours, is always kept. At 50 % the three (2 of 4 neighbours agreeing) stay and the two
        // (1 of 4) go; at 60 % even the three fall short.
        let a: Vec<KeyPoint> = (0..5)
            .map(|i| kp(10.0 * i as f32, 0.0))
            .chain([kp(1000.0, 0.0)])
            .collect();
        let mut b = a.clone();
        b[1].x += 250.0;
        b[3].x += 250.0;
        let matches: Vec<Match> = (0..6)
            .map(|i| Match {
                query: i,
                train: i,
                distance: 0,
            })
            .collect();
        assert_eq!(one_pass(2, 50).kept(&a, &b, &matches), vec![0, 2, 4, 5]);
        assert_eq!(one_pass(2, 60).kept(&a, &b, &matches), vec![5]);
        // Too few neighbours for the rule: every match kept.
        let strict = one_pass(5, 50);
        assert_eq!(strict.kept(&a, &b, &matches).len(), 6);
    }

    #[test]
    fn the_bounds_are_inclusive_in_sixteenths_of_a_pixel() {
        // Neighbour exactly at the radius (120 px) counts; its move differs by exactly the tolerance
        // (24 px absolute + 120/4 = 30 px relative = 54 px): it agrees. One sixteenth more: it does not.
        let rule = one_pass(1, 100);
        let a = [kp(0.0, 0.0), kp(120.0, 0.0)];
        let matches = [
            Match {
                query: 0,
                train: 0,
                distance: 0,
            },
            Match {
                query: 1,
                train: 1,
                distance: 0,
            },
        ];
        let b = [kp(0.0, 0.0), kp(120.0 + 54.0, 0.0)];
        assert_eq!(rule.kept(&a, &b, &matches), vec![0, 1]);
        let b = [kp(0.0, 0.0), kp(120.0 + 54.0625, 0.0)];
        assert!(rule.kept(&a, &b, &matches).is_empty());
        // Beyond the radius: no neighbours, both kept.
        let a = [kp(0.0, 0.0), kp(120.0625, 0.0)];
        assert_eq!(rule.kept(&a, &b, &matches), vec![0, 1]);
    }

    #[test]
    fn a_second_pass_judges_the_survivors_only() {
        // Ten matches in a row, all within the radius of each other: 0..6 move by 0, 6..9 by a period,
        // 9 elsewhere (an outlier). First pass at 20 %: a true match has 5 of 9 neighbours agreeing, a
        // shifted one 2 of 9 (22 %): both stay, the outlier (0 of 9) goes. Second pass at 50 % among
        // the nine survivors: the shifted ones have 2 of 8 (25 %) and go, the true ones 5 of 8 stay.
        let a: Vec<KeyPoint> = (0..10).map(|i| kp(5.0 * i as f32, 0.0)).collect();
        let mut b = a.clone();
        for (i, shift) in [(6, 250.0), (7, 250.0), (8, 250.0), (9, -400.0)] {
            b[i].x += shift;
        }
        b[9].y += 300.0;
        let matches: Vec<Match> = (0..10)
            .map(|i| Match {
                query: i,
                train: i,
                distance: 0,
            })
            .collect();
        let first = one_pass(4, 20);
        assert_eq!(
            first.kept(&a, &b, &matches),
            vec![0, 1, 2, 3, 4, 5, 6, 7, 8]
        );
        let two = NeighbourConsistency {
            passes: 2,
            later_share_percent: 50,
            ..first
        };
        assert_eq!(two.kept(&a, &b, &matches), vec![0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn verification_with_the_rule_reports_inliers_by_the_pair_s_match_index() {
        // A 12 x 12 grid moved by (40, 10) in the second image; every seventh match is moved a period
        // (300 px) further. With the rule those never reach RANSAC, and the inliers it reports are the
        // indices of the pair's own matches (each one a true match).
        let mut a = Vec::new();
        let mut b = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                let (x, y) = (
                    100.0 + 31.0 * i as f32 + 0.3 * j as f32,
                    80.0 + 29.0 * j as f32,
                );
                a.push(kp(x, y));
                b.push(kp(x + 40.0 + 0.02 * y, y + 10.0));
            }
        }
        let matches: Vec<Match> = (0..144)
            .map(|i| Match {
                query: i,
                train: i,
                distance: 0,
            })
            .collect();
        for i in (3..144).step_by(7) {
            b[i].x += 300.0;
        }
        let config = crate::verify::VerifyConfig {
            neighbour_consistency: Some(NeighbourConsistency::default()),
            ..Default::default()
        };
        let geometry = crate::verify::verify_pair(&a, &b, &matches, None, &config).unwrap();
        let shifted = |i: u32| i >= 3 && (i - 3).is_multiple_of(7);
        assert!(
            geometry.inliers.iter().all(|&i| !shifted(i)),
            "{:?}",
            geometry.inliers
        );
        assert_eq!(geometry.inliers.len(), 144 - 21);
    }
}
