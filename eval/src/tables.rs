//! The tables of `clatch-eval`, as aligned text (stdout) and as Markdown (EVALUATION.md).

use std::fmt::Write as _;

use crate::metrics::RatioPoint;
use crate::results::PairResult;

/// A table of strings; the first column is left-aligned, the others right-aligned.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Column titles.
    pub header: Vec<String>,
    /// Rows, each as long as the header.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// Aligned plain text, two spaces between columns, indented by two.
    pub fn to_text(&self) -> String {
        let widths: Vec<usize> = (0..self.header.len())
            .map(|c| {
                std::iter::once(&self.header)
                    .chain(&self.rows)
                    .map(|r| r[c].chars().count())
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        let mut s = String::new();
        for row in std::iter::once(&self.header).chain(&self.rows) {
            s.push(' ');
            for (c, (cell, w)) in row.iter().zip(&widths).enumerate() {
                if c == 0 {
                    let _ = write!(s, " {cell:<w$}");
                } else {
                    let _ = write!(s, "  {cell:>w$}");
                }
            }
            s.push('\n');
        }
        s
    }

    /// A GitHub Markdown table.
    pub fn to_markdown(&self) -> String {
        let line = |cells: &[String]| format!("| {} |\n", cells.join(" | "));
        let mut s = line(&self.header);
        let rule: Vec<String> = (0..self.header.len())
            .map(|c| if c == 0 { "---".into() } else { "---:".into() })
            .collect();
        s.push_str(&line(&rule));
        for row in &self.rows {
            s.push_str(&line(row));
        }
        s
    }
}

fn fraction(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.3}"))
}

fn strings(cells: &[&str]) -> Vec<String> {
    cells.iter().map(|c| c.to_string()).collect()
}

/// The distinct values of `key` in order of first appearance.
pub fn distinct(results: &[PairResult], key: impl Fn(&PairResult) -> &str) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    for r in results {
        if !seen.iter().any(|s| s == key(r)) {
            seen.push(key(r).to_string());
        }
    }
    seen
}

/// The methods in order of first appearance.
pub fn methods(results: &[PairResult]) -> Vec<String> {
    distinct(results, |r| &r.method)
}

/// One row a method for one pair: counts, precision, matching score, correct 1-NN candidates.
pub fn pair_table(results: &[&PairResult]) -> Table {
    let header = strings(&[
        "method",
        "kp A",
        "kp B",
        "overlap A",
        "overlap B",
        "matches",
        "correct",
        "precision",
        "match. score",
        "correct 1-NN",
    ]);
    let rows = results
        .iter()
        .map(|r| {
            vec![
                r.method.clone(),
                r.keypoints.0.to_string(),
                r.keypoints.1.to_string(),
                r.overlap.0.to_string(),
                r.overlap.1.to_string(),
                r.matches.to_string(),
                r.correct.to_string(),
                fraction(r.precision()),
                fraction(r.matching_score()),
                r.correct_candidates().to_string(),
            ]
        })
        .collect();
    Table { header, rows }
}

/// One row a threshold: precision and recall of each method's ratio test on `curves`.
pub fn ratio_table(curves: &[(String, Vec<RatioPoint>)]) -> Table {
    let mut header = vec!["ratio".to_string()];
    for (method, _) in curves {
        header.push(format!("{method} P"));
        header.push(format!("{method} R"));
    }
    let thresholds = curves.first().map_or(0, |(_, c)| c.len());
    let rows = (0..thresholds)
        .map(|i| {
            let mut row = vec![format!("{:.2}", curves[0].1[i].ratio)];
            for (_, curve) in curves {
                row.push(fraction(curve[i].precision()));
                row.push(fraction(curve[i].recall()));
            }
            row
        })
        .collect();
    Table { header, rows }
}

/// One row a pair, one column a method: `correct (matching score)`.
pub fn all_pairs_table(results: &[PairResult]) -> Table {
    let methods = methods(results);
    let mut header = vec!["pair".to_string()];
    header.extend(methods.iter().cloned());
    let rows = distinct(results, |r| &r.pair)
        .iter()
        .map(|pair| {
            let mut row = vec![pair.to_string()];
            for m in &methods {
                let cell = results
                    .iter()
                    .find(|r| r.pair == *pair && r.method == *m)
                    .map_or("-".into(), |r| {
                        format!("{} ({})", r.correct, fraction(r.matching_score()))
                    });
                row.push(cell);
            }
            row
        })
        .collect();
    Table { header, rows }
}

/// Sums the curves of several pairs threshold by threshold (the pooled, micro-averaged curve).
pub fn pooled_curve(results: &[&PairResult]) -> Vec<RatioPoint> {
    let Some(first) = results.first() else {
        return Vec::new();
    };
    let mut pooled: Vec<RatioPoint> = first
        .curve
        .iter()
        .map(|p| RatioPoint {
            kept: 0,
            correct_kept: 0,
            correct_candidates: 0,
            ..*p
        })
        .collect();
    for r in results {
        for (sum, p) in pooled.iter_mut().zip(&r.curve) {
            sum.kept += p.kept;
            sum.correct_kept += p.correct_kept;
            sum.correct_candidates += p.correct_candidates;
        }
    }
    pooled
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(
        method: &str,
        pair: &str,
        correct: usize,
        ratio_points: &[(usize, usize)],
    ) -> PairResult {
        PairResult {
            keypoints: (8, 9),
            overlap: (4, 5),
            curve: ratio_points
                .iter()
                .zip([0.5f32, 1.0])
                .map(|(&(kept, correct_kept), ratio)| RatioPoint {
                    ratio,
                    kept,
                    correct_kept,
                    correct_candidates: 4,
                })
                .collect(),
            ..PairResult::for_test(method, pair, "g", 3, correct)
        }
    }

    #[test]
    fn text_and_markdown() {
        let t = Table {
            header: strings(&["name", "n"]),
            rows: vec![strings(&["a", "10"]), strings(&["bcd", "7"])],
        };
        assert_eq!(t.to_text(), "  name   n\n  a     10\n  bcd    7\n");
        assert_eq!(
            t.to_markdown(),
            "| name | n |\n| --- | ---: |\n| a | 10 |\n| bcd | 7 |\n"
        );
    }

    #[test]
    fn tables_from_results() {
        let results = vec![
            result("clatch", "p1", 2, &[(1, 1), (3, 2)]),
            result("OpenCV ORB", "p1", 1, &[(2, 1), (5, 3)]),
            result("clatch", "p2", 0, &[(0, 0), (1, 0)]),
        ];
        assert_eq!(methods(&results), ["clatch", "OpenCV ORB"]);
        let all = all_pairs_table(&results);
        assert_eq!(all.header, ["pair", "clatch", "OpenCV ORB"]);
        // Matching score: correct / min(4, 5).
        assert_eq!(all.rows[0], ["p1", "2 (0.500)", "1 (0.250)"]);
        assert_eq!(all.rows[1], ["p2", "0 (0.000)", "-"]);

        let detail = pair_table(&[&results[0]]);
        assert_eq!(
            detail.rows[0],
            [
                "clatch", "8", "9", "4", "5", "3", "2", "0.667", "0.500", "4"
            ]
        );

        let pooled = pooled_curve(&[&results[0], &results[2]]);
        assert_eq!(
            pooled
                .iter()
                .map(|p| (p.kept, p.correct_kept, p.correct_candidates))
                .collect::<Vec<_>>(),
            [(1, 1, 8), (4, 2, 8)]
        );
        let ratios = ratio_table(&[("clatch".into(), pooled)]);
        assert_eq!(ratios.header, ["ratio", "clatch P", "clatch R"]);
        assert_eq!(ratios.rows[1], ["1.00", "0.500", "0.250"]);
        assert!(pooled_curve(&[]).is_empty());
    }
}
