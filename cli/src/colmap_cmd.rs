//! `clatch colmap`: features and exhaustive matches of a folder of photos, handed to COLMAP 3.8 for
//! structure from motion (see [`clatch::colmap`] for the conventions).

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use clatch::colmap::{ColmapError, FolderWriter, ImageFolder, Photo, PinholeCamera};
use clatch::prefetch::Prefetched;
use clatch::{Backend, DescriptorSet, Extractor, Match, Matcher};

use crate::ColmapArgs;
use crate::colmap_program::{ColmapProgram, ModelStats, parse_model_analyzer};
use crate::cpu_time::{StageTime, Stopwatch};
use crate::error::CliError;
use crate::model_folder::{ModelFolder, check_images_outside};
use crate::progress::Progress;
use crate::report::print_set_up_steps;
use crate::text_input::read_text;
use crate::{report, settings_on};
use clatch::output::{Staged, TempDir, check_distinct, check_writable};

/// Wall and CPU time of each stage.
#[derive(Default)]
struct Times {
    /// The backend's set-up (on the GPU, the device's context and kernels), on a thread of its own
    /// alongside the checks and the first photos' decoding.
    start: Duration,
    extract: StageTime,
    /// The decoders' side of `extract`.
    decoding: Prefetched,
    matching: StageTime,
    write: StageTime,
    verify: StageTime,
    map: StageTime,
    analyze: StageTime,
}

/// Everything checked before any work: the photos, their names and sizes, the camera, the outputs.
struct Plan {
    folder: ImageFolder,
    /// The camera of `--camera-k`, for the photos' one size.
    camera: Option<PinholeCamera>,
    workspace: PathBuf,
    match_list: PathBuf,
    /// The workspace's `sparse/`, checked: what clatch may replace there.
    sparse: ModelFolder,
    /// `None` with --no-colmap or when `colmap` is not on PATH.
    colmap: Option<ColmapProgram>,
}

/// Runs `clatch colmap`.
pub fn main(args: &ColmapArgs) -> Result<(), CliError> {
    let refinement = args.subpixel.refinement(args.subpixel_radius);
    // The backend's set-up (on the GPU: the device's context and kernels) runs on a thread of its
    // own while the inputs are checked and the first photos decoded.
    let start = args.backend.start()?;
    let settings = settings_on(
        start.backend(),
        &args.detect,
        Some(refinement.detector_subpixel()),
        Some(&args.matching),
    )?;
    let plan = preflight(args)?;
    let mut times = Times::default();

    // Detect and describe every photo.
    let extractor = Extractor::starting(&start, extraction_config(&settings, args))?;
    let progress = Progress::counter(plan.folder.paths.len() as u64, "extracting features");
    let watch = Stopwatch::start();
    let (extracted, decoding) = clatch::colmap::extract_photos(
        &extractor,
        (&plan.folder.paths, &plan.folder.names),
        &args.input.limits(),
        refinement,
        &|_| progress.done(),
    )?;
    let (photos, descriptors): (Vec<Photo>, Vec<DescriptorSet>) = extracted.into_iter().unzip();
    times.extract = watch.stop();
    times.decoding = decoding;
    // Done by now: the first photo's extraction waited for it.
    times.start = start.wait()?;
    progress.finish();

    // Match every pair.
    let matcher = Matcher::new(settings.backend, settings.matching.clone())?;
    let pairs = Matcher::all_pairs(photos.len());
    let progress = Progress::counter(pairs.len() as u64, "matching pairs");
    let watch = Stopwatch::start();
    // The library matches the whole collection (a featureless photo simply matches nothing).
    let sets: Vec<&DescriptorSet> = descriptors.iter().collect();
    let matches: Vec<Vec<Match>> = matcher.match_pairs(&sets, &pairs, &|_| progress.done())?;
    times.matching = watch.stop();
    progress.finish();

    // Outputs: a workspace made here is removed again if nothing could be written to it.
    let workspace_existed = plan.workspace.exists();
    std::fs::create_dir_all(&plan.workspace).map_err(CliError::write(&plan.workspace))?;
    let result = write_and_run(
        args,
        &plan,
        &settings.backend,
        &photos,
        (&pairs, &matches),
        &mut times,
    );
    if result.is_err() && !workspace_existed {
        // Only when empty: a failed COLMAP step leaves its log there.
        std::fs::remove_dir(&plan.workspace).ok();
    }
    result
}

/// Writes the database and the match list to temporary files, runs COLMAP on them, and renames them
/// into place (replacing older ones, with --force) only when everything succeeded.
fn write_and_run(
    args: &ColmapArgs,
    plan: &Plan,
    backend: &Backend,
    photos: &[Photo],
    (pairs, matches): (&[(usize, usize)], &[Vec<Match>]),
    times: &mut Times,
) -> Result<(), CliError> {
    let watch = Stopwatch::start();
    let mut staged = Staged::new();
    let database = staged.reserve(&args.database)?;
    // `Database::create` makes the file itself (and never opens an existing one).
    std::fs::remove_file(&database).map_err(CliError::write(&database))?;
    let list = write_all(&database, plan.camera.as_ref(), photos, (pairs, matches))?;
    let match_list = staged.write(&plan.match_list, |w| w.write_all(&list))?;
    times.write = watch.stop();

    let Some(colmap) = &plan.colmap else {
        staged.commit()?;
        print_extraction_report(args, backend, photos, pairs, matches, times);
        if !args.no_colmap {
            println!("  colmap      not found on PATH: database written, COLMAP not run. Run:");
            let final_paths = (
                args.database.as_path(),
                plan.match_list.as_path(),
                plan.sparse.path(),
            );
            for (step, step_args) in &colmap_steps(args, final_paths) {
                println!("    colmap {step} {}", shell_words(step_args));
            }
        }
        return Ok(());
    };

    let built = TempDir::beside(plan.sparse.path())?;
    let [(_, import_args), (_, mapper_args)] =
        &colmap_steps(args, (&database, &match_list, built.path()));
    let watch = Stopwatch::start();
    colmap.run("matches_importer", import_args)?;
    times.verify = watch.stop();
    let (verified, inliers) = verified_pairs(&database)?;
    let watch = Stopwatch::start();
    colmap.run("mapper", mapper_args)?;
    times.map = watch.stop();

    staged.commit()?;
    let installed = plan.sparse.install(&built)?;
    print_extraction_report(args, backend, photos, pairs, matches, times);

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
    print_colmap_report(photos, pairs, verified, inliers, &models, times);
    Ok(())
}

/// Checks every input and output before any work: photo names, headers (size limits, truncation,
/// the detector's minimum), the camera matrix against the photos' size, outputs that would overwrite
/// an input or an earlier result, and the `colmap` program.
fn preflight(args: &ColmapArgs) -> Result<Plan, CliError> {
    let folder = ImageFolder::open(&args.images, &args.input.limits())?;
    let camera = args
        .camera_k
        .as_deref()
        .map(|k| camera_for_all(k, &folder))
        .transpose()?;

    let workspace = args
        .workspace
        .clone()
        .unwrap_or_else(|| default_workspace(&args.database));
    let match_list = workspace.join("matches.txt");
    let sparse = workspace.join("sparse");
    check_images_outside(&args.images, &workspace, &sparse)?;
    check_writable(&args.database)?;
    check_writable(&match_list)?;
    let mut inputs: Vec<(&'static str, &Path)> = folder
        .paths
        .iter()
        .map(|p| ("image", p.as_path()))
        .collect();
    if let Some(k) = &args.camera_k {
        inputs.push(("camera matrix", k));
    }
    check_distinct(
        &inputs,
        &[("database", &args.database), ("match list", &match_list)],
    )?;
    if !args.force && args.database.exists() {
        return Err(clatch::colmap::ColmapError::DatabaseExists {
            path: args.database.display().to_string(),
        }
        .into());
    }

    let colmap = if args.no_colmap {
        None
    } else {
        let program = args.colmap.clone().unwrap_or_else(|| "colmap".into());
        let found = ColmapProgram::find(&program, &workspace)?;
        if found.is_none() && args.colmap.is_some() {
            return Err(CliError::ColmapStart {
                program,
                step: "help",
                source: std::io::Error::from(std::io::ErrorKind::NotFound),
            });
        }
        found
    };
    // Without COLMAP nothing is written there; a run that installs models may replace only its own.
    let sparse = match colmap {
        Some(_) => ModelFolder::inspect(&sparse, args.force)?,
        None => ModelFolder::untouched(&sparse),
    };
    Ok(Plan {
        folder,
        camera,
        workspace,
        match_list,
        sparse,
        colmap,
    })
}

/// The camera of the K file `k_path`, which needs every photo to have the first one's size.
fn camera_for_all(k_path: &Path, folder: &ImageFolder) -> Result<PinholeCamera, CliError> {
    let text = read_text(k_path, "camera matrix")?;
    folder.shared_camera(&text).map_err(|e| match e {
        ColmapError::InvalidCamera { .. } => CliError::CameraK {
            path: k_path.to_path_buf(),
            source: e,
        },
        other => other.into(),
    })
}

/// `out.db` → `out-colmap/` beside it.
fn default_workspace(database: &Path) -> PathBuf {
    let stem = database.file_stem().unwrap_or_default().to_string_lossy();
    database.with_file_name(format!("{stem}-colmap"))
}

/// The extractor's settings: the library's grid and keypoint budget for structure from motion
/// ([`clatch::colmap::DEFAULT_GRID`], [`clatch::colmap::DEFAULT_MAX_KEYPOINTS`]) unless `--grid` or
/// `--max-keypoints` says otherwise.
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
    config
}

/// Writes the database at `path` and returns the match list: the library's one writer of a folder
/// ([`FolderWriter`]), in the order every run writes.
fn write_all(
    path: &Path,
    camera: Option<&PinholeCamera>,
    photos: &[Photo],
    (pairs, matches): (&[(usize, usize)], &[Vec<Match>]),
) -> Result<Vec<u8>, CliError> {
    let mut writer = FolderWriter::create(path, Vec::new(), camera)?;
    for photo in photos {
        writer.add_photo(photo)?;
    }
    for (&(i, j), m) in pairs.iter().zip(matches) {
        writer.add_matches(i, j, m)?;
    }
    Ok(writer.finish()?)
}

/// The two COLMAP steps after the database: import with verification, then the mapper, on the given
/// database, match list and model folder.
/// The mapper option that `clatch colmap` sets to 0 when --camera-k is given (unless given itself).
const KEEP_FOCAL_LENGTH: &str = "Mapper.ba_refine_focal_length";

fn colmap_steps(
    args: &ColmapArgs,
    (database, match_list, sparse): (&Path, &Path, &Path),
) -> [(&'static str, Vec<OsString>); 2] {
    let os = |s: &str| OsString::from(s);
    let import = vec![
        os("--database_path"),
        database.into(),
        os("--match_list_path"),
        match_list.into(),
        os("--match_type"),
        os("raw"),
        // Geometric verification needs no GPU; COLMAP 3.8's GPU default fails on a headless machine.
        os("--SiftMatching.use_gpu"),
        os("0"),
    ];
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
    [("matches_importer", import), ("mapper", mapper)]
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
    backend: &Backend,
    photos: &[Photo],
    pairs: &[(usize, usize)],
    matches: &[Vec<Match>],
    times: &Times,
) {
    let keypoints: usize = photos.iter().map(|p| p.keypoints.len()).sum();
    let putative: usize = matches.iter().map(Vec::len).sum();
    println!("clatch colmap (COLMAP 3.8 database)");
    println!(
        "  images      {} in {}",
        photos.len(),
        args.images.display()
    );
    println!("  backend     {backend}");
    println!(
        "  start       {:.2} s (the backend's set-up, alongside the checks and decoding; extract includes any wait for it)",
        times.start.as_secs_f64()
    );
    print_set_up_steps(*backend);
    println!(
        "  keypoints   {keypoints} ({:.0} per image)",
        keypoints as f64 / photos.len() as f64
    );
    println!(
        "  matches     {putative} putative over {} pairs ({} with none)",
        pairs.len(),
        matches.iter().filter(|m| m.is_empty()).count()
    );
    println!("  database    {}", args.database.display());
    println!(
        "  extract     {} ({})",
        times.extract,
        report::per_second(photos.len(), times.extract.wall, "images")
    );
    println!("  decode      {}", report::decoding(&times.decoding));
    println!(
        "  match       {} ({})",
        times.matching,
        report::per_second(pairs.len(), times.matching.wall, "pairs")
    );
    println!("  write       {}", times.write);
}

fn print_colmap_report(
    photos: &[Photo],
    pairs: &[(usize, usize)],
    verified: usize,
    inliers: usize,
    models: &[ModelStats],
    times: &Times,
) {
    println!(
        "  verified    {verified} of {} pairs, {inliers} inlier matches (colmap matches_importer)",
        pairs.len()
    );
    println!("  verify      {}", times.verify);
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
                best.registered,
                photos.len()
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

    fn mapper_args(extra: &[&str]) -> Vec<String> {
        let args = colmap_args(extra);
        let [_, (step, mapper)] = colmap_steps(
            &args,
            (Path::new("d.db"), Path::new("m.txt"), Path::new("sparse")),
        );
        assert_eq!(step, "mapper");
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
