//! Checking matches against a ground-truth homography, and the printed summary of a run.

use std::fmt::Write as _;
use std::time::Duration;

use clatch::homography::Homography;
use clatch::{Backend, KeyPoint, Match, MatchConfig};

use clatch_cli::flags::describe_matching;

use crate::draw::MatchClass;
use crate::pipeline::PairRun;

/// How well matches agree with a ground-truth homography.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation {
    /// Largest reprojection error of an inlier, in pixels.
    pub tolerance: f64,
    /// Per match: inlier or outlier.
    pub classes: Vec<MatchClass>,
    /// Number of inliers.
    pub inliers: usize,
    /// Mean reprojection error of the inliers (0 when there are none).
    pub mean_error: f64,
    /// Median reprojection error of the inliers (0 when there are none).
    pub median_error: f64,
}

impl Evaluation {
    /// Inliers over matches (0 when there are no matches).
    pub fn inlier_fraction(&self) -> f64 {
        if self.classes.is_empty() {
            0.0
        } else {
            self.inliers as f64 / self.classes.len() as f64
        }
    }
}

/// Classifies each match: inlier iff its reprojection error under `h` (mapping query pixels to train
/// pixels) is at most `tolerance` pixels.
pub fn evaluate(
    matches: &[Match],
    query: &[KeyPoint],
    train: &[KeyPoint],
    h: &Homography,
    tolerance: f64,
) -> Evaluation {
    let mut errors = Vec::new();
    let classes = matches
        .iter()
        .map(|m| {
            let e = h.transfer_error(&query[m.query as usize], &train[m.train as usize]);
            if e <= tolerance {
                errors.push(e);
                MatchClass::Inlier
            } else {
                MatchClass::Outlier
            }
        })
        .collect();
    let inliers = errors.len();
    let mean_error = if inliers == 0 {
        0.0
    } else {
        errors.iter().sum::<f64>() / inliers as f64
    };
    errors.sort_by(f64::total_cmp);
    let median_error = match inliers {
        0 => 0.0,
        n if n % 2 == 1 => errors[n / 2],
        n => (errors[n / 2 - 1] + errors[n / 2]) / 2.0,
    };
    Evaluation {
        tolerance,
        classes,
        inliers,
        mean_error,
        median_error,
    }
}

/// The report's `set-up` line, with the time of each step of a GPU's set-up (none for the CPU).
pub fn print_set_up_steps(backend: Backend) {
    if let Some(steps) = backend.set_up_steps() {
        println!("  {:<12}{steps}", "set-up");
    }
}

/// Milliseconds with two decimals.
pub fn ms(d: Duration) -> String {
    format!("{:.2} ms", d.as_secs_f64() * 1e3)
}

/// `count` items over `wall` as a rate, e.g. `412.3 images/s`.
pub fn per_second(count: usize, wall: Duration, what: &str) -> String {
    let seconds = wall.as_secs_f64();
    if seconds > 0.0 {
        format!("{:.1} {what}/s", count as f64 / seconds)
    } else {
        format!("{count} {what}")
    }
}

/// The decoders' side of an extraction, e.g. `12.40 ms summed over 2 decoding thread(s); extraction
/// waited 1.05 ms for it`.
pub fn decoding(decoding: &clatch::prefetch::Prefetched) -> String {
    format!(
        "{} summed over {} decoding thread(s); extraction waited {} for it",
        ms(decoding.produce),
        decoding.threads,
        ms(decoding.waited)
    )
}

/// The summary table of a pair run: sizes, keypoints, stage times, matches and (with ground truth)
/// inliers. Image A is the query side, B the gallery.
pub fn pair_summary(
    run: &PairRun,
    sizes: [(u32, u32); 2],
    config: &MatchConfig,
    evaluation: Option<&Evaluation>,
) -> String {
    let mut s = String::new();
    let (a, b) = (&run.a, &run.b);
    let row = |s: &mut String, name: &str, va: String, vb: String| {
        let _ = writeln!(s, "  {name:<12}{va:>12}{vb:>12}");
    };
    let _ = writeln!(s, "  {:<12}{}", "backend", run.backend);
    row(&mut s, "", "A".into(), "B".into());
    row(
        &mut s,
        "size",
        format!("{}x{}", sizes[0].0, sizes[0].1),
        format!("{}x{}", sizes[1].0, sizes[1].1),
    );
    row(
        &mut s,
        "keypoints",
        a.features.keypoints.len().to_string(),
        b.features.keypoints.len().to_string(),
    );
    // Description timed apart only when it ran apart; otherwise one row says what it covers.
    match (a.describe, b.describe) {
        (Some(da), Some(db)) => {
            row(&mut s, "detect", ms(a.detect), ms(b.detect));
            row(&mut s, "describe", ms(da), ms(db));
        }
        _ => row(&mut s, "detect+desc", ms(a.detect), ms(b.detect)),
    }
    let _ = writeln!(
        s,
        "  {:<12}{:>12}   ({} x {} descriptors of {} bits; {})",
        "match",
        ms(run.matching),
        a.features.descriptors.len(),
        b.features.descriptors.len(),
        a.features.descriptors.width().bits(),
        describe_matching(config),
    );
    let total = a.detect
        + a.describe.unwrap_or_default()
        + b.detect
        + b.describe.unwrap_or_default()
        + run.matching;
    let _ = writeln!(s, "  {:<12}{:>12}", "total", ms(total));
    let _ = writeln!(s, "  {:<12}{:>12}", "matches", run.matches.len());
    if let Some(reason) = &run.skipped {
        let _ = writeln!(s, "  {:<12}matching skipped: {reason}", "");
    }
    if let Some(e) = evaluation {
        let _ = writeln!(
            s,
            "  {:<12}{:>12}   ({:.1} % of matches within {} px of the true homography)",
            "inliers",
            e.inliers,
            100.0 * e.inlier_fraction(),
            e.tolerance,
        );
        if e.inliers > 0 {
            let _ = writeln!(
                s,
                "  {:<12}{:>12}   (inliers; median {:.2} px)",
                "reproj. err",
                format!("{:.2} px", e.mean_error),
                e.median_error,
            );
        }
    }
    s
}

/// The line saying where the picture of the matches went and how to read it.
pub fn picture_written(
    path: &std::path::Path,
    (width, height): (u32, u32),
    matches: usize,
    max_lines: usize,
    legend: &str,
) -> String {
    format!(
        "  {:<12}{} ({width}x{height}; lines for {} of {matches} matches; {legend}; \
         unmatched keypoints blue)",
        "wrote",
        path.display(),
        matches.min(max_lines),
    )
}

#[cfg(test)]
mod rate_tests {
    use super::*;

    #[test]
    fn rates() {
        assert_eq!(
            per_second(30, Duration::from_millis(1500), "images"),
            "20.0 images/s"
        );
        assert_eq!(per_second(3, Duration::ZERO, "pairs"), "3 pairs");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evaluation_counts_and_statistics() {
        let query = [
            KeyPoint::new(10.0, 10.0),
            KeyPoint::new(20.0, 20.0),
            KeyPoint::new(30.0, 30.0),
        ];
        // Truth: shift by (+5, 0). Errors: 0, 2, 10.
        let train = [
            KeyPoint::new(15.0, 10.0),
            KeyPoint::new(25.0, 22.0),
            KeyPoint::new(45.0, 30.0),
        ];
        let matches: Vec<Match> = (0..3)
            .map(|i| Match {
                query: i,
                train: i,
                distance: 0,
            })
            .collect();
        let h = Homography::translation(5.0, 0.0);
        let e = evaluate(&matches, &query, &train, &h, 3.0);
        assert_eq!(
            e.classes,
            vec![MatchClass::Inlier, MatchClass::Inlier, MatchClass::Outlier]
        );
        assert_eq!(e.inliers, 2);
        assert!((e.inlier_fraction() - 2.0 / 3.0).abs() < 1e-12);
        assert!((e.mean_error - 1.0).abs() < 1e-12);
        assert!((e.median_error - 1.0).abs() < 1e-12);

        let none = evaluate(&[], &query, &train, &h, 3.0);
        assert_eq!(
            (none.inliers, none.inlier_fraction(), none.mean_error),
            (0, 0.0, 0.0)
        );
    }

    #[test]
    fn a_point_sent_to_infinity_is_an_outlier() {
        let h = Homography::perspective(0.5, 0.0);
        let infinite = Match {
            query: 0,
            train: 0,
            distance: 0,
        };
        let e = evaluate(
            &[infinite],
            &[KeyPoint::new(-2.0, 0.0)],
            &[KeyPoint::new(0.0, 0.0)],
            &h,
            1e9,
        );
        assert_eq!(e.classes, [MatchClass::Outlier]);
    }
}
