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
mod eval;
mod extract;
mod extract_many;
mod homography;
mod input;
mod match_cmd;
mod model_folder;
mod names;
mod npy;
mod output;
mod pipeline;
mod progress;
mod report;
mod subpixel;
#[cfg(test)]
mod test_dir;
mod text_input;
mod warp;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use clatch::decode::DecodeLimits;
use clatch::{Backend, DescriptorConfig, DescriptorWidth, DetectorConfig, ExtractorConfig};
use clatch::{LevelBudget, MatchConfig, OpencvLatch, Pyramid, Ranking, Smoothing, Subpixel};

use crate::error::CliError;
use crate::names::BackendFlag;
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
    /// Descriptor quality on image pairs with ground-truth homographies, optionally beside OpenCV.
    ///
    /// Pairs: OpenCV's graf1/graf3 sample (--opencv-samples), homography sequences in the Oxford or
    /// HPatches layout, image 1 against the others (--data), and synthetic views of the embedded
    /// photo and of --synthetic-image photos: warps (rotations 0-180 degrees, scales 0.5-2, two
    /// perspective tilts) and copies with Gaussian noise (sigma 5-25 gray levels) or Gaussian blur
    /// (sigma 1-3 pixels).
    /// Per pair and method: keypoints in the overlap, matches, correct matches (within --inlier-px
    /// of the true homography), matching score, and precision and recall of the ratio test at
    /// thresholds 0.50..1.00. Writes OUT/pairs.csv (the pairs, for tools/eval_opencv.py),
    /// OUT/clatch.summary.csv and OUT/clatch.pr.csv, OUT/results.json, OUT/tables.md, and the charts
    /// OUT/pr.png and OUT/synthetic.png. EVALUATION.md defines every figure.
    Eval(EvalArgs),
}

/// Arguments of `clatch eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A homography sequence folder, or a folder of them (repeatable). A sequence is image 1 against
    /// every image k with a homography 1 to k, in the Oxford layout (img1.ppm, H1to2p, ...) or the
    /// HPatches layout (1.ppm, H_1_2, ...); images .ppm, .pgm, .png or .jpg. Pairs are named after
    /// the folder (`v_wall 1-2`; a leading `oxford_` is dropped: oxford_graf gives `graf 1-2`).
    #[arg(long, value_name = "DIR")]
    pub data: Vec<PathBuf>,
    /// Folder holding OpenCV's graf1.png, graf3.png and H1to3p.xml (Debian's opencv-doc package
    /// installs them in /usr/share/doc/opencv-doc/examples/data).
    #[arg(long, value_name = "DIR")]
    pub opencv_samples: Option<PathBuf>,
    /// A photo to warp synthetically besides the embedded one: PATH, or NAME=PATH (repeatable).
    #[arg(long = "synthetic-image", value_name = "[NAME=]PATH")]
    pub synthetic_images: Vec<String>,
    /// No synthetic pairs at all.
    #[arg(long, conflicts_with = "synthetic_images")]
    pub no_synthetic: bool,
    /// Output folder.
    #[arg(short, long, default_value = "clatch-eval", value_name = "DIR")]
    pub out: PathBuf,
    /// clatch configurations to evaluate (repeatable): `clatch` (CLATCH descriptors) and
    /// `clatch-opencv` (the same keypoints, OpenCV-compatible LATCH with cv2's defaults). Default:
    /// both; with --pyramid only `clatch`, since OpenCV-compatible LATCH describes full-resolution
    /// keypoints only.
    #[arg(long = "method", value_enum)]
    pub methods: Vec<eval::run::ClatchMethod>,
    /// Run the OpenCV script with this Python (which needs opencv-contrib-python-headless) and merge
    /// its results.
    #[arg(long, value_name = "PYTHON")]
    pub opencv_python: Option<PathBuf>,
    /// The OpenCV script.
    #[arg(long, default_value = "tools/eval_opencv.py", value_name = "FILE")]
    pub opencv_script: PathBuf,
    /// Merge results written earlier for the same pairs: PREFIX.summary.csv and PREFIX.pr.csv
    /// (repeatable).
    #[arg(long, value_name = "PREFIX")]
    pub merge: Vec<PathBuf>,
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
    /// Folder for the match list, COLMAP's logs and its model (default: DATABASE's name + `-colmap`).
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
    /// Only write the database and match list; do not run COLMAP.
    #[arg(long)]
    pub no_colmap: bool,
    /// The COLMAP 3.8 executable (default: `colmap` on PATH, skipped with a note if absent).
    #[arg(long, value_name = "PROGRAM", conflicts_with = "no_colmap")]
    pub colmap: Option<PathBuf>,
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
        DecodeLimits {
            max_pixels: self.max_pixels,
        }
    }
}

/// Backend selection.
#[derive(Debug, Args)]
pub struct BackendArgs {
    /// Compute backend.
    #[arg(long, default_value = "auto", value_parser = names::backend())]
    pub backend: BackendFlag,
    /// CUDA device ordinal (with --backend cuda).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub device: usize,
}

/// Detector and descriptor settings.
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// FAST threshold (1..=254): nine contiguous circle pixels must differ from the centre by more.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u8).range(1..=254))]
    pub threshold: u8,
    /// Keep at most this many keypoints per image, strongest first (default 5000, the library's, and
    /// 8192 for `colmap`, COLMAP's own budget of SIFT features per image).
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    pub max_keypoints: Option<usize>,
    /// Side in pixels of the window each detected keypoint is described over (the 64x64 samples are
    /// spread over it): 1 to 1024. Default 40, and 64 with --single-scale.
    #[arg(long, value_name = "PIXELS", value_parser = parse_keypoint_size)]
    pub keypoint_size: Option<f32>,
    /// Descriptor width in bits: a multiple of 8 from 8 to 512.
    #[arg(long, default_value_t = 512, value_parser = parse_bits)]
    pub bits: usize,
    /// Detect on a scale pyramid of LEVELS levels (full resolution included), each FACTOR (in
    /// [1.05, 2], default 2) smaller than the one before; each keypoint is described on its own level.
    /// Default 8:1.2 (the library's default); see --single-scale.
    #[arg(long, value_name = "LEVELS[:FACTOR]", value_parser = parse_pyramid)]
    pub pyramid: Option<Pyramid>,
    /// The single-scale speed preset: full resolution only, 64-pixel windows, the strongest keypoints
    /// anywhere (the defaults of clatch before 0.2). Fewer correct matches under scale and viewpoint
    /// change.
    #[arg(long, conflicts_with_all = ["pyramid", "level_budget"])]
    pub single_scale: bool,
    /// Spread keypoints over a GRID x GRID division of each image (1: the strongest anywhere; default
    /// 1, and 8 for `colmap`, so that textured corners of a photo cannot take every keypoint).
    #[arg(long, value_name = "GRID", value_parser = clap::value_parser!(u32).range(1..=64))]
    pub grid: Option<u32>,
    /// How --max-keypoints is shared among pyramid levels: `global` (the strongest of all levels) or
    /// `geometric` (ORB's shares, each level's in proportion to its scale; the default).
    #[arg(long, value_parser = names::named::<LevelBudget>())]
    pub level_budget: Option<LevelBudget>,
    /// What orders corners when the strongest are kept: `fast` (the FAST score) or `harris` (ORB's
    /// Harris response over the strongest 2 x --max-keypoints).
    #[arg(long, value_parser = names::named::<Ranking>(), default_value_t = Ranking::Fast)]
    pub ranking: Ranking,
    /// Smooth the image the descriptor samples (each pyramid level's, before its keypoints are
    /// described; detection still sees the unsmoothed image) with an integer binomial kernel.
    /// Default: the library's (`none`).
    #[arg(long, value_parser = names::named::<Smoothing>())]
    pub smoothing: Option<Smoothing>,
}

/// `--subpixel` (every command but `colmap`, which adds its `corner` method).
#[derive(Debug, Args)]
pub struct SubpixelArgs {
    /// Sub-pixel keypoint positions: `none` (whole pixels of each keypoint's pyramid level) or `score`
    /// (per axis, the peak of the parabola through the FAST scores of the keypoint and its 4
    /// neighbours, on every level; descriptors do not change). Default `score`, and `none` with
    /// --single-scale.
    #[arg(long, value_parser = names::named::<Subpixel>())]
    pub subpixel: Option<Subpixel>,
}

impl SubpixelArgs {
    /// The library's setting, when given.
    pub fn library(&self) -> Option<Subpixel> {
        self.subpixel
    }
}

/// Which matches are kept.
#[derive(Debug, Args)]
pub struct MatchingArgs {
    /// Lowe's ratio test: keep a match only if best < RATIO x second best (0 < RATIO <= 1).
    #[arg(long, default_value_t = 0.8, value_parser = parse_ratio)]
    pub ratio: f32,
    /// Turn the ratio test off.
    #[arg(long, conflicts_with = "ratio")]
    pub no_ratio: bool,
    /// Keep matches that are not mutual nearest neighbours.
    #[arg(long)]
    pub no_cross_check: bool,
    /// Drop matches farther than this many bits.
    #[arg(long, value_name = "BITS")]
    pub max_distance: Option<u32>,
}

/// How matches are checked against a ground-truth homography.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// A match is an inlier if its reprojection error is at most this many pixels.
    #[arg(long, default_value_t = 3.0, value_name = "PIXELS", value_parser = parse_tolerance)]
    pub inlier_px: f64,
}

/// How the picture of the matches is drawn.
#[derive(Debug, Args)]
pub struct DrawArgs {
    /// Draw lines for at most this many matches, spread evenly (every match still gets its circles).
    #[arg(long, default_value_t = 150, value_name = "N")]
    pub max_lines: usize,
}

fn parse_positive(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

fn parse_bits(s: &str) -> Result<usize, String> {
    let bits = s.parse::<usize>().map_err(|e| e.to_string())?;
    DescriptorWidth::from_bits(bits)
        .map(DescriptorWidth::bits)
        .map_err(|_| "must be a multiple of 8 between 8 and 512".into())
}

/// Smallest pyramid factor: closer levels are near-identical copies whose corners duplicate each other's
/// (at 1.05 every level of an image the detector accepts is at least 4 pixels smaller than the last).
pub const MIN_PYRAMID_FACTOR: f32 = 1.05;

/// `LEVELS` or `LEVELS:FACTOR`; the ranges are checked with the keypoint size by the library, and the
/// factor against [`MIN_PYRAMID_FACTOR`].
fn parse_pyramid(s: &str) -> Result<Pyramid, String> {
    let (levels, factor) = s.split_once(':').unwrap_or((s, "2"));
    let levels = levels
        .parse::<usize>()
        .map_err(|e| format!("LEVELS: {e}"))?;
    let scale_factor = factor.parse::<f32>().map_err(|e| format!("FACTOR: {e}"))?;
    if levels > 1 && scale_factor.is_finite() && scale_factor < MIN_PYRAMID_FACTOR {
        return Err(format!(
            "FACTOR {scale_factor} is below {MIN_PYRAMID_FACTOR}: levels that close are near-identical \
             copies of each other"
        ));
    }
    let pyramid = Pyramid {
        levels,
        scale_factor,
    };
    pyramid
        .validate(clatch::KeyPoint::DEFAULT_SIZE)
        .map_err(|e| e.to_string())?;
    Ok(pyramid)
}

fn parse_keypoint_size(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && (1.0..=1024.0).contains(&v) {
        Ok(v)
    } else {
        Err("must be a number of pixels from 1 to 1024".into())
    }
}

fn parse_ratio(s: &str) -> Result<f32, String> {
    let ratio = s.parse::<f32>().map_err(|e| e.to_string())?;
    if ratio.is_finite() && ratio > 0.0 && ratio <= 1.0 {
        Ok(ratio)
    } else {
        Err("must be a number in (0, 1]".into())
    }
}

fn parse_tolerance(s: &str) -> Result<f64, String> {
    let px = s.parse::<f64>().map_err(|e| e.to_string())?;
    if px.is_finite() && px >= 0.0 {
        Ok(px)
    } else {
        Err("must be a finite number of pixels, at least 0".into())
    }
}

impl BackendArgs {
    /// The backend asked for (`auto`: CUDA device 0 when usable, else the CPU), not yet checked.
    fn chosen(&self) -> Backend {
        self.backend.backend(self.device)
    }

    /// The backend asked for; `cuda` gives the library's typed error when it cannot exist here.
    pub fn resolve(&self) -> Result<Backend, CliError> {
        let backend = self.chosen();
        backend.ensure_available()?;
        Ok(backend)
    }

    /// The backend asked for, its set-up started on a thread of its own ([`Backend::start`]) so that
    /// it overlaps checking and decoding the images; what is known at once (a build without CUDA, no
    /// driver) is an error here.
    pub fn start(&self) -> Result<clatch::BackendStart, CliError> {
        Ok(self.chosen().start()?)
    }
}

impl DetectArgs {
    /// Detector and descriptor configuration: the library's default (or the single-scale preset)
    /// with the flags given on top.
    pub fn config(&self) -> Result<ExtractorConfig, CliError> {
        self.config_from(if self.single_scale {
            ExtractorConfig::single_scale()
        } else {
            ExtractorConfig::default()
        })
    }

    /// [`DetectArgs::config`] for OpenCV-compatible LATCH, which describes full-resolution keypoints
    /// only: the single-scale preset unless --pyramid is given (which the caller then refuses).
    pub fn config_full_resolution(&self) -> Result<ExtractorConfig, CliError> {
        if self.pyramid.is_some() {
            return self.config();
        }
        self.config_from(ExtractorConfig::single_scale())
    }

    fn config_from(&self, base: ExtractorConfig) -> Result<ExtractorConfig, CliError> {
        Ok(ExtractorConfig {
            detector: DetectorConfig {
                threshold: self.threshold,
                max_keypoints: self.max_keypoints.unwrap_or(base.detector.max_keypoints),
                keypoint_size: self.keypoint_size.unwrap_or(base.detector.keypoint_size),
                grid: self.grid.unwrap_or(1) as usize,
                level_budget: self.level_budget.unwrap_or(base.detector.level_budget),
                ranking: self.ranking,
                subpixel: base.detector.subpixel,
            },
            descriptor: DescriptorConfig {
                width: DescriptorWidth::from_bits(self.bits)?,
                smoothing: self.smoothing.unwrap_or(base.descriptor.smoothing),
                ..base.descriptor
            },
            pyramid: self.pyramid.or(base.pyramid),
        })
    }
}

impl MatchingArgs {
    /// Matcher configuration.
    pub fn config(&self) -> MatchConfig {
        MatchConfig {
            ratio: (!self.no_ratio).then_some(self.ratio),
            cross_check: !self.no_cross_check,
            max_distance: self.max_distance,
        }
    }
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
    let result = match cli.command {
        Command::Demo(args) => demo::main(&args),
        Command::Match(args) => match_cmd::main(&args),
        Command::Extract(args) => extract::main(&args),
        Command::Colmap(args) => colmap_cmd::main(&args),
        Command::Eval(args) => eval::main(&args),
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
            &["clatch", "demo", "--pyramid", "6"],
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
            (
                Pyramid {
                    levels: 3,
                    scale_factor: 2.0
                },
                Pyramid {
                    levels: 8,
                    scale_factor: 1.2
                }
            )
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
                Command::Eval(a) => a.detect,
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
                &["clatch", "eval"],
                &["clatch", "colmap", "--images", "i", "--database", "d.db"],
                &["clatch", "demo"],
            ] {
                let args = [command, &["--smoothing", arg]].concat();
                assert_eq!(smoothing(&args), expected, "{args:?}");
            }
        }
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn cuda_without_the_feature_is_a_typed_error() {
        let args = BackendArgs {
            backend: BackendFlag::named(Backend::Cuda { device: 0 }),
            device: 0,
        };
        assert!(matches!(
            args.resolve(),
            Err(CliError::Clatch(clatch::Error::BackendUnavailable { .. }))
        ));
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
        for command in ["match", "eval", "demo"] {
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
            backend: BackendFlag::named(Backend::Cpu),
            device: 0,
        };
        let Command::Demo(demo) = Cli::try_parse_from(["clatch", "demo"]).unwrap().command else {
            panic!("parsed the wrong subcommand")
        };
        let s = settings(&backend, &demo.detect, Some(Subpixel::Score), None).unwrap();
        assert_eq!(s.extractor.detector.subpixel, Subpixel::Score);
    }
}
