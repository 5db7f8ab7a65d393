//! One evaluation run: the pairs, clatch's columns, the merged OpenCV columns, then the files and
//! the printed report.

use std::collections::HashMap;

use indicatif::{ProgressBar, ProgressStyle};

use crate::EvalArgs;
use crate::error::{EvalError, IoContext, write_file};
use crate::inputs::{collect_pairs, headline};
use crate::merge::read_csv;
use crate::metrics::ratio_grid;
use crate::run::{ClatchMethod, Setup};
use crate::tables::methods;
use crate::{chart, json, opencv, pairs, report, results, run};

/// The command line's detector, descriptor and matcher settings, on the backend asked for.
fn setup(args: &EvalArgs) -> Result<Setup, EvalError> {
    let mut extractor = args.detect.config()?;
    if let Some(subpixel) = args.subpixel.library() {
        extractor.detector.subpixel = subpixel;
    }
    Ok(Setup {
        backend: args.backend.resolve()?,
        extractor,
        matching: args.matching.config(),
    })
}

/// A bar over the pairs on stderr (hidden when stderr is not a terminal).
fn progress_bar(pairs: usize) -> ProgressBar {
    let bar = ProgressBar::new(pairs as u64);
    let template = "{spinner:.cyan} [{bar:24.cyan/blue}] {pos}/{len} {msg} ({per_sec}, {eta} left)";
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("evaluating pairs with clatch");
    bar
}

/// The settings line of the report and of `results.json`: the detector's scales and keypoint size
/// too, so that the defaults and --single-scale read differently, and whether the OpenCV-compatible
/// column describes the clatch column's keypoints or full-resolution ones of its own.
fn settings_text(args: &EvalArgs, setup: &Setup, methods_run: &[ClatchMethod]) -> String {
    let detector = &setup.extractor.detector;
    let scales = match setup.extractor.pyramid {
        Some(p) => format!(
            "pyramid {} levels x {}, keypoint size {} px at full resolution",
            p.levels, p.scale_factor, detector.keypoint_size
        ),
        None => format!("single scale, keypoint size {} px", detector.keypoint_size),
    };
    let mut text = format!(
        "{}; {scales}, grid {}; FAST threshold {}, at most {} keypoints, {} bits; {}",
        setup.backend,
        detector.grid,
        args.detect.threshold,
        detector.max_keypoints,
        args.detect.bits,
        clatch_cli::flags::describe_matching(&setup.matching),
    );
    if methods_run.contains(&ClatchMethod::ClatchOpencv) {
        let keypoints = if setup.extractor.pyramid.is_some() {
            "its own keypoints (the same detector at full resolution only, no pyramid: not the \
             clatch column's)"
        } else {
            "the same keypoints as the clatch column"
        };
        text.push_str(&format!(
            "; {}: {keypoints}, OpenCV-compatible LATCH (64 bytes, rotation invariance, \
             half_ssd_size 3, sigma 2)",
            ClatchMethod::ClatchOpencv.label()
        ));
    }
    text
}

/// Removes what a failed run wrote into an output folder it created: the files it names (the
/// synthetic pairs' images and homographies, the outputs written so far), then the folders left
/// empty. Nothing else is removed: a folder holding anything more stays.
fn remove_failed_run(
    out: &std::path::Path,
    pairs: &[pairs::EvalPair],
    written: &[std::path::PathBuf],
) {
    let ours = pairs
        .iter()
        .flat_map(|p| [&p.image_a, &p.image_b, &p.homography])
        .chain(written)
        .filter(|p| p.starts_with(out));
    let mut folders = vec![out.to_path_buf()];
    for path in ours {
        if std::fs::symlink_metadata(path).is_ok_and(|m| m.is_file()) {
            std::fs::remove_file(path).ok();
        }
        if let Some(parent) = path.parent() {
            folders.push(parent.to_path_buf());
        }
    }
    // Innermost first; `remove_dir` leaves a folder that still holds anything.
    folders.sort_by_key(|f| std::cmp::Reverse(f.components().count()));
    folders.dedup();
    for folder in folders {
        std::fs::remove_dir(folder).ok();
    }
}

/// Runs `clatch-eval`. A failed run leaves no output of its own: the files of an earlier run in the
/// folder are replaced only by a run that got as far as writing them, `pairs.csv` (the manifest)
/// only once every pair's images were read, and an output folder the run created is removed again
/// with what it wrote there.
pub fn run(args: &EvalArgs) -> Result<(), EvalError> {
    let existed = args.out.exists();
    let mut pairs_seen = Vec::new();
    let mut written = Vec::new();
    let result = run_writing(args, &mut pairs_seen, &mut written);
    if result.is_err() && !existed {
        remove_failed_run(&args.out, &pairs_seen, &written);
    }
    result
}

fn run_writing(
    args: &EvalArgs,
    pairs_seen: &mut Vec<pairs::EvalPair>,
    written_so_far: &mut Vec<std::path::PathBuf>,
) -> Result<(), EvalError> {
    let setup = setup(args)?;
    let (methods_run, methods_note) =
        run::methods_to_run(&args.methods, args.detect.pyramid.is_some())?;
    // The OpenCV script is looked for now, not after the clatch columns' minutes of work.
    let script = match &args.opencv_python {
        Some(python) => Some((python, opencv::script(args)?)),
        None => None,
    };
    std::fs::create_dir_all(&args.out).writing(&args.out)?;
    let (pairs, mut notes) = collect_pairs(args)?;
    pairs_seen.extend(pairs.iter().cloned());
    notes.extend(methods_note);
    let manifest_path = args.out.join("pairs.csv");
    let ratios = ratio_grid();
    let tolerance = args.check.inlier_px;

    let progress = progress_bar(pairs.len());
    let mut results = Vec::new();
    let mut sizes = HashMap::new();
    for pair in &pairs {
        let loaded = run::load_pair(pair, tolerance)?;
        sizes.insert(
            pair.name.clone(),
            [loaded.a.dimensions(), loaded.b.dimensions()],
        );
        for &method in &methods_run {
            results.push(run::evaluate_pair(method, &setup, &loaded, &ratios)?);
        }
        progress.inc(1);
    }
    progress.finish_and_clear();
    // Written once every pair's images were read: a run that fails on one leaves the last run's.
    written_so_far.push(manifest_path.clone());
    pairs::write_manifest(&pairs, &manifest_path)?;
    let mut written = results::write_csv(&results, &args.out.join("clatch"))?.to_vec();
    written_so_far.extend(written.iter().cloned());

    let mut merges = args.merge.clone();
    if let Some((python, script)) = script {
        let prefix = args.out.join("opencv");
        for suffix in [".summary.csv", ".pr.csv"] {
            written_so_far.push(crate::results::with_suffix(&prefix, suffix));
        }
        eprintln!(
            "clatch-eval: running {} on {} pairs",
            script.display(),
            pairs.len()
        );
        opencv::run(opencv::command(
            args,
            python,
            &script,
            &manifest_path,
            &prefix,
        ))?;
        merges.push(prefix);
    }
    for prefix in &merges {
        for merged in read_csv(prefix, &pairs, &sizes, &ratios)? {
            if results
                .iter()
                .any(|r| r.method == merged.method && r.pair == merged.pair)
            {
                return Err(EvalError::ResultsFormat {
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

    let setting_text = settings_text(args, &setup, &methods_run);
    let json_path = args.out.join("results.json");
    written_so_far.push(json_path.clone());
    let json = json::to_json(&results, tolerance, &setting_text);
    write_file(&json_path, json.as_bytes())?;
    written.push(json_path);

    let methods = methods(&results);
    let headline = headline(&pairs);
    let pr_path = args.out.join("pr.png");
    written_so_far.push(pr_path.clone());
    chart::pr_chart(&pr_path, &methods, &report::pr_panels(&results, headline))?;
    written.push(pr_path);
    let sweeps = report::sweep_panels(&results);
    if !sweeps.is_empty() {
        let sweep_path = args.out.join("synthetic.png");
        written_so_far.push(sweep_path.clone());
        chart::sweep_chart(&sweep_path, &methods, &sweeps)?;
        written.push(sweep_path);
    }

    let mut markdown = String::new();
    println!(
        "clatch-eval ({} pairs; correct = within {tolerance} px of the true homography)",
        pairs.len()
    );
    println!("  clatch      {setting_text}");
    for note in &notes {
        println!("  note        {note}");
    }
    for (title, table) in &report::sections(&results, headline) {
        println!("\n  {title}");
        print!("{}", table.to_text());
        markdown.push_str(&format!("\n**{title}**\n\n{}", table.to_markdown()));
    }
    let md_path = args.out.join("tables.md");
    written_so_far.push(md_path.clone());
    write_file(&md_path, markdown.as_bytes())?;
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

    /// A failed run removes only what it wrote, never a file of the user's (in the folder, or an
    /// input outside it), nor a link, nor a folder that still holds anything.
    #[test]
    fn a_failed_run_removes_only_its_own_files() {
        let root = std::env::temp_dir().join(format!("clatch-eval-cleanup-{}", std::process::id()));
        std::fs::remove_dir_all(&root).ok();
        let out = root.join("out");
        let synthetic = out.join("synthetic");
        std::fs::create_dir_all(&synthetic).unwrap();
        let input = root.join("img1.ppm");
        std::fs::write(&input, "the user's image").unwrap();
        let (ours_a, ours_h) = (synthetic.join("a.png"), synthetic.join("H_a"));
        std::fs::write(&ours_a, "ours").unwrap();
        std::fs::write(&ours_h, "ours").unwrap();
        let notes = out.join("notes.txt");
        std::fs::write(&notes, "the user's notes").unwrap();
        let link = out.join("pairs.csv");
        #[cfg(unix)]
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let pair = pairs::EvalPair {
            name: "a".into(),
            group: "g".into(),
            param: None,
            image_a: ours_a.clone(),
            image_b: input.clone(),
            homography: ours_h.clone(),
        };
        remove_failed_run(&out, &[pair], std::slice::from_ref(&link));
        assert!(!ours_a.exists() && !ours_h.exists() && !synthetic.exists());
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "the user's image");
        assert_eq!(std::fs::read_to_string(&notes).unwrap(), "the user's notes");
        #[cfg(unix)]
        assert!(
            std::fs::symlink_metadata(&link).is_ok(),
            "a link is not removed"
        );
        assert!(out.exists(), "a folder holding the user's notes stays");
        std::fs::remove_dir_all(&root).ok();
    }
}
