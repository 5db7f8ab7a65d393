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

/// The settings line of the report and of `results.json`.
fn settings_text(args: &EvalArgs, setup: &Setup, methods_run: &[ClatchMethod]) -> String {
    let mut text = format!(
        "{}; FAST threshold {}, at most {} keypoints, {} bits; {}",
        setup.backend,
        args.detect.threshold,
        setup.extractor.detector.max_keypoints,
        args.detect.bits,
        clatch_cli::flags::describe_matching(&setup.matching),
    );
    if methods_run.contains(&ClatchMethod::ClatchOpencv) {
        text.push_str(&format!(
            "; {}: the same keypoints, OpenCV-compatible LATCH (64 bytes, rotation invariance, \
             half_ssd_size 3, sigma 2)",
            ClatchMethod::ClatchOpencv.label()
        ));
    }
    text
}

/// Runs `clatch-eval`.
pub fn run(args: &EvalArgs) -> Result<(), EvalError> {
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
    notes.extend(methods_note);
    let manifest_path = args.out.join("pairs.csv");
    pairs::write_manifest(&pairs, &manifest_path)?;
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
    let mut written = results::write_csv(&results, &args.out.join("clatch"))?.to_vec();

    let mut merges = args.merge.clone();
    if let Some((python, script)) = script {
        let prefix = args.out.join("opencv");
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
    let json = json::to_json(&results, tolerance, &setting_text);
    write_file(&json_path, json.as_bytes())?;
    written.push(json_path);

    let methods = methods(&results);
    let headline = headline(&pairs);
    let pr_path = args.out.join("pr.png");
    chart::pr_chart(&pr_path, &methods, &report::pr_panels(&results, headline))?;
    written.push(pr_path);
    let sweeps = report::sweep_panels(&results);
    if !sweeps.is_empty() {
        let sweep_path = args.out.join("synthetic.png");
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
    write_file(&md_path, markdown.as_bytes())?;
    written.push(md_path);
    println!();
    for path in [&manifest_path].into_iter().chain(&written) {
        println!("  wrote       {}", path.display());
    }
    Ok(())
}
