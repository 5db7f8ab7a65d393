//! Reading back `PREFIX.summary.csv` and `PREFIX.pr.csv` (written by `clatch-eval` or the OpenCV
//! script) to merge them into a run, checked against the run's pairs.

use std::collections::HashMap;
use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::{EvalError, IoContext};
use crate::metrics::RatioPoint;
use crate::pairs::EvalPair;
use crate::results::{
    Fixed, PR_HEADER, PairResult, PrRow, SUMMARY_HEADER, Shortest, SummaryRow, with_suffix,
};

/// The rows of a results CSV, each with its line number, after checking the header.
fn read_rows<T: DeserializeOwned>(path: &Path, header: &str) -> Result<Vec<(u64, T)>, EvalError> {
    let bad = |line, reason: String| EvalError::ResultsFormat {
        path: path.to_path_buf(),
        line,
        reason,
    };
    let file = std::fs::File::open(path).reading(path)?;
    let mut reader = csv::Reader::from_reader(file);
    let headers = reader.headers().map_err(|e| bad(1, e.to_string()))?.clone();
    if headers.iter().collect::<Vec<_>>().join(",") != header {
        return Err(bad(1, format!("the first line must be `{header}`")));
    }
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, csv::Position::line);
            bad(line, e.to_string())
        })?;
        let line = record.position().map_or(0, csv::Position::line);
        let row = record
            .deserialize(Some(&headers))
            .map_err(|e| bad(line, e.to_string()))?;
        rows.push((line, row));
    }
    Ok(rows)
}

/// Reads `PREFIX.summary.csv` and `PREFIX.pr.csv` and checks them against the pairs of this run:
/// every pair known, same group and image sizes, the same ratio thresholds, and the same
/// correct-candidate count in both files.
pub fn read_csv(
    prefix: &Path,
    pairs: &[EvalPair],
    sizes: &HashMap<String, [(u32, u32); 2]>,
    ratios: &[f32],
) -> Result<Vec<PairResult>, EvalError> {
    let summary_path = with_suffix(prefix, ".summary.csv");
    let pr_path = with_suffix(prefix, ".pr.csv");
    let format_error = |path: &Path, line, reason: String| EvalError::ResultsFormat {
        path: path.to_path_buf(),
        line,
        reason,
    };

    let (mut results, mut correct_1nn) = (Vec::new(), Vec::new());
    for (line, row) in read_rows::<SummaryRow<Fixed<4>, Shortest>>(&summary_path, SUMMARY_HEADER)? {
        let path = summary_path.as_path();
        let pair = pairs.iter().find(|p| p.name == row.pair).ok_or_else(|| {
            format_error(
                path,
                line,
                format!("pair `{}` is not in this run", row.pair),
            )
        })?;
        if pair.group != row.group {
            return Err(format_error(
                path,
                line,
                format!(
                    "pair `{}` is in group `{}`, not `{}`",
                    row.pair, pair.group, row.group
                ),
            ));
        }
        let found = [(row.width_a, row.height_a), (row.width_b, row.height_b)];
        let expected = sizes[&pair.name];
        if found != expected {
            return Err(EvalError::SizeMismatch {
                what: format!("pair `{}` in {}", pair.name, path.display()),
                expected: format!("{expected:?}"),
                found: format!("{found:?}"),
            });
        }
        if row.correct > row.matches {
            return Err(format_error(path, line, "more correct than matches".into()));
        }
        results.push(PairResult {
            method: row.method,
            pair: pair.name.clone(),
            group: pair.group.clone(),
            param: pair.param,
            size_a: found[0],
            size_b: found[1],
            keypoints: (row.keypoints_a, row.keypoints_b),
            overlap: (row.overlap_a, row.overlap_b),
            matches: row.matches,
            correct: row.correct,
            // The curve comes from the second file; the count is checked against it.
            curve: Vec::new(),
        });
        correct_1nn.push((line, row.correct_1nn));
    }

    let mut curves: HashMap<(String, String), Vec<RatioPoint>> = HashMap::new();
    for (line, row) in read_rows::<PrRow>(&pr_path, PR_HEADER)? {
        let ratio = row
            .ratio
            .0
            .ok_or_else(|| format_error(&pr_path, line, "the ratio is empty".into()))?;
        let point = RatioPoint {
            ratio,
            kept: row.kept,
            correct_kept: row.correct_kept,
            correct_candidates: row.correct_1nn,
        };
        if point.correct_kept > point.kept.min(point.correct_candidates) {
            return Err(format_error(
                &pr_path,
                line,
                "correct_kept too large".into(),
            ));
        }
        curves
            .entry((row.method, row.pair))
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
    use crate::results::write_csv;

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

    struct Fixture {
        dir: std::path::PathBuf,
        pairs: Vec<EvalPair>,
        sizes: HashMap<String, [(u32, u32); 2]>,
    }

    fn fixture(tag: &str) -> Fixture {
        let dir = std::env::temp_dir().join(format!("clatch-merge-{}-{tag}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pairs = vec![pair("graf 1-2"), pair("graf 1-3")];
        let sizes = pairs
            .iter()
            .map(|p| (p.name.clone(), [(800, 640), (800, 640)]))
            .collect();
        Fixture { dir, pairs, sizes }
    }

    #[test]
    fn written_results_read_back_equal() {
        let f = fixture("round");
        let written = vec![
            PairResult::sample("OpenCV ORB", "graf 1-2"),
            PairResult::sample("OpenCV ORB", "graf 1-3"),
        ];
        let prefix = f.dir.join("opencv");
        write_csv(&written, &prefix).unwrap();
        let read = read_csv(&prefix, &f.pairs, &f.sizes, &[0.5, 1.0]).unwrap();
        assert_eq!(read, written);
        std::fs::remove_dir_all(&f.dir).ok();
    }

    #[test]
    fn bad_results_files_are_typed_errors() {
        let f = fixture("bad");
        let prefix = f.dir.join("x");
        let write = |results: &[PairResult]| write_csv(results, &prefix).unwrap();
        let read = || read_csv(&prefix, &f.pairs, &f.sizes, &[0.5, 1.0]);

        write(&[PairResult::sample("m", "graf 1-9")]);
        assert!(matches!(
            read(),
            Err(EvalError::ResultsFormat { line: 2, .. })
        ));

        write(&[PairResult {
            size_b: (640, 800),
            ..PairResult::sample("m", "graf 1-2")
        }]);
        assert!(matches!(read(), Err(EvalError::SizeMismatch { .. })));

        write(&[PairResult::sample("m", "graf 1-2")]);
        let err = read_csv(&prefix, &f.pairs, &f.sizes, &[0.5, 0.8, 1.0]).unwrap_err();
        assert!(err.to_string().contains("thresholds"), "{err}");

        let summary = f.dir.join("x.summary.csv");
        let good = std::fs::read_to_string(&summary).unwrap();
        let row = good.lines().nth(1).unwrap();
        for (broken, why) in [
            (row.replace(",800,640,800,", ",800,x,800,"), "invalid digit"),
            (row.replacen(",21,", ",31,", 1), "more correct than matches"),
            (row.rsplit_once(',').unwrap().0.to_string(), "fields"),
        ] {
            std::fs::write(&summary, format!("{SUMMARY_HEADER}\n{broken}\n")).unwrap();
            let e = read().unwrap_err();
            assert!(
                matches!(e, EvalError::ResultsFormat { line: 2, .. })
                    && e.to_string().contains(why),
                "{why}: {e}"
            );
        }

        std::fs::write(&summary, "method,pair\n").unwrap();
        assert!(matches!(
            read(),
            Err(EvalError::ResultsFormat { line: 1, .. })
        ));

        std::fs::remove_file(&summary).unwrap();
        assert!(matches!(
            read(),
            Err(EvalError::File {
                access: crate::error::Access::Read,
                ..
            })
        ));
        std::fs::remove_dir_all(&f.dir).ok();
    }
}
