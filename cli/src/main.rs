//! `clatch`: FAST keypoints, CLATCH descriptors and Hamming matching from the command line.
//!
//! This file holds the command-line definitions and the dispatch; each subcommand lives in its own
//! module.

mod colmap_cmd;
mod colmap_program;
mod cpu_time;
mod demo;
mod draw;
mod error;
mod extract;
mod extract_many;
mod input;
mod interrupt;
mod match_cmd;
mod model_folder;
mod npy;
mod pipeline;
mod progress;
mod report;
mod subpixel;
#[cfg(test)]
mod test_dir;
mod text_input;
mod threads;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use clatch::decode::DecodeLimits;
use clatch::{Backend, OpencvLatch, Subpixel};
use clatch_cli::flags::{BackendArgs, CheckArgs, DetectArgs, MatchingArgs, SubpixelArgs};

use crate::error::CliError;
use crate::pipeline::Settings;

/// FAST keypoints, CLATCH binary descriptors and brute-force Hamming matching.
///
/// Every command reads 8-bit images (PNG, JPEG, PGM/PPM; colour is converted to gray), runs on the
/// backend chosen with --backend, and reports the time of each stage. `clatch demo` needs no files:
/// it runs on a public-domain NASA photograph (astronaut Eileen Collins) embedded in the binary.
#[derive(Debug, Parser)]
#[command(name = "clatch", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Match a photo against a warped copy of itself and check the matches against the known warp.
    ///
    /// The photo is embedded in the binary: `astronaut` from scikit-image (`skimage.data.astronaut()`),
    /// a photograph of NASA astronaut Eileen Collins from the NASA Great Images database, in the public
    /// domain, converted to 512x512 gray. The second view is the same photo warped by a fixed
    /// homography (rotation 30 degrees about the centre, scale 0.9, slight perspective). The command
    /// prints keypoints, matches, how many matches agree with the true homography, and the time of
    /// each stage, and draws the matches side by side (inliers green, outliers red).
    Demo(DemoArgs),
    /// Match two images and draw the matches side by side.
    ///
    /// With --homography (a 3x3 matrix mapping pixels of A to pixels of B, as the Oxford affine
    /// data set's `H1to2p` files) the matches are checked against it: inliers green, outliers red.
    Match(MatchArgs),
    /// Detect and describe one image; write keypoints (CSV, JSON) and descriptors (.npy).
    ///
    /// Writes PREFIX.keypoints.csv, PREFIX.keypoints.json and PREFIX.descriptors.npy. The .npy holds
    /// one uint8 row per keypoint in OpenCV LATCH's byte layout, so it can go straight into
    /// `cv2.BFMatcher(cv2.NORM_HAMMING)`.
    Extract(ExtractArgs),
    /// Structure from motion with COLMAP 3.8: features of a folder of photos, matched exhaustively.
    ///
    /// Detects and describes every image in DIR, matches every pair (ratio test and cross-check), and
    /// writes a COLMAP 3.8 database (cameras, images, keypoints) plus the putative matches as a text
    /// file in the workspace. If the `colmap` program is installed it then runs `colmap
    /// matches_importer --match_type raw` (COLMAP's geometric verification), `colmap mapper` and
    /// `colmap model_analyzer`, and reports registered images, 3D points, reprojection error and the
    /// time of each stage. The model is in WORKSPACE/sparse/N.
    Colmap(ColmapArgs),
}

/// Arguments of `clatch demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Where to write the picture of the matches (.png, .jpg, .ppm: by extension).
    #[arg(short, long, default_value = "clatch-demo.png")]
    pub output: PathBuf,
    #[command(flatten)]
    pub backend: BackendArgs,
    #[command(flatten)]
    pub detect: DetectArgs,
    #[command(flatten)]
    pub subpixel: SubpixelArgs,
    #[command(flatten)]
    pub matching: MatchingArgs,
    #[command(flatten)]
    pub check: CheckArgs,
    #[command(flatten)]
    pub draw: DrawArgs,
}

/// Arguments of `clatch match`.
#[derive(Debug, Args)]
pub struct MatchArgs {
    /// First image (the query side).
    pub image_a: PathBuf,
    /// Second image (the train side).
    pub image_b: PathBuf,
    /// Where to write the picture of the matches (.png, .jpg, .ppm: by extension).
    #[arg(short, long, default_value = "clatch-matches.png")]
    pub output: PathBuf,
    /// Ground-truth homography: 9 whitespace-separated numbers, row-major, mapping pixels of A to B.
    #[arg(long, value_name = "FILE")]
    pub homography: Option<PathBuf>,
    /// Also write the matches as CSV: query,train,distance,xq,yq,xt,yt.
    #[arg(long, value_name = "FILE")]
    pub matches_csv: Option<PathBuf>,
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub backend: BackendArgs,
    #[command(flatten)]
    pub detect: DetectArgs,
    #[command(flatten)]
    pub subpixel: SubpixelArgs,
    #[command(flatten)]
    pub matching: MatchingArgs,
    #[command(flatten)]
    pub check: CheckArgs,
    #[command(flatten)]
    pub draw: DrawArgs,
}

/// Arguments of `clatch extract`.
#[derive(Debug, Args)]
pub struct ExtractArgs {
    /// The image to describe; several images are decoded on worker threads while earlier ones are
    /// extracted (on the GPU several in flight), and each writes its files into the folder `-o`
    /// names, as STEM.keypoints.csv, STEM.keypoints.json and STEM.descriptors.npy.
    #[arg(required = true, value_name = "IMAGE")]
    pub images: Vec<PathBuf>,
    /// Output prefix: writes PREFIX.keypoints.csv, PREFIX.keypoints.json, PREFIX.descriptors.npy
    /// (with several images: the output folder).
    #[arg(short, long, value_name = "PREFIX")]
    pub output: PathBuf,
    /// With several images: stop at the first image that fails and write no image's files (the
    /// default goes on, writes every good image's three files, lists the failures and exits 1).
    #[arg(long)]
    pub fail_fast: bool,
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub backend: BackendArgs,
    #[command(flatten)]
    pub detect: DetectArgs,
    #[command(flatten)]
    pub subpixel: SubpixelArgs,
    #[command(flatten)]
    pub opencv: OpencvLatchArgs,
}

/// OpenCV-compatible LATCH instead of CLATCH (`clatch extract --opencv-latch`).
#[derive(Debug, Args)]
pub struct OpencvLatchArgs {
    /// Describe with OpenCV's LATCH: the descriptors equal
    /// `cv2.xfeatures2d.LATCH_create(BYTES, rotation, HALF, SIGMA).compute` on the same keypoints.
    #[arg(long, conflicts_with_all = ["bits", "smoothing"])]
    pub opencv_latch: bool,
    /// OpenCV LATCH descriptor bytes: 1, 2, 4, 8, 16, 32 or 64.
    #[arg(
        long,
        default_value_t = 32,
        value_name = "BYTES",
        requires = "opencv_latch"
    )]
    pub latch_bytes: usize,
    /// OpenCV LATCH without rotation invariance (patch centres not rotated by the keypoint angle).
    #[arg(long, requires = "opencv_latch")]
    pub latch_no_rotation: bool,
    /// OpenCV LATCH patch half size: patches are (2 HALF + 1)² pixels.
    #[arg(
        long,
        default_value_t = 3,
        value_name = "HALF",
        requires = "opencv_latch"
    )]
    pub latch_half_ssd_size: usize,
    /// OpenCV LATCH pre-blur sigma (3x3 Gaussian; 0: none).
    #[arg(
        long,
        default_value_t = 2.0,
        value_name = "SIGMA",
        requires = "opencv_latch"
    )]
    pub latch_sigma: f64,
}

impl OpencvLatchArgs {
    /// The validated settings, or `None` without `--opencv-latch`.
    pub fn latch(&self) -> Result<Option<OpencvLatch>, CliError> {
        if !self.opencv_latch {
            return Ok(None);
        }
        Ok(Some(OpencvLatch::new(
            self.latch_bytes,
            !self.latch_no_rotation,
            self.latch_half_ssd_size,
            self.latch_sigma,
        )?))
    }
}

/// Arguments of `clatch colmap`.
#[derive(Debug, Args)]
pub struct ColmapArgs {
    /// Folder of photos (JPEG, PNG, PGM/PPM; not its subfolders), read in name order.
    #[arg(long, value_name = "DIR")]
    pub images: PathBuf,
    /// The COLMAP database to create (an existing file is an error unless --force).
    #[arg(long, value_name = "FILE")]
    pub database: PathBuf,
    /// Camera matrix K (9 numbers, row-major) shared by every photo, kept fixed by the mapper (it passes
    /// --Mapper.ba_refine_focal_length 0 unless a --mapper-option sets it). Without it: the focal length
    /// from EXIF's 35 mm equivalent where a photo has one, else COLMAP's guess (1.2 x the larger side),
    /// principal point at the centre, one camera per image size and focal, refined by the mapper.
    #[arg(long, value_name = "FILE")]
    pub camera_k: Option<PathBuf>,
    /// Folder for COLMAP's logs, its model and the match list, if any (default beside DATABASE: `out.db` gives
    /// `out-colmap`, any other name keeps its extension, `out.sqlite` gives `out.sqlite-colmap`).
    #[arg(long, value_name = "DIR")]
    pub workspace: Option<PathBuf>,
    /// How the keypoint positions written to COLMAP are refined below a pixel (descriptors and
    /// matches do not change): `score` is the library's (as `--subpixel score` of the other
    /// commands, on every pyramid level), `corner` a least-squares corner over a window of the photo.
    #[arg(long, value_enum, default_value_t = subpixel::Subpixel::Score)]
    pub subpixel: subpixel::Subpixel,
    /// Half side of the window of --subpixel corner.
    #[arg(long, default_value_t = 3, value_name = "R", value_parser = clap::value_parser!(u32).range(1..=16))]
    pub subpixel_radius: u32,
    /// Replace an existing database and model, once the new ones are complete.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub input: InputArgs,
    /// Only write the database (and match list); do not run COLMAP.
    #[arg(long)]
    pub no_colmap: bool,
    /// Accepted for compatibility: verification is the default (see --no-verify).
    #[arg(long, conflicts_with = "no_verify")]
    pub verify: bool,
    /// Leave the verification to COLMAP: write the match list (`matches.txt` in the workspace) and
    /// run `colmap matches_importer` on it before the mapper. By default clatch verifies every pair
    /// (two-view geometry by LO-RANSAC with COLMAP 3.8's rules) and writes the matches and their
    /// geometries into the database, as COLMAP's own matcher does: COLMAP's mapper then runs
    /// straight on it, and no match list is written (see --match-list).
    #[arg(long)]
    pub no_verify: bool,
    /// Write the match list (`matches.txt` in the workspace) even though clatch verifies the pairs
    /// (it is always written with --no-verify).
    #[arg(long)]
    pub match_list: bool,
    /// Verify every putative match, as COLMAP does, without first dropping those whose
    /// neighbours (within 160 px in the first image) do not move with them into the second
    /// (clatch::verify::NeighbourConsistency, on by default: it drops matches one period off on
    /// repeated structure, a facade of near-identical windows).
    #[arg(long, conflicts_with = "no_verify")]
    pub no_neighbour_consistency: bool,
    /// The COLMAP 3.8 executable (default: `colmap` on PATH, skipped with a note if absent).
    #[arg(long, value_name = "PROGRAM", conflicts_with = "no_colmap")]
    pub colmap: Option<PathBuf>,
    /// The longest each COLMAP step may run, in seconds, before it is killed and the run fails
    /// (the database and match list are kept). Default 6 hours.
    #[arg(long, value_name = "SECONDS", default_value_t = 21_600, value_parser = clap::value_parser!(u64).range(1..))]
    pub colmap_timeout: u64,
    /// An option for `colmap mapper`, as KEY=VALUE (for example Mapper.init_min_num_inliers=50);
    /// repeatable.
    #[arg(long = "mapper-option", value_name = "KEY=VALUE")]
    pub mapper_options: Vec<String>,
    #[command(flatten)]
    pub backend: BackendArgs,
    #[command(flatten)]
    pub detect: DetectArgs,
    #[command(flatten)]
    pub matching: MatchingArgs,
}

/// Limits on input images.
#[derive(Debug, Args)]
pub struct InputArgs {
    /// Refuse images of more than this many pixels (width x height), read from the file's header
    /// before decoding. The default, 100 megapixels, is a 12000x8000 photo.
    #[arg(long, value_name = "PIXELS", default_value_t = DecodeLimits::DEFAULT_MAX_PIXELS, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_pixels: u64,
}

impl InputArgs {
    /// The decoding limits.
    pub fn limits(&self) -> DecodeLimits {
        DecodeLimits::default().with_max_pixels(self.max_pixels)
    }
}

/// How the picture of the matches is drawn.
#[derive(Debug, Args)]
pub struct DrawArgs {
    /// Draw lines for at most this many matches, spread evenly (every match still gets its circles).
    #[arg(long, default_value_t = 150, value_name = "N")]
    pub max_lines: usize,
}

/// Everything the pipeline needs, from the shared flags and the sub-pixel setting.
pub fn settings(
    backend: &BackendArgs,
    detect: &DetectArgs,
    subpixel: Option<Subpixel>,
    matching: Option<&MatchingArgs>,
) -> Result<Settings, CliError> {
    settings_on(backend.resolve()?, detect, subpixel, matching)
}

/// [`settings`] on a backend already chosen (one being set up: [`BackendArgs::start`]).
pub fn settings_on(
    backend: Backend,
    detect: &DetectArgs,
    subpixel: Option<Subpixel>,
    matching: Option<&MatchingArgs>,
) -> Result<Settings, CliError> {
    detect
        .check_sizes()
        .map_err(|reason| CliError::OptionConflict {
            options: "--keypoint-size and --pyramid".into(),
            reason,
        })?;
    let mut extractor = detect.config()?;
    if let Some(subpixel) = subpixel {
        extractor.detector.subpixel = subpixel;
    }
    Ok(Settings {
        backend,
        extractor,
        matching: matching.map(MatchingArgs::config).unwrap_or_default(),
        opencv_latch: None,
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    interrupt::install();
    if let Some(warning) = threads::cap_pool() {
        eprintln!("clatch: warning: {warning}");
    }
    let result = match cli.command {
        Command::Demo(args) => demo::main(&args),
        Command::Match(args) => match_cmd::main(&args),
        Command::Extract(args) => extract::main(&args),
        Command::Colmap(args) => colmap_cmd::main(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("clatch: error: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;
    use clatch::Pyramid;
    use clatch_cli::flags::MIN_PYRAMID_FACTOR;
    use clatch_cli::names::BackendFlag;

    /// Sizes that do not fit name the options as given and what would fit.
    #[test]
    fn pyramid_and_keypoint_sizes_that_do_not_fit_name_the_options() {
        let refused = |extra: &[&str]| {
            let args = [&["clatch", "demo"][..], extra].concat();
            let Command::Demo(demo) = Cli::try_parse_from(args).unwrap().command else {
                panic!("parsed the wrong subcommand")
            };
            match settings(&demo.backend, &demo.detect, None, None) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("{extra:?} should be refused"),
            }
        };
        let e = refused(&["--pyramid", "8"]);
        assert!(
            e.contains("--pyramid 8:2 with the default keypoint size 40"),
            "{e}"
        );
        assert!(e.contains("at most 5 levels with FACTOR 2"), "{e}");
        assert!(!e.contains("pyramid.levels"), "{e}");
        let e = refused(&["--keypoint-size", "300"]);
        assert!(
            e.contains("the default pyramid 8:1.2 with --keypoint-size 300"),
            "{e}"
        );
        assert!(e.contains("--keypoint-size at most 285"), "{e}");
        let Command::Demo(demo) =
            Cli::try_parse_from(["clatch", "demo", "--pyramid", "6", "--keypoint-size", "32"])
                .unwrap()
                .command
        else {
            panic!("parsed the wrong subcommand")
        };
        settings(&demo.backend, &demo.detect, None, None).unwrap();
    }

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn bad_flag_values_are_rejected_by_the_parser() {
        for args in [
            &["clatch", "demo", "--ratio", "1.5"][..],
            &["clatch", "demo", "--ratio", "nan"],
            &["clatch", "demo", "--threshold", "0"],
            &["clatch", "demo", "--threshold", "300"],
            &["clatch", "demo", "--bits", "100"],
            &["clatch", "demo", "--max-keypoints", "0"],
            &["clatch", "demo", "--backend", "tpu"],
            &["clatch", "demo", "--pyramid", "0"],
            &["clatch", "demo", "--pyramid", "3:1"],
            &["clatch", "demo", "--pyramid", "3:2.5"],
            &["clatch", "demo", "--pyramid", "3:x"],
            &["clatch", "demo", "--pyramid", "32:1.0000153"],
            &["clatch", "demo", "--pyramid", "2:1.049"],
            &["clatch", "match", "a.png", "b.png", "--max-pixels", "0"],
            &["clatch", "demo", "--pyramid", "3:"],
            &["clatch", "match", "only-one.png"],
            &["clatch", "extract", "img.png"],
            &["clatch", "demo", "--ratio", "0.7", "--no-ratio"],
            &[
                "clatch",
                "extract",
                "a.png",
                "-o",
                "a",
                "--latch-bytes",
                "64",
            ],
            &[
                "clatch",
                "extract",
                "a.png",
                "-o",
                "a",
                "--opencv-latch",
                "--bits",
                "256",
            ],
            &["clatch", "demo", "--smoothing", "gaussian"],
        ] {
            assert!(Cli::try_parse_from(args).is_err(), "{args:?} should fail");
        }
        let ok = Cli::try_parse_from(["clatch", "demo", "--bits", "256", "--no-ratio"]).unwrap();
        let Command::Demo(demo) = ok.command else {
            panic!("parsed the wrong subcommand")
        };
        assert_eq!(demo.detect.bits, 256);
        assert_eq!(demo.detect.pyramid, None);
        let parse = |arg: &str| {
            let Command::Demo(demo) = Cli::try_parse_from(["clatch", "demo", "--pyramid", arg])
                .unwrap()
                .command
            else {
                panic!("parsed the wrong subcommand")
            };
            demo.detect.config().unwrap().pyramid.unwrap()
        };
        assert_eq!(parse("2:1.05").scale_factor, MIN_PYRAMID_FACTOR);
        assert_eq!(
            (parse("3"), parse("8:1.2")),
            (Pyramid::new(3, 2.0), Pyramid::new(8, 1.2))
        );
        assert_eq!(demo.matching.config().ratio, None);
        let parse = |extra: &[&str]| {
            let args = [&["clatch", "extract", "a.png", "-o", "a"][..], extra].concat();
            let Command::Extract(extract) = Cli::try_parse_from(args).unwrap().command else {
                panic!("parsed the wrong subcommand")
            };
            extract.opencv.latch()
        };
        assert_eq!(parse(&[]).unwrap(), None);
        assert_eq!(
            parse(&["--opencv-latch"]).unwrap(),
            Some(OpencvLatch::default())
        );
        assert_eq!(
            parse(&[
                "--opencv-latch",
                "--latch-bytes",
                "64",
                "--latch-no-rotation",
                "--latch-sigma",
                "0"
            ])
            .unwrap(),
            Some(OpencvLatch::new(64, false, 3, 0.0).unwrap())
        );
        assert!(parse(&["--opencv-latch", "--latch-bytes", "3"]).is_err());
    }

    #[test]
    fn smoothing_maps_to_the_descriptor_option_on_every_command() {
        use clatch::Smoothing;
        let smoothing = |args: &[&str]| {
            let detect = match Cli::try_parse_from(args).unwrap().command {
                Command::Extract(a) => a.detect,
                Command::Match(a) => a.detect,
                Command::Colmap(a) => a.detect,
                Command::Demo(a) => a.detect,
            };
            detect.config().unwrap().descriptor.smoothing
        };
        let extract = ["clatch", "extract", "a.png", "-o", "a"];
        assert_eq!(
            smoothing(&extract),
            clatch::DescriptorConfig::default().smoothing,
            "the library's default"
        );
        let opencv = [
            &extract[..],
            &["--opencv-latch", "--smoothing", "binomial3"],
        ]
        .concat();
        assert!(
            Cli::try_parse_from(opencv).is_err(),
            "OpenCV LATCH has its own blur"
        );
        for (arg, expected) in [
            ("none", Smoothing::None),
            ("binomial3", Smoothing::Binomial3),
            ("binomial5", Smoothing::Binomial5),
        ] {
            for command in [
                &extract[..],
                &["clatch", "match", "a.png", "b.png"],
                &["clatch", "colmap", "--images", "i", "--database", "d.db"],
                &["clatch", "demo"],
            ] {
                let args = [command, &["--smoothing", arg]].concat();
                assert_eq!(smoothing(&args), expected, "{args:?}");
            }
        }
    }

    #[test]
    fn subpixel_reaches_the_library_and_colmap_keeps_score() {
        let extract = |extra: &[&str]| {
            let args = [&["clatch", "extract", "a.png", "-o", "a"][..], extra].concat();
            match Cli::try_parse_from(args).map(|c| c.command) {
                Ok(Command::Extract(e)) => Ok(e.subpixel.library()),
                Ok(_) => panic!("parsed the wrong subcommand"),
                Err(e) => Err(e),
            }
        };
        // Not given: the library's default (or the single-scale preset's) stays.
        assert_eq!(extract(&[]).unwrap(), None);
        assert_eq!(
            extract(&["--subpixel", "score"]).unwrap(),
            Some(Subpixel::Score)
        );
        assert_eq!(
            extract(&["--subpixel", "none"]).unwrap(),
            Some(Subpixel::None)
        );
        assert!(extract(&["--subpixel", "corner"]).is_err());
        for command in ["match", "demo"] {
            let mut args = vec!["clatch", command];
            if command == "match" {
                args.extend(["a.png", "b.png"]);
            }
            args.extend(["--subpixel", "score"]);
            assert!(Cli::try_parse_from(&args).is_ok(), "{args:?}");
        }
        let colmap = |extra: &[&str]| {
            let args = [
                &["clatch", "colmap", "--images", "d", "--database", "d.db"][..],
                extra,
            ]
            .concat();
            let Command::Colmap(c) = Cli::try_parse_from(args).unwrap().command else {
                panic!("parsed the wrong subcommand")
            };
            c.subpixel
        };
        assert_eq!(colmap(&[]), subpixel::Subpixel::Score);
        let detector = |c: subpixel::Subpixel| c.refinement(3).detector_subpixel();
        assert_eq!(detector(colmap(&[])), Subpixel::Score);
        assert_eq!(detector(colmap(&["--subpixel", "corner"])), Subpixel::None);
        assert_eq!(
            colmap(&["--subpixel", "corner"]).refinement(5),
            clatch::colmap::Refinement::Corner { radius: 5 }
        );
        assert_eq!(detector(colmap(&["--subpixel", "none"])), Subpixel::None);
        let backend = BackendArgs {
            backend: BackendFlag::named(clatch::Backend::Cpu),
            device: 0,
        };
        let Command::Demo(demo) = Cli::try_parse_from(["clatch", "demo"]).unwrap().command else {
            panic!("parsed the wrong subcommand")
        };
        let s = settings(&backend, &demo.detect, Some(Subpixel::Score), None).unwrap();
        assert_eq!(s.extractor.detector.subpixel, Subpixel::Score);
    }
}
