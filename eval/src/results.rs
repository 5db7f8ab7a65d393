//! Per-pair results of one method, and their files: `PREFIX.summary.csv` (one row a pair) and
//! `PREFIX.pr.csv` (one row a pair and ratio threshold), written through serde. The JSON file with
//! everything is [`crate::json`]; `scripts/eval_opencv.py` writes the same two CSV files, which
//! [`crate::merge`] reads back.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize, Serializer};

use crate::error::{EvalError, IoContext};
use crate::metrics::{RatioPoint, matching_score};

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

    /// A result of an 800x640 pair (100 and 90 keypoints, 80 and 70 in the overlap, 21 of 30 matches
    /// correct) with a two-threshold curve (0.5: 5 of 5 kept; 1.0: 25 of 40; 28 correct 1-NN).
    #[cfg(test)]
    pub fn sample(method: &str, pair: &str) -> Self {
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

/// Header of `PREFIX.summary.csv`: the fields of [`SummaryRow`], in order.
pub const SUMMARY_HEADER: &str = "method,pair,group,param,width_a,height_a,width_b,height_b,\
    keypoints_a,keypoints_b,overlap_a,overlap_b,matches,correct,correct_1nn,precision,matching_score";
/// Header of `PREFIX.pr.csv`: the fields of [`PrRow`], in order.
pub const PR_HEADER: &str = "method,pair,ratio,kept,correct_kept,correct_1nn,precision,recall";

/// A number written with `DECIMALS` decimals, as the OpenCV script writes it, and read as any
/// number; an empty field when there is none.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(transparent)]
pub struct Fixed<const DECIMALS: usize, T = f64>(pub Option<T>);

impl<const DECIMALS: usize, T: std::fmt::Display> Serialize for Fixed<DECIMALS, T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match &self.0 {
            Some(v) => serializer.serialize_str(&format!("{v:.DECIMALS$}")),
            None => serializer.serialize_str(""),
        }
    }
}

/// A synthetic pair's parameter as Rust prints it (`0`, `1.15`), as the manifest hands it to the
/// OpenCV script; read as any number; an empty field for none.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(transparent)]
pub struct Shortest(pub Option<f64>);

impl Serialize for Shortest {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&self.0.map(|v| v.to_string()).unwrap_or_default())
    }
}

/// One row of `PREFIX.summary.csv`; `F` and `P` are how the fractions and the parameter are written
/// ([`Fixed`] and [`Shortest`] in the CSV file, plain numbers in the JSON file).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SummaryRow<F, P> {
    pub method: String,
    pub pair: String,
    pub group: String,
    pub param: P,
    pub width_a: u32,
    pub height_a: u32,
    pub width_b: u32,
    pub height_b: u32,
    pub keypoints_a: usize,
    pub keypoints_b: usize,
    pub overlap_a: usize,
    pub overlap_b: usize,
    pub matches: usize,
    pub correct: usize,
    pub correct_1nn: usize,
    pub precision: F,
    pub matching_score: F,
}

/// One row of `PREFIX.pr.csv`: one method on one pair at one ratio threshold.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PrRow {
    pub method: String,
    pub pair: String,
    pub ratio: Fixed<2, f32>,
    pub kept: usize,
    pub correct_kept: usize,
    pub correct_1nn: usize,
    pub precision: Fixed<4>,
    pub recall: Fixed<4>,
}

impl PairResult {
    /// The summary row, the fractions made by `fraction` and the parameter by `param`.
    pub fn summary_row<F, P>(
        &self,
        fraction: impl Fn(Option<f64>) -> F,
        param: impl FnOnce(Option<f64>) -> P,
    ) -> SummaryRow<F, P> {
        SummaryRow {
            method: self.method.clone(),
            pair: self.pair.clone(),
            group: self.group.clone(),
            param: param(self.param),
            width_a: self.size_a.0,
            height_a: self.size_a.1,
            width_b: self.size_b.0,
            height_b: self.size_b.1,
            keypoints_a: self.keypoints.0,
            keypoints_b: self.keypoints.1,
            overlap_a: self.overlap.0,
            overlap_b: self.overlap.1,
            matches: self.matches,
            correct: self.correct,
            correct_1nn: self.correct_candidates(),
            precision: fraction(self.precision()),
            matching_score: fraction(self.matching_score()),
        }
    }

    /// The rows of the thresholds file.
    fn pr_rows(&self) -> impl Iterator<Item = PrRow> + '_ {
        self.curve.iter().map(|p| PrRow {
            method: self.method.clone(),
            pair: self.pair.clone(),
            ratio: Fixed(Some(p.ratio)),
            kept: p.kept,
            correct_kept: p.correct_kept,
            correct_1nn: p.correct_candidates,
            precision: Fixed(p.precision()),
            recall: Fixed(p.recall()),
        })
    }
}

/// `prefix` with `suffix` added to its file name (`out/opencv` and `.pr.csv`: `out/opencv.pr.csv`).
pub fn with_suffix(prefix: &Path, suffix: &str) -> PathBuf {
    let mut name = OsString::from(prefix.as_os_str());
    name.push(suffix);
    PathBuf::from(name)
}

/// Writes `rows` to `path` as CSV under a header line of their field names.
pub fn write_rows<T: Serialize>(
    path: &Path,
    rows: impl IntoIterator<Item = T>,
) -> Result<(), EvalError> {
    let written = || -> csv::Result<()> {
        let mut writer = csv::Writer::from_path(path)?;
        for row in rows {
            writer.serialize(row)?;
        }
        Ok(writer.flush()?)
    };
    written().map_err(std::io::Error::from).writing(path)
}

/// Writes `PREFIX.summary.csv` and `PREFIX.pr.csv`; returns their paths.
pub fn write_csv(results: &[PairResult], prefix: &Path) -> Result<[PathBuf; 2], EvalError> {
    let paths = [".summary.csv", ".pr.csv"].map(|suffix| with_suffix(prefix, suffix));
    write_rows(
        &paths[0],
        results.iter().map(|r| r.summary_row(Fixed::<4>, Shortest)),
    )?;
    write_rows(&paths[1], results.iter().flat_map(PairResult::pr_rows))?;
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_files_have_the_scripts_columns_and_number_formats() {
        let dir = std::env::temp_dir().join(format!("clatch-results-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let written = [
            PairResult::sample("OpenCV ORB", "graf 1-2"),
            PairResult {
                param: Some(0.0),
                ..PairResult::sample("OpenCV ORB", "a rot 0")
            },
        ];
        let [summary, pr] = write_csv(&written, &dir.join("opencv")).unwrap();
        assert_eq!(summary, dir.join("opencv.summary.csv"));
        let summary = std::fs::read_to_string(&summary).unwrap();
        let lines: Vec<&str> = summary.lines().collect();
        assert_eq!(lines[0], SUMMARY_HEADER);
        // precision 21/30, matching score 21/min(80, 70); no parameter is an empty field.
        assert_eq!(
            lines[1],
            "OpenCV ORB,graf 1-2,oxford-graf,,800,640,800,640,100,90,80,70,30,21,28,0.7000,0.3000"
        );
        assert!(
            lines[2].starts_with("OpenCV ORB,a rot 0,oxford-graf,0,800,"),
            "{}",
            lines[2]
        );
        let pr = std::fs::read_to_string(pr).unwrap();
        let lines: Vec<&str> = pr.lines().collect();
        assert_eq!(lines[0], PR_HEADER);
        assert_eq!(lines[1], "OpenCV ORB,graf 1-2,0.50,5,5,28,1.0000,0.1786");
        assert_eq!(lines[2], "OpenCV ORB,graf 1-2,1.00,40,25,28,0.6250,0.8929");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_opencv_script_writes_the_same_columns() {
        let script = include_str!("../scripts/eval_opencv.py");
        assert!(script.contains(&format!("SUMMARY_HEADER = \"{SUMMARY_HEADER}\"")));
        assert!(script.contains(&format!("PR_HEADER = \"{PR_HEADER}\"")));
    }
}
