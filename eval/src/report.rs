//! The report of a run: the charts' panels and the tables, from the results of every method.

use crate::chart::{PrPanel, SweepPanel};
use crate::pairs::{EvalPair, GROUP_BLUR, GROUP_NOISE, GROUP_ROTATION, GROUP_SCALE};
use crate::results::PairResult;
use crate::sequences;
use crate::tables::{self, Table, methods, pooled_curve};

/// The precision-recall panels: the headline pair, the Oxford pairs pooled, the synthetic pairs
/// pooled (each only if present).
pub fn pr_panels(results: &[PairResult], headline: Option<&EvalPair>) -> Vec<PrPanel> {
    let methods = methods(results);
    let panel = |title: String, keep: &dyn Fn(&PairResult) -> bool| {
        let curves: Vec<_> = methods
            .iter()
            .map(|m| {
                let of_method: Vec<&PairResult> = results
                    .iter()
                    .filter(|r| r.method == *m && keep(r))
                    .collect();
                (m.clone(), pooled_curve(&of_method))
            })
            .filter(|(_, c)| !c.is_empty())
            .collect();
        (!curves.is_empty()).then_some(PrPanel { title, curves })
    };
    let count = |keep: &dyn Fn(&PairResult) -> bool| {
        let kept: Vec<PairResult> = results.iter().filter(|r| keep(r)).cloned().collect();
        tables::distinct(&kept, |r| &r.pair).len()
    };
    let on_disk = |r: &PairResult| sequences::is_sequence_group(&r.group);
    let synthetic = |r: &PairResult| r.group.starts_with("synthetic-");
    let mut panels = Vec::new();
    if let Some(h) = headline {
        panels.extend(panel(h.name.clone(), &|r| r.pair == h.name));
    }
    panels.extend(panel(
        format!(
            "{}: {} pairs pooled",
            sequence_title(results),
            count(&on_disk)
        ),
        &on_disk,
    ));
    panels.extend(panel(
        format!("synthetic pairs: {} pairs pooled", count(&synthetic)),
        &synthetic,
    ));
    panels
}

/// The sequences read from disk, by name when few (`sequences graf, boat, bikes`), else counted.
fn sequence_title(results: &[PairResult]) -> String {
    let groups = tables::distinct(results, |r| &r.group);
    let names: Vec<&str> = groups
        .iter()
        .filter_map(|g| sequences::sequence_of_group(g))
        .collect();
    if names.len() <= 4 {
        format!("sequences {}", names.join(", "))
    } else {
        format!("{} sequences", names.len())
    }
}

/// Mean matching score of each method against the synthetic parameter of `group`.
pub fn sweep_series(results: &[PairResult], group: &str) -> Vec<(String, Vec<(f64, f64)>)> {
    methods(results)
        .into_iter()
        .map(|m| {
            let mut by_param: Vec<(f64, Vec<f64>)> = Vec::new();
            for r in results.iter().filter(|r| r.method == m && r.group == group) {
                let (Some(p), Some(score)) = (r.param, r.matching_score()) else {
                    continue;
                };
                match by_param.iter_mut().find(|(q, _)| *q == p) {
                    Some((_, scores)) => scores.push(score),
                    None => by_param.push((p, vec![score])),
                }
            }
            by_param.sort_by(|a, b| a.0.total_cmp(&b.0));
            let points = by_param
                .into_iter()
                .map(|(p, s)| (p, s.iter().sum::<f64>() / s.len() as f64))
                .collect();
            (m, points)
        })
        .filter(|(_, points): &(String, Vec<(f64, f64)>)| !points.is_empty())
        .collect()
}

/// One row a group: pairs, and per method the total of correct matches and the mean matching score.
pub fn group_table(results: &[PairResult]) -> Table {
    let methods = methods(results);
    let mut header = vec!["group".to_string(), "pairs".to_string()];
    header.extend(methods.iter().map(|m| format!("{m}: correct (mean m.s.)")));
    let rows = tables::distinct(results, |r| &r.group)
        .iter()
        .map(|g| {
            let pairs = results
                .iter()
                .filter(|r| r.group == *g && r.method == methods[0])
                .count();
            let mut row = vec![g.to_string(), pairs.to_string()];
            for m in &methods {
                let of: Vec<&PairResult> = results
                    .iter()
                    .filter(|r| r.group == *g && r.method == *m)
                    .collect();
                let correct: usize = of.iter().map(|r| r.correct).sum();
                let scores: Vec<f64> = of.iter().filter_map(|r| r.matching_score()).collect();
                let mean = if scores.is_empty() {
                    "-".into()
                } else {
                    format!("{:.3}", scores.iter().sum::<f64>() / scores.len() as f64)
                };
                row.push(format!("{correct} ({mean})"));
            }
            row
        })
        .collect();
    Table { header, rows }
}

/// The parameter sweeps of the synthetic pairs that are present: mean matching score of each
/// method against rotation, scale, noise and blur.
pub fn sweep_panels(results: &[PairResult]) -> Vec<SweepPanel> {
    [
        (
            GROUP_ROTATION,
            "rotation (degrees)",
            "synthetic rotation, scale 1",
        ),
        (GROUP_SCALE, "scale factor", "synthetic scale, no rotation"),
        (
            GROUP_NOISE,
            "noise sigma (gray levels)",
            "synthetic Gaussian noise, no warp",
        ),
        (
            GROUP_BLUR,
            "blur sigma (pixels)",
            "synthetic Gaussian blur, no warp",
        ),
    ]
    .into_iter()
    .map(|(group, x_label, title)| SweepPanel {
        title: title.into(),
        x_label: x_label.into(),
        y_label: "matching score (mean over photos)".into(),
        series: sweep_series(results, group),
    })
    .filter(|p| !p.series.is_empty())
    .collect()
}

/// The report's tables, titled: the headline pair in detail, then every pair, then the groups.
pub fn sections(results: &[PairResult], headline: Option<&EvalPair>) -> Vec<(String, Table)> {
    let mut sections = Vec::new();
    if let Some(h) = headline {
        let of_pair: Vec<&PairResult> = results.iter().filter(|r| r.pair == h.name).collect();
        sections.push((
            format!(
                "{} (A: {}, B: {})",
                h.name,
                h.image_a.display(),
                h.image_b.display()
            ),
            tables::pair_table(&of_pair),
        ));
        let curves = of_pair
            .iter()
            .map(|r| (r.method.clone(), r.curve.clone()))
            .collect::<Vec<_>>();
        sections.push((
            format!("{}: ratio test, precision P and recall R", h.name),
            tables::ratio_table(&curves),
        ));
    }
    sections.push((
        "every pair: correct matches (matching score)".into(),
        tables::all_pairs_table(results),
    ));
    sections.push(("by group".into(), group_table(results)));
    sections
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::RatioPoint;

    fn result(
        method: &str,
        pair: &str,
        group: &str,
        param: Option<f64>,
        correct: usize,
    ) -> PairResult {
        PairResult {
            param,
            overlap: (10, 8),
            curve: vec![RatioPoint {
                ratio: 0.8,
                kept: 10,
                correct_kept: correct,
                correct_candidates: 10,
            }],
            ..PairResult::for_test(method, pair, group, 10, correct)
        }
    }

    #[test]
    fn panels_pool_by_family_and_count_pairs_once() {
        let mut results = Vec::new();
        for method in ["clatch", "OpenCV ORB"] {
            results.push(result(method, "graf 1-2", "oxford-graf", None, 4));
            results.push(result(method, "boat 1-2", "oxford-boat", None, 6));
            results.push(result(method, "a rot 15", GROUP_ROTATION, Some(15.0), 8));
        }
        let panels = pr_panels(&results, None);
        let titles: Vec<&str> = panels.iter().map(|p| p.title.as_str()).collect();
        assert_eq!(
            titles,
            [
                "sequences graf, boat: 2 pairs pooled",
                "synthetic pairs: 1 pairs pooled"
            ]
        );
        assert_eq!(panels[0].curves[1].0, "OpenCV ORB");
        assert_eq!(panels[0].curves[1].1[0].correct_kept, 10);
        assert_eq!(panels[0].curves[1].1[0].correct_candidates, 20);

        // Sweep: mean matching score (correct / min(10, 8)) per parameter.
        results.push(result("clatch", "b rot 15", GROUP_ROTATION, Some(15.0), 4));
        let sweep = sweep_series(&results, GROUP_ROTATION);
        assert_eq!(sweep[0], ("clatch".to_string(), vec![(15.0, 0.75)]));
        assert_eq!(sweep[1], ("OpenCV ORB".to_string(), vec![(15.0, 1.0)]));

        let groups = group_table(&results);
        assert_eq!(
            groups.rows[2],
            ["synthetic-rotation", "2", "12 (0.750)", "8 (1.000)"]
        );
    }
}
