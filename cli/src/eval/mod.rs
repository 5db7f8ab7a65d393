//! `clatch eval`: descriptor quality on image pairs with ground-truth homographies (homography
//! sequences in the Oxford or HPatches layout, OpenCV's graf sample, synthetic warps, noise and
//! blur), with OpenCV's LATCH, ORB and SIFT beside clatch through `tools/eval_opencv.py`. The definitions are in [`metrics`] and EVALUATION.md.

pub mod chart;
pub mod degrade;
pub mod metrics;
pub mod pairs;
pub mod results;
pub mod run;
pub mod sequences;
pub mod tables;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::CliError;
use crate::progress::Progress;
use crate::{EvalArgs, settings};
use chart::{PrPanel, SweepPanel};
use metrics::ratio_grid;
use pairs::{EvalPair, GROUP_BLUR, GROUP_NOISE, GROUP_OPENCV_SAMPLE, GROUP_ROTATION, GROUP_SCALE};
use results::PairResult;
use tables::{Table, methods, pooled_curve};

/// The pair whose figures head the report: OpenCV's graf1/graf3 if given, else Oxford graf 1-3.
pub fn headline(pairs: &[EvalPair]) -> Option<&EvalPair> {
    let by_group = pairs.iter().find(|p| p.group == GROUP_OPENCV_SAMPLE);
    by_group.or_else(|| pairs.iter().find(|p| p.name == "graf 1-3"))
}

/// Every pair this run evaluates; synthetic images are written under `out/pairs`.
fn collect_pairs(args: &EvalArgs) -> Result<(Vec<EvalPair>, Vec<String>), CliError> {
    let mut pairs = Vec::new();
    let mut notes = Vec::new();
    if let Some(dir) = &args.opencv_samples {
        pairs.push(pairs::opencv_sample_pair(dir)?);
    }
    for data in &args.data {
        let (found, skipped) = sequences::sequences_under(data)?;
        pairs.extend(found);
        notes.extend(skipped.into_iter().map(|d| {
            format!(
                "skipped {}: no img1.* or 1.* (not a sequence folder)",
                d.display()
            )
        }));
    }
    if !args.no_synthetic {
        let mut sources = vec![pairs::SyntheticSource {
            name: "astronaut".into(),
            image: crate::demo::embedded_image()?,
        }];
        for arg in &args.synthetic_images {
            sources.push(pairs::synthetic_source(arg)?);
        }
        for (i, s) in sources.iter().enumerate() {
            if sources[..i].iter().any(|t| t.name == s.name) {
                return Err(CliError::EvalInput {
                    path: PathBuf::from(&s.name),
                    reason: "two synthetic sources share this name; give one as NAME=PATH".into(),
                });
            }
        }
        let dir = args.out.join("pairs");
        for source in &sources {
            pairs.extend(pairs::write_synthetic(source, &dir)?);
        }
    }
    if let Some(twice) = repeated_name(&pairs) {
        return Err(CliError::EvalInput {
            path: twice.image_a.clone(),
            reason: format!(
                "two pairs are named `{}` (two sequence folders with one name?); \
                 pair names must be unique",
                twice.name
            ),
        });
    }
    if pairs.is_empty() {
        return Err(CliError::EvalInput {
            path: args.out.clone(),
            reason:
                "no pairs to evaluate (give --data, --opencv-samples, or allow synthetic pairs)"
                    .into(),
        });
    }
    Ok((pairs, notes))
}

/// The first pair whose name an earlier pair already has: results are told apart by pair name.
fn repeated_name(pairs: &[EvalPair]) -> Option<&EvalPair> {
    let mut seen = std::collections::HashSet::new();
    pairs.iter().find(|p| !seen.insert(p.name.as_str()))
}

/// Runs the OpenCV script on the manifest; its results go to `prefix`.summary.csv / .pr.csv.
fn run_opencv_script(
    args: &EvalArgs,
    python: &Path,
    manifest: &Path,
    prefix: &Path,
) -> Result<(), CliError> {
    let mut command = Command::new(python);
    command
        .arg(&args.opencv_script)
        .arg("--manifest")
        .arg(manifest)
        .arg("--out")
        .arg(prefix)
        .arg("--inlier-px")
        .arg(args.check.inlier_px.to_string())
        .arg("--max-keypoints")
        .arg(
            (args.detect.max_keypoints)
                .unwrap_or(clatch::ExtractorConfig::default().detector.max_keypoints)
                .to_string(),
        );
    // The same matcher rules; the distance limit is in Hamming bits and has no SIFT counterpart.
    match args.matching.config().ratio {
        Some(ratio) => command.arg("--ratio").arg(ratio.to_string()),
        None => command.arg("--no-ratio"),
    };
    if args.matching.no_cross_check {
        command.arg("--no-cross-check");
    }
    let shown = format!("{command:?}");
    let status = command.status().map_err(|e| CliError::Script {
        command: shown.clone(),
        reason: e.to_string(),
    })?;
    if status.success() {
        Ok(())
    } else {
        Err(CliError::Script {
            command: shown,
            reason: status.to_string(),
        })
    }
}

/// The precision-recall panels: the headline pair, the Oxford pairs pooled, the synthetic pairs
/// pooled (each only if present).
fn pr_panels(results: &[PairResult], headline: Option<&EvalPair>) -> Vec<PrPanel> {
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
fn sweep_series(results: &[PairResult], group: &str) -> Vec<(String, Vec<(f64, f64)>)> {
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
fn group_table(results: &[PairResult]) -> Table {
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

/// Writes a text output through a temporary file renamed into place.
fn write_text(path: &std::path::Path, text: &str) -> Result<(), CliError> {
    crate::output::write_file(path, |w| std::io::Write::write_all(w, text.as_bytes()))
}

/// Runs `clatch eval`.
pub fn main(args: &EvalArgs) -> Result<(), CliError> {
    let subpixel = args.subpixel.library();
    let from_flags = settings(&args.backend, &args.detect, subpixel, Some(&args.matching))?;
    let (methods_run, methods_note) =
        run::methods_to_run(&args.methods, args.detect.pyramid.is_some())?;
    std::fs::create_dir_all(&args.out).map_err(CliError::write(&args.out))?;
    let (pairs, mut notes) = collect_pairs(args)?;
    notes.extend(methods_note);
    let manifest_path = args.out.join("pairs.csv");
    let manifest = pairs::manifest(&pairs)?;
    write_text(&manifest_path, &manifest)?;
    let ratios = ratio_grid();
    let tolerance = args.check.inlier_px;

    let progress = Progress::new(pairs.len() as u64);
    progress.stage("evaluating pairs with clatch");
    let mut results = Vec::new();
    let mut sizes = HashMap::new();
    for pair in &pairs {
        let loaded = run::load_pair(pair, tolerance)?;
        sizes.insert(
            pair.name.clone(),
            [loaded.a.dimensions(), loaded.b.dimensions()],
        );
        for &method in &methods_run {
            results.push(run::evaluate_pair(method, &from_flags, &loaded, &ratios)?);
        }
        progress.done();
    }
    progress.finish();
    let clatch_prefix = args.out.join("clatch");
    let mut written = results::write_csv(&results, &clatch_prefix)?.to_vec();

    let mut merges = args.merge.clone();
    if let Some(python) = &args.opencv_python {
        let prefix = args.out.join("opencv");
        eprintln!(
            "clatch eval: running {} on {} pairs",
            args.opencv_script.display(),
            pairs.len()
        );
        run_opencv_script(args, python, &manifest_path, &prefix)?;
        merges.push(prefix);
    }
    for prefix in &merges {
        for merged in results::read_csv(prefix, &pairs, &sizes, &ratios)? {
            if results
                .iter()
                .any(|r| r.method == merged.method && r.pair == merged.pair)
            {
                return Err(CliError::ResultsFormat {
                    path: prefix.clone(),
                    line: 0,
                    reason: format!(
                        "{} on `{}` is already in this run",
                        merged.method, merged.pair
                    ),
                });
            }
            results.push(merged);
        }
    }

    let mut setting_text = format!(
        "{}; FAST threshold {}, at most {} keypoints, {} bits; {}",
        from_flags.backend,
        args.detect.threshold,
        from_flags.extractor.detector.max_keypoints,
        args.detect.bits,
        crate::report::describe_matching(&from_flags.matching),
    );
    if methods_run.contains(&run::ClatchMethod::ClatchOpencv) {
        setting_text.push_str(&format!(
            "; {}: the same keypoints, OpenCV-compatible LATCH (64 bytes, rotation invariance, \
             half_ssd_size 3, sigma 2)",
            run::ClatchMethod::ClatchOpencv.label()
        ));
    }
    let json_path = args.out.join("results.json");
    write_text(
        &json_path,
        &results::to_json(&results, tolerance, &setting_text),
    )?;
    written.push(json_path);

    let methods = methods(&results);
    let headline = headline(&pairs);
    let pr_path = args.out.join("pr.png");
    chart::pr_chart(&pr_path, &methods, &pr_panels(&results, headline))?;
    written.push(pr_path);
    let sweeps: Vec<SweepPanel> = [
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
        series: sweep_series(&results, group),
    })
    .filter(|p| !p.series.is_empty())
    .collect();
    if !sweeps.is_empty() {
        let sweep_path = args.out.join("synthetic.png");
        chart::sweep_chart(&sweep_path, &methods, &sweeps)?;
        written.push(sweep_path);
    }

    // The report: the headline pair in detail, then every pair, then the groups.
    let mut sections: Vec<(String, Table)> = Vec::new();
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
        tables::all_pairs_table(&results),
    ));
    sections.push(("by group".into(), group_table(&results)));

    let mut markdown = String::new();
    println!(
        "clatch eval ({} pairs; correct = within {tolerance} px of the true homography)",
        pairs.len()
    );
    println!("  clatch      {setting_text}");
    for note in &notes {
        println!("  note        {note}");
    }
    for (title, table) in &sections {
        println!("\n  {title}");
        print!("{}", table.to_text());
        markdown.push_str(&format!("\n**{title}**\n\n{}", table.to_markdown()));
    }
    let md_path = args.out.join("tables.md");
    write_text(&md_path, &markdown)?;
    written.push(md_path);
    println!();
    for path in [&manifest_path].into_iter().chain(&written) {
        println!("  wrote       {}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use metrics::RatioPoint;

    fn pair(name: &str, group: &str) -> EvalPair {
        EvalPair {
            name: name.into(),
            group: group.into(),
            param: None,
            image_a: "a".into(),
            image_b: "b".into(),
            homography: "h".into(),
        }
    }

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
    fn headline_prefers_the_opencv_sample() {
        let oxford = pair("graf 1-3", "oxford-graf");
        let sample = pair("opencv graf1-graf3", GROUP_OPENCV_SAMPLE);
        assert_eq!(headline(std::slice::from_ref(&oxford)), Some(&oxford));
        assert_eq!(headline(&[oxford, sample.clone()]), Some(&sample));
        assert_eq!(headline(&[pair("x", GROUP_ROTATION)]), None);
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
