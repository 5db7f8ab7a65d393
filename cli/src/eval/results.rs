//! Per-pair results of one method, and their files: `PREFIX.summary.csv` (one row a pair),
//! `PREFIX.pr.csv` (one row a pair and ratio threshold) and one JSON file with everything.
//! `tools/eval_opencv.py` writes the same two CSV files, which `clatch eval` reads back to merge.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::CliError;
use crate::eval::metrics::{RatioPoint, matching_score};
use crate::eval::pairs::EvalPair;

/// The figures of one method on one pair.
#[derive(Clone, Debug, PartialEq)]
pub struct PairResult {
    /// Method label (a column of the tables), e.g. `clatch`, `OpenCV SIFT`.
    pub method: String,
    /// Pair name.
    pub pair: String,
    /// Pair group.
    pub group: String,
    /// Varied parameter of a synthetic pair.
    pub param: Option<f64>,
    /// Width and height of A.
    pub size_a: (u32, u32),
    /// Width and height of B.
    pub size_b: (u32, u32),
    /// Keypoints with a descriptor in A and in B.
    pub keypoints: (usize, usize),
    /// Of those, in the overlap (see `metrics`).
    pub overlap: (usize, usize),
    /// Matches the configured matcher kept.
    pub matches: usize,
    /// Of those, correct.
    pub correct: usize,
    /// Ratio test at each threshold of the grid.
    pub curve: Vec<RatioPoint>,
}

impl PairResult {
    /// A result with the given counts and a one-threshold curve (ratio 0.8, everything kept), for
    /// tests to adjust with struct update syntax.
    #[cfg(test)]
    pub fn for_test(method: &str, pair: &str, group: &str, matches: usize, correct: usize) -> Self {
        Self {
            method: method.into(),
            pair: pair.into(),
            group: group.into(),
            param: None,
            size_a: (10, 10),
            size_b: (10, 10),
            keypoints: (matches, matches),
            overlap: (matches, matches),
            matches,
            correct,
            curve: vec![RatioPoint {
                ratio: 0.8,
                kept: matches,
                correct_kept: correct,
                correct_candidates: correct,
            }],
        }
    }

    /// Correct 1-NN candidates (the recall's denominator).
    pub fn correct_candidates(&self) -> usize {
        self.curve.first().map_or(0, |p| p.correct_candidates)
    }

    /// Correct / matches; `None` without matches.
    pub fn precision(&self) -> Option<f64> {
        (self.matches > 0).then(|| self.correct as f64 / self.matches as f64)
    }

    /// See [`matching_score`].
    pub fn matching_score(&self) -> Option<f64> {
        matching_score(self.correct, self.overlap)
    }
}

/// Header of `PREFIX.summary.csv`.
pub const SUMMARY_HEADER: &str = "method,pair,group,param,width_a,height_a,width_b,height_b,\
    keypoints_a,keypoints_b,overlap_a,overlap_b,matches,correct,correct_1nn,precision,matching_score";
/// Header of `PREFIX.pr.csv`.
pub const PR_HEADER: &str = "method,pair,ratio,kept,correct_kept,correct_1nn,precision,recall";

/// One value of a results row, written as CSV or as JSON.
enum Field {
    Text(String),
    Count(usize),
    Real(Option<f64>),
    /// A fraction: 4 decimals in CSV.
    Fraction(Option<f64>),
    /// A ratio threshold of the grid: two decimals (0.55), as the script writes it.
    Ratio(f32),
}

impl Field {
    fn csv(&self) -> String {
        match self {
            Field::Text(t) => t.clone(),
            Field::Count(n) => n.to_string(),
            Field::Real(v) => v.map(|v| v.to_string()).unwrap_or_default(),
            Field::Fraction(v) => v.map(|v| format!("{v:.4}")).unwrap_or_default(),
            Field::Ratio(r) => format!("{r:.2}"),
        }
    }

    fn json(&self) -> String {
        match self {
            Field::Text(t) => json_string(t),
            Field::Count(n) => n.to_string(),
            Field::Real(v) | Field::Fraction(v) => v
                .filter(|v| v.is_finite())
                .map_or("null".into(), |v| v.to_string()),
            Field::Ratio(r) => format!("{r:.2}"),
        }
    }
}

/// The values of a summary row, in [`SUMMARY_HEADER`] order.
fn summary_fields(r: &PairResult) -> Vec<Field> {
    use Field::{Count, Fraction, Real, Text};
    vec![
        Text(r.method.clone()),
        Text(r.pair.clone()),
        Text(r.group.clone()),
        Real(r.param),
        Count(r.size_a.0 as usize),
        Count(r.size_a.1 as usize),
        Count(r.size_b.0 as usize),
        Count(r.size_b.1 as usize),
        Count(r.keypoints.0),
        Count(r.keypoints.1),
        Count(r.overlap.0),
        Count(r.overlap.1),
        Count(r.matches),
        Count(r.correct),
        Count(r.correct_candidates()),
        Fraction(r.precision()),
        Fraction(r.matching_score()),
    ]
}

/// The values of a threshold row, in [`PR_HEADER`] order.
fn pr_fields(r: &PairResult, p: &RatioPoint) -> Vec<Field> {
    use Field::{Count, Fraction, Ratio, Text};
    vec![
        Text(r.method.clone()),
        Text(r.pair.clone()),
        Ratio(p.ratio),
        Count(p.kept),
        Count(p.correct_kept),
        Count(p.correct_candidates),
        Fraction(p.precision()),
        Fraction(p.recall()),
    ]
}

fn csv_line(fields: &[Field]) -> String {
    let cells: Vec<String> = fields.iter().map(Field::csv).collect();
    cells.join(",") + "\n"
}

/// A JSON object with `header`'s names as keys, leaving out those in `skip`.
fn json_object(header: &str, fields: &[Field], skip: &[&str]) -> String {
    let members: Vec<String> = header
        .split(',')
        .zip(fields)
        .filter(|(name, _)| !skip.contains(name))
        .map(|(name, f)| format!("\"{name}\": {}", f.json()))
        .collect();
    format!("{{{}}}", members.join(", "))
}

/// Both CSV files' text.
pub fn to_csv(results: &[PairResult]) -> (String, String) {
    let (mut summary, mut pr) = (format!("{SUMMARY_HEADER}\n"), format!("{PR_HEADER}\n"));
    for r in results {
        summary.push_str(&csv_line(&summary_fields(r)));
        for p in &r.curve {
            pr.push_str(&csv_line(&pr_fields(r, p)));
        }
    }
    (summary, pr)
}

/// Writes `PREFIX.summary.csv` and `PREFIX.pr.csv`; returns their paths.
pub fn write_csv(results: &[PairResult], prefix: &Path) -> Result<[PathBuf; 2], CliError> {
    let (summary, pr) = to_csv(results);
    let paths = [
        crate::extract::with_suffix(prefix, ".summary.csv"),
        crate::extract::with_suffix(prefix, ".pr.csv"),
    ];
    for (path, text) in paths.iter().zip([summary, pr]) {
        crate::output::write_file(path, |w| std::io::Write::write_all(w, text.as_bytes()))?;
    }
    Ok(paths)
}

fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Everything as one JSON document: the settings that decide correctness, then one object a result
/// with the summary file's columns as keys and its thresholds under `ratio_test`.
pub fn to_json(results: &[PairResult], tolerance: f64, settings: &str) -> String {
    let mut s = format!(
        "{{\n  \"tolerance_px\": {tolerance},\n  \"clatch_settings\": {},\n  \"results\": [",
        json_string(settings)
    );
    for (i, r) in results.iter().enumerate() {
        let curve: Vec<String> = r
            .curve
            .iter()
            .map(|p| {
                json_object(
                    PR_HEADER,
                    &pr_fields(r, p),
                    &["method", "pair", "correct_1nn"],
                )
            })
            .collect();
        let summary = json_object(SUMMARY_HEADER, &summary_fields(r), &[]);
        let _ = write!(
            s,
            "{}\n    {}, \"ratio_test\": [{}]}}",
            if i == 0 { "" } else { "," },
            &summary[..summary.len() - 1],
            curve.join(", "),
        );
    }
    s.push_str("\n  ]\n}\n");
    s
}

/// Reads a results CSV into rows of fields, checking the header.
fn read_rows(path: &Path, header: &str) -> Result<Vec<(usize, Vec<String>)>, CliError> {
    let text = std::fs::read_to_string(path).map_err(|source| CliError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let bad = |line, reason: String| CliError::ResultsFormat {
        path: path.to_path_buf(),
        line,
        reason,
    };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, first)) if first.trim_end() == header => {}
        _ => return Err(bad(1, format!("the first line must be `{header}`"))),
    }
    let columns = header.split(',').count();
    lines
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            let fields: Vec<String> = l.trim_end().split(',').map(str::to_string).collect();
            if fields.len() == columns {
                Ok((i + 1, fields))
            } else {
                Err(bad(
                    i + 1,
                    format!("{} fields, expected {columns}", fields.len()),
                ))
            }
        })
        .collect()
}

/// Reads `PREFIX.summary.csv` and `PREFIX.pr.csv` (written by `clatch eval` or the OpenCV script)
/// and checks them against the pairs of this run: every pair known, same group and image sizes, the
/// same ratio thresholds, and the same correct-candidate count in both files.
pub fn read_csv(
    prefix: &Path,
    pairs: &[EvalPair],
    sizes: &HashMap<String, [(u32, u32); 2]>,
    ratios: &[f32],
) -> Result<Vec<PairResult>, CliError> {
    let summary_path = crate::extract::with_suffix(prefix, ".summary.csv");
    let pr_path = crate::extract::with_suffix(prefix, ".pr.csv");
    let format_error = |path: &Path, line, reason: String| CliError::ResultsFormat {
        path: path.to_path_buf(),
        line,
        reason,
    };
    let number = |path: &Path, line, field: &str| -> Result<usize, CliError> {
        field
            .parse()
            .map_err(|_| format_error(path, line, format!("`{field}` is not a count")))
    };

    let (mut results, mut correct_1nn) = (Vec::new(), Vec::new());
    for (line, f) in read_rows(&summary_path, SUMMARY_HEADER)? {
        let path = summary_path.as_path();
        let pair = pairs.iter().find(|p| p.name == f[1]).ok_or_else(|| {
            format_error(path, line, format!("pair `{}` is not in this run", f[1]))
        })?;
        if pair.group != f[2] {
            return Err(format_error(
                path,
                line,
                format!(
                    "pair `{}` is in group `{}`, not `{}`",
                    f[1], pair.group, f[2]
                ),
            ));
        }
        let n: Vec<usize> = f[4..15]
            .iter()
            .map(|v| number(path, line, v))
            .collect::<Result<_, _>>()?;
        let found = [(n[0] as u32, n[1] as u32), (n[2] as u32, n[3] as u32)];
        let expected = sizes[&pair.name];
        if found != expected {
            return Err(CliError::SizeMismatch {
                what: format!("pair `{}` in {}", pair.name, path.display()),
                expected: format!("{:?}", expected),
                found: format!("{:?}", found),
            });
        }
        results.push(PairResult {
            method: f[0].clone(),
            pair: pair.name.clone(),
            group: pair.group.clone(),
            param: pair.param,
            size_a: found[0],
            size_b: found[1],
            keypoints: (n[4], n[5]),
            overlap: (n[6], n[7]),
            matches: n[8],
            correct: n[9],
            // The curve comes from the second file; the count is checked against it.
            curve: Vec::new(),
        });
        if n[9] > n[8] {
            return Err(format_error(path, line, "more correct than matches".into()));
        }
        correct_1nn.push((line, n[10]));
    }

    let mut curves: HashMap<(String, String), Vec<RatioPoint>> = HashMap::new();
    for (line, f) in read_rows(&pr_path, PR_HEADER)? {
        let path = pr_path.as_path();
        let ratio: f32 = f[2]
            .parse()
            .map_err(|_| format_error(path, line, format!("`{}` is not a ratio", f[2])))?;
        let point = RatioPoint {
            ratio,
            kept: number(path, line, &f[3])?,
            correct_kept: number(path, line, &f[4])?,
            correct_candidates: number(path, line, &f[5])?,
        };
        if point.correct_kept > point.kept.min(point.correct_candidates) {
            return Err(format_error(path, line, "correct_kept too large".into()));
        }
        curves
            .entry((f[0].clone(), f[1].clone()))
            .or_default()
            .push(point);
    }
    for (r, (line, correct_1nn)) in results.iter_mut().zip(correct_1nn) {
        let curve = curves
            .remove(&(r.method.clone(), r.pair.clone()))
            .unwrap_or_default();
        let thresholds: Vec<f32> = curve.iter().map(|p| p.ratio).collect();
        if thresholds != ratios {
            return Err(format_error(
                &pr_path,
                0,
                format!(
                    "{} on `{}`: thresholds {thresholds:?}, expected {ratios:?}",
                    r.method, r.pair
                ),
            ));
        }
        r.curve = curve;
        if r.correct_candidates() != correct_1nn {
            return Err(format_error(
                &summary_path,
                line,
                format!(
                    "correct_1nn is {correct_1nn}, the thresholds file says {}",
                    r.correct_candidates()
                ),
            ));
        }
    }
    if let Some((method, pair)) = curves.keys().next() {
        return Err(format_error(
            &pr_path,
            0,
            format!("{method} on `{pair}` has no row in the summary file"),
        ));
    }
    Ok(results)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(name: &str) -> EvalPair {
        EvalPair {
            name: name.into(),
            group: "oxford-graf".into(),
            param: None,
            image_a: "a.ppm".into(),
            image_b: "b.ppm".into(),
            homography: "H".into(),
        }
    }

    fn result(method: &str, pair: &str) -> PairResult {
        PairResult {
            size_a: (800, 640),
            size_b: (800, 640),
            keypoints: (100, 90),
            overlap: (80, 70),
            curve: [(0.5f32, 5, 5), (1.0, 40, 25)]
                .iter()
                .map(|&(ratio, kept, correct_kept)| RatioPoint {
                    ratio,
                    kept,
                    correct_kept,
                    correct_candidates: 28,
                })
                .collect(),
            ..PairResult::for_test(method, pair, "oxford-graf", 30, 21)
        }
    }

    struct Fixture {
        dir: PathBuf,
        pairs: Vec<EvalPair>,
        sizes: HashMap<String, [(u32, u32); 2]>,
    }

    fn fixture(tag: &str) -> Fixture {
        let dir = std::env::temp_dir().join(format!("clatch-results-{}-{tag}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pairs = vec![pair("graf 1-2"), pair("graf 1-3")];
        let sizes = pairs
            .iter()
            .map(|p| (p.name.clone(), [(800, 640), (800, 640)]))
            .collect();
        Fixture { dir, pairs, sizes }
    }

    #[test]
    fn csv_round_trip_and_derived_columns() {
        let f = fixture("round");
        let written = vec![
            result("OpenCV ORB", "graf 1-2"),
            result("OpenCV ORB", "graf 1-3"),
        ];
        let prefix = f.dir.join("opencv");
        write_csv(&written, &prefix).unwrap();
        let summary = std::fs::read_to_string(f.dir.join("opencv.summary.csv")).unwrap();
        // precision 21/30, matching score 21/min(80, 70).
        assert!(
            summary
                .lines()
                .nth(1)
                .unwrap()
                .ends_with(",21,28,0.7000,0.3000")
        );
        let pr = std::fs::read_to_string(f.dir.join("opencv.pr.csv")).unwrap();
        assert_eq!(
            pr.lines().nth(2).unwrap(),
            "OpenCV ORB,graf 1-2,1.00,40,25,28,0.6250,0.8929"
        );
        let read = read_csv(&prefix, &f.pairs, &f.sizes, &[0.5, 1.0]).unwrap();
        assert_eq!(read, written);
        let json = to_json(&read, 3.0, "cpu");
        assert!(json.contains("\"matching_score\": 0.3,"), "{json}");
        assert!(json.contains("{\"ratio\": 0.50, \"kept\": 5, \"correct_kept\": 5, \"precision\": 1, \"recall\": 0.17857142857142858}"));
        std::fs::remove_dir_all(&f.dir).ok();
    }

    #[test]
    fn the_opencv_script_writes_the_same_columns() {
        let script = include_str!("../../../tools/eval_opencv.py");
        assert!(script.contains(&format!("SUMMARY_HEADER = \"{SUMMARY_HEADER}\"")));
        assert!(script.contains(&format!("PR_HEADER = \"{PR_HEADER}\"")));
    }

    #[test]
    fn bad_results_files_are_typed_errors() {
        let f = fixture("bad");
        let prefix = f.dir.join("x");
        let write = |results: &[PairResult]| write_csv(results, &prefix).unwrap();
        let read = || read_csv(&prefix, &f.pairs, &f.sizes, &[0.5, 1.0]);

        write(&[result("m", "graf 1-9")]);
        assert!(matches!(
            read(),
            Err(CliError::ResultsFormat { line: 2, .. })
        ));

        write(&[PairResult {
            size_b: (640, 800),
            ..result("m", "graf 1-2")
        }]);
        assert!(matches!(read(), Err(CliError::SizeMismatch { .. })));

        write(&[result("m", "graf 1-2")]);
        let err = read_csv(&prefix, &f.pairs, &f.sizes, &[0.5, 0.8, 1.0]).unwrap_err();
        assert!(err.to_string().contains("thresholds"), "{err}");

        let summary = f.dir.join("x.summary.csv");
        std::fs::write(&summary, "method,pair\n").unwrap();
        assert!(matches!(
            read(),
            Err(CliError::ResultsFormat { line: 1, .. })
        ));

        std::fs::remove_file(&summary).unwrap();
        assert!(matches!(read(), Err(CliError::Read { .. })));
        std::fs::remove_dir_all(&f.dir).ok();
    }
}
