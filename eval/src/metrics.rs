//! The correctness rule of `clatch-eval` and the figures built on it (see EVALUATION.md, which
//! states the same definitions; `scripts/eval_opencv.py` implements them again for OpenCV).
//!
//! - A match (a, b) is **correct** iff `|H(a) - b| <= tolerance` pixels, `H` mapping image A's pixels
//!   to image B's (a point that `H` sends to infinity is never correct).
//! - A keypoint of A is **in the overlap** iff `H(a)` lies inside B (`0 <= x <= width - 1`,
//!   `0 <= y <= height - 1`); a keypoint of B iff `H⁻¹(b)` lies inside A.
//! - **Matching score** = correct matches of the configured matcher / min(keypoints of A in the
//!   overlap, keypoints of B in the overlap) (Mikolajczyk and Schmid, PAMI 2005, use the same ratio).
//! - **Candidates** are the 1-NN matches of every keypoint of A that pass the ratio-independent rules
//!   (cross-check, distance limit) as configured; at ratio `r` a candidate is **kept** iff
//!   `(d1 as f32) < r * (d2 as f32)` (the library's rule). Precision(r) = correct kept / kept;
//!   recall(r) = correct kept / correct candidates.

use clatch::homography::Homography;
use clatch::{KeyPoint, KnnMatches, Match};

/// The ground truth of one pair: the true map from A to B and the two image sizes.
#[derive(Clone, Debug)]
pub struct PairTruth {
    /// Maps pixels of A to pixels of B.
    pub h: Homography,
    /// Maps pixels of B to pixels of A.
    pub h_inv: Homography,
    /// Width and height of A.
    pub size_a: (u32, u32),
    /// Width and height of B.
    pub size_b: (u32, u32),
    /// Largest distance in B, in pixels, at which a match is correct.
    pub tolerance: f64,
}

/// True iff `p` exists and lies inside a `width` x `height` image (pixel centres `0..=size-1`).
pub fn inside(p: Option<(f64, f64)>, (width, height): (u32, u32)) -> bool {
    p.is_some_and(|(x, y)| {
        (0.0..=width as f64 - 1.0).contains(&x) && (0.0..=height as f64 - 1.0).contains(&y)
    })
}

impl PairTruth {
    /// The truth for `h`; `None` if `h` is singular.
    pub fn new(
        h: Homography,
        size_a: (u32, u32),
        size_b: (u32, u32),
        tolerance: f64,
    ) -> Option<Self> {
        Some(Self {
            h_inv: h.inverse()?,
            h,
            size_a,
            size_b,
            tolerance,
        })
    }

    /// Whether matching A's keypoint `a` to B's keypoint `b` is correct.
    pub fn is_correct(&self, a: &KeyPoint, b: &KeyPoint) -> bool {
        self.h.transfer_error(a, b) <= self.tolerance
    }

    /// How many keypoints of A and of B lie in the overlap.
    pub fn overlap(&self, kps_a: &[KeyPoint], kps_b: &[KeyPoint]) -> (usize, usize) {
        let a = kps_a
            .iter()
            .filter(|k| inside(self.h.apply(k.x as f64, k.y as f64), self.size_b))
            .count();
        let b = kps_b
            .iter()
            .filter(|k| inside(self.h_inv.apply(k.x as f64, k.y as f64), self.size_a))
            .count();
        (a, b)
    }
}

/// A 1-NN match of one query with its second-nearest distance, checked against the truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Distance to the nearest neighbour.
    pub d1: u32,
    /// Distance to the second-nearest neighbour.
    pub d2: u32,
    /// Whether the nearest neighbour is a correct match.
    pub correct: bool,
}

/// The library's ratio test: kept iff `d1 < ratio * d2`, one correctly rounded `f32` product.
pub fn passes_ratio(d1: u32, d2: u32, ratio: f32) -> bool {
    (d1 as f32) < ratio * d2 as f32
}

/// The candidates among 2-NN lists (`knn.k() == 2`): a query's nearest neighbour stays if `keep`
/// accepts it (cross-check, distance limit); `correct` judges it.
pub fn candidates(
    knn: &KnnMatches,
    keep: impl Fn(&Match) -> bool,
    correct: impl Fn(&Match) -> bool,
) -> Vec<Candidate> {
    knn.iter()
        .filter(|n| keep(&n[0]))
        .map(|n| Candidate {
            d1: n[0].distance,
            d2: n[1].distance,
            correct: correct(&n[0]),
        })
        .collect()
}

/// What the ratio test keeps at one threshold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RatioPoint {
    /// The threshold.
    pub ratio: f32,
    /// Candidates kept.
    pub kept: usize,
    /// Correct candidates kept.
    pub correct_kept: usize,
    /// Correct candidates at all (the recall's denominator).
    pub correct_candidates: usize,
}

impl RatioPoint {
    /// Correct kept / kept; `None` when nothing is kept.
    pub fn precision(&self) -> Option<f64> {
        (self.kept > 0).then(|| self.correct_kept as f64 / self.kept as f64)
    }

    /// Correct kept / correct candidates; `None` when no candidate is correct.
    pub fn recall(&self) -> Option<f64> {
        (self.correct_candidates > 0)
            .then(|| self.correct_kept as f64 / self.correct_candidates as f64)
    }
}

/// The thresholds of the precision-recall curves: 0.50, 0.55, ..., 1.00, each the `f32` nearest to
/// its decimal value (as `--ratio 0.55` parses).
pub fn ratio_grid() -> Vec<f32> {
    (0..=10).map(|i| (50 + 5 * i) as f32 / 100.0).collect()
}

/// Precision and recall of the ratio test at each threshold.
pub fn ratio_curve(candidates: &[Candidate], ratios: &[f32]) -> Vec<RatioPoint> {
    let correct_candidates = candidates.iter().filter(|c| c.correct).count();
    ratios
        .iter()
        .map(|&ratio| {
            let kept = candidates
                .iter()
                .filter(|c| passes_ratio(c.d1, c.d2, ratio));
            let (kept, correct_kept) =
                kept.fold((0, 0), |(k, ck), c| (k + 1, ck + usize::from(c.correct)));
            RatioPoint {
                ratio,
                kept,
                correct_kept,
                correct_candidates,
            }
        })
        .collect()
}

/// Correct matches / min(overlap of A, overlap of B); `None` when either overlap is empty.
pub fn matching_score(correct: usize, (overlap_a, overlap_b): (usize, usize)) -> Option<f64> {
    let denominator = overlap_a.min(overlap_b);
    (denominator > 0).then(|| correct as f64 / denominator as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth(h: Homography) -> PairTruth {
        PairTruth::new(h, (100, 50), (80, 60), 3.0).unwrap()
    }

    #[test]
    fn correctness_is_distance_to_the_projection() {
        // Scale by 2 about the origin: (10, 5) goes to (20, 10).
        let t = truth(Homography::rotation_scale(0.0, 2.0));
        let a = KeyPoint::new(10.0, 5.0);
        assert!(t.is_correct(&a, &KeyPoint::new(20.0, 10.0)));
        // 3-4-5 triangle: exactly 5 px away is wrong at 3 px, right at 5 px.
        let off = KeyPoint::new(23.0, 14.0);
        assert!(!t.is_correct(&a, &off));
        assert!(
            PairTruth {
                tolerance: 5.0,
                ..t.clone()
            }
            .is_correct(&a, &off)
        );
        // Exactly at the tolerance counts as correct: 3 px along x.
        assert!(t.is_correct(&a, &KeyPoint::new(23.0, 10.0)));
        // Perspective: w = 1 + 0.01 x; (100, 0) -> (50, 0); (-100, 0) goes to infinity.
        let p = truth(Homography::perspective(0.01, 0.0));
        assert!(p.is_correct(&KeyPoint::new(100.0, 0.0), &KeyPoint::new(50.0, 0.0)));
        assert!(!p.is_correct(&KeyPoint::new(-100.0, 0.0), &KeyPoint::new(0.0, 0.0)));
    }

    #[test]
    fn overlap_counts_both_sides() {
        // A is 100x50, B is 80x60; H shifts by (+30, +20). A's (0..=49, 0..=39) lands in B;
        // B's (30..=79, 20..=59) comes from A.
        let t = truth(Homography::translation(30.0, 20.0));
        let kps_a = [
            KeyPoint::new(0.0, 0.0),   // -> (30, 20): inside
            KeyPoint::new(49.0, 39.0), // -> (79, 59): the last pixel, inside
            KeyPoint::new(49.5, 10.0), // -> (79.5, 30): outside
            KeyPoint::new(10.0, 40.0), // -> (40, 60): outside
        ];
        let kps_b = [
            KeyPoint::new(30.0, 20.0), // <- (0, 0): inside
            KeyPoint::new(29.0, 30.0), // <- (-1, 10): outside
            KeyPoint::new(79.0, 59.0), // <- (49, 39): inside
        ];
        assert_eq!(t.overlap(&kps_a, &kps_b), (2, 2));
        assert_eq!(t.overlap(&[], &kps_b[1..2]), (0, 0));
        assert!(inside(Some((0.0, 0.0)), (1, 1)));
        assert!(!inside(Some((0.0, -0.001)), (1, 1)));
        assert!(!inside(None, (10, 10)));
    }

    #[test]
    fn matching_score_uses_the_smaller_overlap() {
        assert_eq!(matching_score(3, (10, 6)), Some(0.5));
        assert_eq!(matching_score(3, (4, 12)), Some(0.75));
        assert_eq!(matching_score(0, (0, 12)), None);
    }

    #[test]
    fn grid_is_the_decimal_thresholds() {
        let grid = ratio_grid();
        assert_eq!(grid.len(), 11);
        assert_eq!(grid[0], 0.5);
        assert_eq!(grid[6], "0.8".parse::<f32>().unwrap());
        assert_eq!(grid[10], 1.0);
    }

    #[test]
    fn precision_and_recall_by_hand() {
        let c = |d1, d2, correct| Candidate { d1, d2, correct };
        // Ratios d1/d2: 0.2 (correct), 0.5 (correct), 0.75 (wrong), 0.9 (correct), 1.0 (wrong).
        let candidates = [
            c(10, 50, true),
            c(20, 40, true),
            c(30, 40, false),
            c(45, 50, true),
            c(60, 60, false),
        ];
        let curve = ratio_curve(&candidates, &[0.5, 0.8, 0.95, 1.0]);
        let got: Vec<(usize, usize)> = curve.iter().map(|p| (p.kept, p.correct_kept)).collect();
        // 0.5: only 0.2 (0.5 is not < 0.5); 0.8: 0.2, 0.5, 0.75; 0.95 and 1.0: all but the tie.
        assert_eq!(got, vec![(1, 1), (3, 2), (4, 3), (4, 3)]);
        assert_eq!(curve[0].precision(), Some(1.0));
        assert_eq!(curve[0].recall(), Some(1.0 / 3.0));
        assert_eq!(curve[1].precision(), Some(2.0 / 3.0));
        assert_eq!(curve[1].recall(), Some(2.0 / 3.0));
        assert_eq!(curve[3].precision(), Some(0.75));
        assert_eq!(curve[3].recall(), Some(1.0));
        let empty = ratio_curve(&[c(5, 5, false)], &[0.5]);
        assert_eq!((empty[0].precision(), empty[0].recall()), (None, None));
    }

    #[test]
    fn ratio_rule_is_the_librarys() {
        // 0.8 as f32 is a little above 0.8, but 0.8f32 * 5 rounds to exactly 4: d1 = 4 is not kept.
        assert!(!passes_ratio(4, 5, 0.8));
        assert!(passes_ratio(3, 5, 0.8));
        assert!(!passes_ratio(7, 7, 1.0));
    }

    #[test]
    fn candidates_filter_and_judge() {
        let m = |query, train, distance| Match {
            query,
            train,
            distance,
        };
        let knn = KnnMatches::new(
            2,
            vec![
                m(0, 3, 5),
                m(0, 1, 9),
                m(1, 2, 4),
                m(1, 0, 6),
                m(2, 3, 1),
                m(2, 2, 2),
            ],
        )
        .expect("whole queries");
        // Keep queries whose nearest train is not 2; call train 3 correct.
        let got = candidates(&knn, |n| n.train != 2, |n| n.train == 3);
        assert_eq!(
            got,
            vec![
                Candidate {
                    d1: 5,
                    d2: 9,
                    correct: true
                },
                Candidate {
                    d1: 1,
                    d2: 2,
                    correct: true
                },
            ]
        );
    }
}
