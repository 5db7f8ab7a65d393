//! A folder run's report as the dictionary `clatch.colmap.MatchFolderResult` is built from.

use clatch::colmap::FolderReport;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// `database`, `match_list`, `images`, `keypoints`, `pairs`, `matches`, `pairs_with_matches`,
/// `pairs_verified`, `pairs_with_inliers`, `inliers` and `stage_seconds` (`set_up`, `extraction`,
/// `decoding` (summed over the decoding threads), `matching`, `verification`, `writing`; zero for
/// what ran in other processes).
pub fn report_out<'py>(py: Python<'py>, report: &FolderReport) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let counts = &report.counts;
    out.set_item("database", &report.database)?;
    out.set_item("match_list", &report.match_list)?;
    out.set_item("images", counts.photos)?;
    out.set_item("keypoints", counts.keypoints)?;
    out.set_item("pairs", counts.pairs)?;
    out.set_item("matches", counts.matches)?;
    out.set_item("pairs_with_matches", counts.pairs_with_matches)?;
    out.set_item("pairs_verified", counts.pairs_verified)?;
    out.set_item("pairs_with_inliers", counts.pairs_with_inliers)?;
    out.set_item("inliers", counts.inliers)?;
    let times = &report.times;
    let seconds = PyDict::new(py);
    for (stage, time) in [
        ("set_up", times.set_up),
        ("extraction", times.extraction),
        ("decoding", times.decoding.produce),
        ("matching", times.matching),
        ("verification", times.verification),
        ("writing", times.writing),
    ] {
        seconds.set_item(stage, time.as_secs_f64())?;
    }
    out.set_item("stage_seconds", seconds)?;
    Ok(out)
}
