//! `clatch colmap`: features and exhaustive matches of a folder of photos, handed to COLMAP 3.8 for
//! structure from motion (see [`clatch::colmap`] for the conventions).

use std::ffi::OsString;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use clatch::colmap::{
    ColmapError, FolderCamera, FolderJob, FolderPlan, FolderProgress, FolderReport, Overwrite,
    WrittenFolder,
};
use clatch::output::TempDir;

use crate::ColmapArgs;
use crate::colmap_program::{ColmapProgram, ModelStats, parse_model_analyzer};
use crate::cpu_time::{StageTime, Stopwatch};
use crate::error::CliError;
use crate::model_folder::{ModelFolder, check_images_outside};
use crate::progress::Progress;
use crate::report::print_set_up_steps;
use crate::text_input::read_text;
use crate::{report, settings_on};

/// Wall and CPU time of the COLMAP steps.
#[derive(Default)]
struct ColmapTimes {
    verify: StageTime,
    map: StageTime,
    analyze: StageTime,
}

/// What `clatch colmap` checks and writes beyond the library's run: the workspace, its `sparse/`
/// and the `colmap` program.
struct Workspace {
    path: PathBuf,
    /// The workspace's `sparse/`, checked: what clatch may replace there.
    sparse: ModelFolder,
    /// `None` with --no-colmap or when `colmap` is not on PATH.
    colmap: Option<ColmapProgram>,
}

/// Runs `clatch colmap`: the library's folder run ([`FolderJob`]), then COLMAP on its files before
/// they are put in place.
pub fn main(args: &ColmapArgs) -> Result<(), CliError> {
    let job = folder_job(args)?;
    // Every check before any work; the backend's set-up (on the GPU: the device's context and
    // kernels) runs on a thread of its own meanwhile and while the first photos are decoded.
    let plan = job.plan().map_err(|e| camera_k_error(args, e))?;
    let skipped = clatch::colmap::skipped_entries(&args.images);
    if !skipped.is_empty() {
        let list: Vec<String> = skipped
            .iter()
            .map(|(path, what)| format!("{} ({what})", path.display()))
            .collect();
        eprintln!(
            "clatch: warning: skipped {} entr{} of {} named like images but not regular files: {}",
            skipped.len(),
            if skipped.len() == 1 { "y" } else { "ies" },
            args.images.display(),
            list.join(", ")
        );
    }
    // The database stays locked until COLMAP's model is installed.
    let _lock = plan.lock();
    let workspace = check_workspace(args, &job, plan.folder().paths.len())?;
    // A workspace made here is removed again if nothing could be written to it.
    let workspace_existed = workspace.path.exists();
    let result = write_and_run(args, plan, &workspace);
    if result.is_err() && !workspace_existed {
        // Only when empty: a failed COLMAP step leaves its log there.
        std::fs::remove_dir(&workspace.path).ok();
    }
    result
}

/// The library's job of the flags: the folder, the database, the match list in the workspace, the
/// camera of --camera-k, the settings.
fn folder_job(args: &ColmapArgs) -> Result<FolderJob, CliError> {
    let backend = args.backend.chosen();
    let settings = settings_on(backend, &args.detect, None, Some(&args.matching))?;
    let camera = match &args.camera_k {
        Some(k) => FolderCamera::KText {
            text: read_text(k, "camera matrix")?,
            file: Some(k.clone()),
        },
        None => FolderCamera::PerPhoto,
    };
    let job = FolderJob::new(&args.images, &args.database).with_match_list_written(args.match_list);
    let job = if args.no_verify {
        job.without_verification()
    } else {
        let mut config = FolderJob::default_verification();
        if args.no_neighbour_consistency {
            config.neighbour_consistency = None;
        }
        job.with_verification(config)
            .with_guided_matching(!args.no_guided_matching)
    };
    Ok(job
        .with_workspace(workspace_path(args))
        .with_camera(camera)
        .with_backend(backend)
        .with_extractor(extraction_config(&settings, args))
        .with_matching(settings.matching)
        .with_refinement(args.subpixel.refinement(args.subpixel_radius))
        .with_limits(args.input.limits())
        .with_overwrite(if args.force {
            Overwrite::Replace
        } else {
            Overwrite::Refuse
        }))
}

/// --workspace, or the database's name + `-colmap` beside it.
fn workspace_path(args: &ColmapArgs) -> PathBuf {
    args.workspace
        .clone()
        .unwrap_or_else(|| clatch::colmap::default_workspace(&args.database))
}

/// A K file that is not a pinhole K, named as the file's fault.
fn camera_k_error(args: &ColmapArgs, e: ColmapError) -> CliError {
    match (e, &args.camera_k) {
        (e @ ColmapError::InvalidCamera { .. }, Some(path)) => CliError::CameraK {
            path: path.clone(),
            source: e,
        },
        (other, _) => other.into(),
    }
}

/// Checks what the library's run does not write, before any work: the photos are not where clatch
/// writes, the workspace's `sparse/` holds only what clatch may replace, the `colmap` program.
fn check_workspace(
    args: &ColmapArgs,
    job: &FolderJob,
    job_photos: usize,
) -> Result<Workspace, CliError> {
    let path = workspace_path(args);
    let sparse = path.join("sparse");
    check_images_outside(&job.images, &path, &sparse)?;
    let colmap = if args.no_colmap {
        None
    } else {
        let program = args.colmap.clone().unwrap_or_else(|| "colmap".into());
        let timeout = std::time::Duration::from_secs(args.colmap_timeout);
        let found = ColmapProgram::find(&program, &path, timeout)?;
        if found.is_none() && args.colmap.is_some() {
            return Err(CliError::ColmapStart {
                program,
                step: "help",
                source: std::io::Error::from(std::io::ErrorKind::NotFound),
            });
        }
        found
    };
    if let Some(colmap) = &colmap {
        check_mapper_options(&args.mapper_options, &colmap.options("mapper"))?;
        let photos = job_photos;
        if photos < 2 {
            return Err(CliError::TooFewPhotos {
                images: args.images.clone(),
                photos,
            });
        }
    }
    // Without COLMAP nothing is written there; a run that installs models may replace only its own.
    let sparse = match colmap {
        Some(_) => ModelFolder::inspect(&sparse, args.force)?,
        None => ModelFolder::untouched(&sparse),
    };
    Ok(Workspace {
        path,
        sparse,
        colmap,
    })
}

/// Runs the library's stages with a progress bar, then COLMAP on the database and match list under
/// their temporary names; renames them into place (replacing older ones, with --force) only when
/// everything succeeded.
fn write_and_run(
    args: &ColmapArgs,
    plan: FolderPlan,
    workspace: &Workspace,
) -> Result<(), CliError> {
    let backend = plan.job().backend;
    let watch = Stopwatch::start();
    let written = run_with_progress_bar(plan)?;
    let run = watch.stop();
    // The workspace stays locked while COLMAP works in it.
    let _locks = written.locks();

    let Some(colmap) = &workspace.colmap else {
        let report = written.commit()?;
        print_extraction_report(args, backend, &report, run);
        if !args.no_colmap {
            println!("  colmap      not found on PATH: database written, COLMAP not run. Run:");
            let final_paths = (
                report.database.as_path(),
                report.match_list.as_deref(),
                workspace.sparse.path(),
            );
            for (step, step_args) in &colmap_steps(args, final_paths) {
                println!("    colmap {step} {}", shell_words(step_args));
            }
        }
        return Ok(());
    };

    let mut times = ColmapTimes::default();
    let built = TempDir::beside(workspace.sparse.path())?;
    let steps = colmap_steps(
        args,
        (written.database(), written.match_list(), built.path()),
    );
    let watch = Stopwatch::start();
    let steps = (|| {
        let [.., (_, mapper_args)] = steps.as_slice() else {
            unreachable!("the mapper is always a step")
        };
        if let [(step, import_args), _] = steps.as_slice() {
            colmap.run(step, import_args)?;
            times.verify = watch.stop();
        }
        let (verified, inliers) = verified_pairs(written.database())?;
        let watch = Stopwatch::start();
        colmap.run("mapper", mapper_args)?;
        times.map = watch.stop();
        Ok::<_, CliError>((verified, inliers))
    })();
    let (verified, inliers) = match steps {
        Ok(figures) => figures,
        // The extraction and matching are not thrown away: both files go into place.
        Err(error) => return Err(keep_after_colmap_failed(args, written, workspace, error)),
    };

    let report = written.commit()?;
    let installed = workspace.sparse.install(&built)?;
    print_extraction_report(args, backend, &report, run);

    let watch = Stopwatch::start();
    let mut models = Vec::new();
    for model in installed
        .into_iter()
        .filter(|m| m.join("images.bin").exists())
    {
        let output = colmap.run(
            "model_analyzer",
            &[OsString::from("--path"), model.clone().into()],
        )?;
        models.push(parse_model_analyzer(&model, &output)?);
    }
    times.analyze = watch.stop();
    print_colmap_report(&report, verified, inliers, &models, &times);
    Ok(())
}

/// A COLMAP step failed: the database and match list, complete, are renamed into place all the same
/// (the error says so, with the commands that run COLMAP on them again).
fn keep_after_colmap_failed(
    args: &ColmapArgs,
    written: WrittenFolder,
    workspace: &Workspace,
    error: CliError,
) -> CliError {
    let report = match written.commit() {
        Ok(report) => report,
        Err(e) => return CliError::Colmap(e),
    };
    let final_paths = (
        report.database.as_path(),
        report.match_list.as_deref(),
        workspace.sparse.path(),
    );
    let commands = colmap_steps(args, final_paths)
        .iter()
        .map(|(step, step_args)| format!("  colmap {step} {}", shell_words(step_args)))
        .collect::<Vec<_>>()
        .join("\n");
    CliError::ColmapFailedKept {
        error: Box::new(error),
        database: report.database,
        match_list: report.match_list,
        commands,
    }
}

/// Refuses, before any work, a --mapper-option that is not KEY=VALUE or whose key `colmap mapper -h`
/// does not list (`known`; empty: the program lists none, nothing is refused).
fn check_mapper_options(options: &[String], known: &[String]) -> Result<(), CliError> {
    for option in options {
        let refuse = |reason: String| CliError::MapperOption {
            option: option.clone(),
            reason,
        };
        let Some((key, value)) = option.split_once('=') else {
            return Err(refuse("it is not KEY=VALUE".into()));
        };
        if key.is_empty() || value.is_empty() || key.starts_with('-') {
            return Err(refuse(
                "it is not KEY=VALUE (a key without dashes, a value)".into(),
            ));
        }
        if !known.is_empty() && !known.iter().any(|k| k == key) {
            let close = known
                .iter()
                .min_by_key(|k| edit_distance(k, key))
                .filter(|k| edit_distance(k, key) <= 3);
            let hint = close.map_or(String::new(), |k| format!("; did you mean {k}?"));
            return Err(refuse(format!(
                "`colmap mapper -h` lists no option {key}{hint}"
            )));
        }
    }
    Ok(())
}

/// Levenshtein distance, for the hint of a mistyped option.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (above + 1)
                .min(row[j] + 1)
                .min(diagonal + usize::from(ca != cb));
            diagonal = above;
        }
    }
    row[b.len()]
}

/// [`FolderPlan::run`] with a progress bar per stage on stderr.
fn run_with_progress_bar(plan: FolderPlan) -> Result<WrittenFolder, CliError> {
    let mut bar: Option<Progress> = None;
    let mut show = |p: FolderProgress| {
        if p.done == 0 {
            bar = Some(Progress::counter(p.total as u64, p.stage.to_string()));
        } else if let Some(bar) = &bar {
            bar.done_so_far(p.done as u64);
        }
        ControlFlow::Continue(())
    };
    let written = plan.run(Some(&mut show))?;
    if let Some(bar) = bar {
        bar.finish();
    }
    Ok(written)
}

/// The extractor's settings: the library's grid and keypoint budget for structure from motion
/// ([`clatch::colmap::DEFAULT_GRID`], [`clatch::colmap::DEFAULT_MAX_KEYPOINTS`] whatever the photo's
/// size, as [`clatch::colmap::FolderJob::default_extractor`]) unless `--grid`, `--max-keypoints` or
/// `--budget-pixels` says otherwise.
fn extraction_config(
    settings: &crate::pipeline::Settings,
    args: &ColmapArgs,
) -> clatch::ExtractorConfig {
    let mut config = settings.extractor.clone();
    config.detector.grid = args
        .detect
        .grid
        .map_or(clatch::colmap::DEFAULT_GRID, |g| g as usize);
    config.detector.max_keypoints = args
        .detect
        .max_keypoints
        .unwrap_or(clatch::colmap::DEFAULT_MAX_KEYPOINTS);
    config.detector.budget_pixels = args.detect.budget_pixels.and_then(|b| b.0);
    config
}

/// The mapper option that `clatch colmap` sets to 0 when --camera-k is given (unless given itself).
const KEEP_FOCAL_LENGTH: &str = "Mapper.ba_refine_focal_length";

/// The COLMAP steps after the database, on the given database, match list and model folder: import
/// with verification (only with `--no-verify`, when clatch did not verify), then the mapper.
fn colmap_steps(
    args: &ColmapArgs,
    (database, match_list, sparse): (&Path, Option<&Path>, &Path),
) -> Vec<(&'static str, Vec<OsString>)> {
    let os = |s: &str| OsString::from(s);
    let import = |match_list: &Path| {
        vec![
            os("--database_path"),
            database.into(),
            os("--match_list_path"),
            match_list.into(),
            os("--match_type"),
            os("raw"),
            // Geometric verification needs no GPU; COLMAP 3.8's GPU default fails on a headless machine.
            os("--SiftMatching.use_gpu"),
            os("0"),
        ]
    };
    let mut mapper = vec![
        os("--database_path"),
        database.into(),
        os("--image_path"),
        args.images.clone().into(),
        os("--output_path"),
        sparse.into(),
    ];
    let key_of = |option: &String| {
        option
            .split_once('=')
            .map_or(option.clone(), |(k, _)| k.to_owned())
    };
    // A given K is a calibration: the mapper keeps it. COLMAP's bundle adjustment refines fx and fy
    // by default (prior_focal_length only seeds them), and on a nearly planar scene they drift apart
    // by 1 % and tilt the cameras (Herz-Jesu: 0.38° rotation error refined, 0.09° kept; SIFT 0.11°
    // either way; docs/bench/2026-12-02-sfm/). --mapper-option Mapper.ba_refine_focal_length=1 refines.
    if args.camera_k.is_some()
        && !args
            .mapper_options
            .iter()
            .any(|o| key_of(o) == KEEP_FOCAL_LENGTH)
    {
        mapper.push(format!("--{KEEP_FOCAL_LENGTH}").into());
        mapper.push(os("0"));
    }
    for option in &args.mapper_options {
        let (key, value) = option.split_once('=').unwrap_or((option, ""));
        mapper.push(format!("--{key}").into());
        mapper.push(value.into());
    }
    match match_list {
        Some(list) if args.no_verify => {
            vec![("matches_importer", import(list)), ("mapper", mapper)]
        }
        _ => vec![("mapper", mapper)],
    }
}

fn shell_words(args: &[OsString]) -> String {
    args.iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Pairs that COLMAP verified (at least one inlier) and their inliers in all.
fn verified_pairs(database: &Path) -> Result<(usize, usize), CliError> {
    let sql = |e| clatch::colmap::ColmapError::Sqlite {
        operation: "counting verified pairs",
        source: e,
    };
    let db = rusqlite::Connection::open(database).map_err(sql)?;
    db.query_row(
        "SELECT COUNT(*), COALESCE(SUM(rows), 0) FROM two_view_geometries WHERE rows > 0",
        [],
        |row| {
            Ok((
                row.get::<_, i64>(0)? as usize,
                row.get::<_, i64>(1)? as usize,
            ))
        },
    )
    .map_err(|e| sql(e).into())
}

fn print_extraction_report(
    args: &ColmapArgs,
    backend: clatch::Backend,
    report: &FolderReport,
    run: StageTime,
) {
    let (counts, times) = (&report.counts, &report.times);
    println!("clatch colmap (COLMAP 3.8 database)");
    println!(
        "  images      {} in {}",
        counts.photos,
        args.images.display()
    );
    println!("  backend     {backend}");
    println!(
        "  start       {:.2} s (the backend's set-up, alongside the checks and decoding; extract includes any wait for it)",
        times.set_up.as_secs_f64()
    );
    print_set_up_steps(backend);
    println!(
        "  keypoints   {} ({:.0} per image)",
        counts.keypoints,
        counts.keypoints as f64 / counts.photos as f64
    );
    println!(
        "  matches     {} putative over {} pairs ({} with none)",
        counts.matches,
        counts.pairs,
        counts.pairs - counts.pairs_with_matches
    );
    println!("  database    {}", report.database.display());
    if let Some(list) = &report.match_list {
        println!("  match list  {}", list.display());
    }
    println!(
        "  extract     {:.2} s ({})",
        times.extraction.as_secs_f64(),
        report::per_second(counts.photos, times.extraction, "images")
    );
    println!("  decode      {}", report::decoding(&times.decoding));
    println!(
        "  match       {:.2} s ({})",
        times.matching.as_secs_f64(),
        report::per_second(counts.pairs, times.matching, "pairs")
    );
    if counts.pairs_verified > 0 {
        println!(
            "  verify      {:.2} s ({}): {}",
            times.verification.as_secs_f64(),
            report::per_second(counts.pairs_verified, times.verification, "pairs"),
            kept_share(counts, !args.no_guided_matching)
        );
    }
    println!("  write       {:.2} s", times.writing.as_secs_f64());
    println!("  total       {run}: extract, match and write");
}

/// The share of pairs and of matches that verification kept: "P of Q pairs kept (x %), M of N
/// matches (y %)". After guided matching a pair's inliers are its guided matches, which may outnumber
/// its putative ones: "P of Q pairs kept (x %), M inliers after guided matching from N putative
/// matches".
fn kept_share(counts: &clatch::colmap::FolderCounts, guided: bool) -> String {
    let percent = |part: usize, whole: usize| 100.0 * part as f64 / whole.max(1) as f64;
    let pairs = format!(
        "{} of {} pairs kept ({:.1} %)",
        counts.pairs_with_inliers,
        counts.pairs_verified,
        percent(counts.pairs_with_inliers, counts.pairs_verified),
    );
    if guided {
        format!(
            "{pairs}, {} inliers after guided matching from {} putative matches",
            counts.inliers, counts.matches
        )
    } else {
        format!(
            "{pairs}, {} of {} matches ({:.1} %)",
            counts.inliers,
            counts.matches,
            percent(counts.inliers, counts.matches)
        )
    }
}

fn print_colmap_report(
    report: &FolderReport,
    verified: usize,
    inliers: usize,
    models: &[ModelStats],
    times: &ColmapTimes,
) {
    if report.counts.pairs_verified > 0 {
        println!(
            "  verified    {verified} of {} pairs, {inliers} inlier matches (clatch)",
            report.counts.pairs
        );
    } else {
        println!(
            "  verified    {verified} of {} pairs, {inliers} inlier matches (colmap matches_importer)",
            report.counts.pairs
        );
        println!("  verify      {}", times.verify);
    }
    println!("  map         {}", times.map);
    println!("  analyze     {}", times.analyze);
    match models.iter().max_by_key(|m| m.registered) {
        None => println!("  model       none: the mapper registered no image"),
        Some(best) => {
            println!(
                "  model       {} ({} in all)",
                best.path.display(),
                models.len()
            );
            println!(
                "  registered  {} of {} images",
                best.registered, report.counts.photos
            );
            println!("  points      {}", best.points);
            println!(
                "  track       {:.2} observations per point",
                best.mean_track_length
            );
            println!("  reproj.     {:.3} px mean", best.mean_reprojection_error);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn colmap_args(extra: &[&str]) -> ColmapArgs {
        let args = [
            &["clatch", "colmap", "--images", "d", "--database", "d.db"][..],
            extra,
        ]
        .concat();
        let crate::Command::Colmap(c) = crate::Cli::try_parse_from(args).unwrap().command else {
            panic!("parsed the wrong subcommand")
        };
        c
    }

    #[test]
    fn verification_is_the_default_and_drops_inconsistent_neighbours_unless_told_not_to() {
        let rule = |extra: &[&str]| {
            let job = folder_job(&colmap_args(extra)).unwrap();
            job.verification.map(|v| v.neighbour_consistency.is_some())
        };
        assert_eq!(rule(&[]), Some(true));
        assert_eq!(rule(&["--verify"]), Some(true), "--verify is the default");
        assert_eq!(rule(&["--no-neighbour-consistency"]), Some(false));
        assert_eq!(rule(&["--no-verify"]), None);
        for clash in [
            &["--no-verify", "--verify"][..],
            &["--no-verify", "--no-neighbour-consistency"],
        ] {
            let parsed = crate::Cli::try_parse_from(
                [
                    &["clatch", "colmap", "--images", "d", "--database", "d.db"][..],
                    clash,
                ]
                .concat(),
            );
            assert!(parsed.is_err(), "{clash:?} accepted");
        }
    }

    #[test]
    fn the_match_list_is_written_without_verification_or_when_asked() {
        let writes = |extra: &[&str]| folder_job(&colmap_args(extra)).unwrap().writes_match_list();
        assert!(!writes(&[]));
        assert!(writes(&["--match-list"]));
        assert!(writes(&["--no-verify"]));
    }

    #[test]
    fn verified_the_mapper_runs_straight_on_the_database() {
        let names = |extra: &[&str], list: Option<&Path>| {
            let paths = (Path::new("d.db"), list, Path::new("sparse"));
            let steps = colmap_steps(&colmap_args(extra), paths);
            steps.iter().map(|(step, _)| *step).collect::<Vec<_>>()
        };
        let list = Some(Path::new("m.txt"));
        assert_eq!(names(&[], None), ["mapper"]);
        assert_eq!(names(&["--match-list"], list), ["mapper"]);
        assert_eq!(
            names(&["--no-verify"], list),
            ["matches_importer", "mapper"]
        );
    }

    #[test]
    fn the_verification_line_gives_both_shares_kept() {
        let mut counts = clatch::colmap::FolderCounts::default();
        (counts.pairs_verified, counts.pairs_with_inliers) = (8, 6);
        (counts.matches, counts.inliers) = (1000, 250);
        assert_eq!(
            kept_share(&counts, false),
            "6 of 8 pairs kept (75.0 %), 250 of 1000 matches (25.0 %)"
        );
        counts.inliers = 2500;
        assert_eq!(
            kept_share(&counts, true),
            "6 of 8 pairs kept (75.0 %), 2500 inliers after guided matching from 1000 putative matches"
        );
    }

    #[test]
    fn verify_matches_again_under_the_geometry_unless_told_not_to() {
        let guided = |extra: &[&str]| folder_job(&colmap_args(extra)).unwrap().guided_config();
        assert_eq!(guided(&["--no-verify"]), None);
        assert_eq!(guided(&["--no-guided-matching"]), None);
        for on in [guided(&[]).unwrap(), guided(&["--verify"]).unwrap()] {
            assert_eq!(
                on.max_error,
                clatch::verify::VerifyConfig::default().max_error
            );
            assert!(on.neighbour_consistency.is_some());
        }
        let alone = guided(&["--no-neighbour-consistency"]).unwrap();
        assert!(alone.neighbour_consistency.is_none());
        let parsed = crate::Cli::try_parse_from([
            "clatch",
            "colmap",
            "--images",
            "d",
            "--database",
            "d.db",
            "--no-verify",
            "--no-guided-matching",
        ]);
        assert!(parsed.is_err(), "--no-guided-matching with --no-verify");
    }

    fn mapper_args(extra: &[&str]) -> Vec<String> {
        let args = colmap_args(extra);
        let steps = colmap_steps(
            &args,
            (
                Path::new("d.db"),
                Some(Path::new("m.txt")),
                Path::new("sparse"),
            ),
        );
        let [.., (step, mapper)] = steps.as_slice() else {
            panic!("no step")
        };
        assert_eq!(*step, "mapper");
        mapper
            .iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn a_given_k_is_kept_by_the_mapper_unless_an_option_says_otherwise() {
        let keep = ["--Mapper.ba_refine_focal_length".to_owned(), "0".to_owned()];
        let given = mapper_args(&["--camera-k", "K.txt"]);
        assert!(given.windows(2).any(|w| w == keep), "{given:?}");
        let guessed = mapper_args(&[]);
        assert!(
            !guessed.iter().any(|a| a.contains("ba_refine_focal_length")),
            "a guessed focal length is refined: {guessed:?}"
        );
        let told = mapper_args(&[
            "--camera-k",
            "K.txt",
            "--mapper-option",
            "Mapper.ba_refine_focal_length=1",
        ]);
        let mentions: Vec<_> = told
            .iter()
            .enumerate()
            .filter(|(_, a)| a.contains("ba_refine_focal_length"))
            .collect();
        assert_eq!(mentions.len(), 1, "{told:?}");
        assert_eq!(told[mentions[0].0 + 1], "1");
    }

    #[test]
    fn colmap_keeps_8192_keypoints_unless_told() {
        let backend = clatch_cli::flags::BackendArgs {
            backend: clatch_cli::names::BackendFlag::named(clatch::Backend::Cpu),
            device: 0,
        };
        let budget = |extra: &[&str]| {
            let args = colmap_args(extra);
            let settings = crate::settings(&backend, &args.detect, None, None).unwrap();
            extraction_config(&settings, &args).detector.max_keypoints
        };
        assert_eq!(budget(&[]), 8192);
        assert_eq!(budget(&["--max-keypoints", "5000"]), 5000);
        // Whatever the photo's size, unless --budget-pixels says otherwise.
        let grows = |extra: &[&str]| {
            let args = colmap_args(extra);
            let settings = crate::settings(&backend, &args.detect, None, None).unwrap();
            extraction_config(&settings, &args).detector.budget_pixels
        };
        assert_eq!(grows(&[]), None);
        assert_eq!(grows(&["--budget-pixels", "1000000"]), Some(1_000_000));
        // Every other command keeps the library's budget.
        let crate::Command::Demo(demo) = crate::Cli::try_parse_from(["clatch", "demo"])
            .unwrap()
            .command
        else {
            panic!("parsed the wrong subcommand")
        };
        assert_eq!(
            demo.detect.config().unwrap().detector.max_keypoints,
            clatch::ExtractorConfig::default().detector.max_keypoints
        );
    }
}
