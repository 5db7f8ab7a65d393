//! `clatch-eval`: descriptor quality on image pairs with ground-truth homographies (homography
//! sequences in the Oxford or HPatches layout, OpenCV's graf sample, synthetic warps, noise and
//! blur), with OpenCV's LATCH, ORB and SIFT beside clatch through `scripts/eval_opencv.py`. The
//! definitions are in [`metrics`] and EVALUATION.md.

mod chart;
mod degrade;
mod error;
mod facade;
mod geometry;
mod harness;
mod inputs;
mod json;
mod merge;
mod metrics;
mod opencv;
mod pairs;
mod report;
mod results;
mod run;
mod sequences;
mod tables;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use clatch_cli::flags::{BackendArgs, CheckArgs, DetectArgs, MatchingArgs, SubpixelArgs};

/// Descriptor quality on image pairs with ground-truth homographies, optionally beside OpenCV.
///
/// Pairs: OpenCV's graf1/graf3 sample (--opencv-samples), homography sequences in the Oxford or
/// HPatches layout, image 1 against the others (--data), and synthetic views of the embedded
/// photo and of --synthetic-image photos: warps (rotations 0-180 degrees, scales 0.5-2, two
/// perspective tilts) and copies with Gaussian noise (sigma 5-25 gray levels) or Gaussian blur
/// (sigma 1-3 pixels).
/// Per pair and method: keypoints in the overlap, matches, correct matches (within --inlier-px
/// of the true homography), matching score, and precision and recall of the ratio test at
/// thresholds 0.50..1.00. Writes OUT/pairs.csv (the pairs, for scripts/eval_opencv.py),
/// OUT/clatch.summary.csv and OUT/clatch.pr.csv, OUT/results.json, OUT/tables.md, and the charts
/// OUT/pr.png and OUT/synthetic.png. EVALUATION.md defines every figure.
#[derive(Debug, Parser)]
#[command(name = "clatch-eval", version, about, long_about)]
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
    pub methods: Vec<run::ClatchMethod>,
    /// Run the OpenCV script with this Python (which needs opencv-contrib-python-headless) and merge
    /// its results.
    #[arg(long, value_name = "PYTHON")]
    pub opencv_python: Option<PathBuf>,
    /// The OpenCV script (default: scripts/eval_opencv.py of this crate's source folder).
    #[arg(long, value_name = "FILE")]
    pub opencv_script: Option<PathBuf>,
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

fn main() -> ExitCode {
    // Subcommands ahead of the descriptor evaluation's flags, which stay as they were.
    let first = std::env::args().nth(1);
    let result = match first.as_deref() {
        Some("facade") => facade::run(&facade::FacadeArgs::parse_from(std::env::args().skip(1))),
        Some("geometry") => geometry::run(&geometry::GeometryArgs::parse_from(
            std::env::args().skip(1),
        )),
        _ => harness::run(&EvalArgs::parse()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("clatch-eval: error: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent_and_maps_onto_the_library() {
        EvalArgs::command().debug_assert();
        let args = EvalArgs::try_parse_from([
            "clatch-eval",
            "--smoothing",
            "binomial5",
            "--subpixel",
            "score",
            "--pyramid",
            "3:1.5",
            "--no-ratio",
        ])
        .unwrap();
        let config = args.detect.config().unwrap();
        assert_eq!(config.descriptor.smoothing, clatch::Smoothing::Binomial5);
        assert_eq!(config.pyramid.unwrap().levels, 3);
        assert_eq!(args.subpixel.library(), Some(clatch::Subpixel::Score));
        assert_eq!(args.matching.config().ratio, None);
        assert_eq!(args.opencv_script, None);
        for bad in [
            &[
                "clatch-eval",
                "--no-synthetic",
                "--synthetic-image",
                "a.png",
            ][..],
            &["clatch-eval", "--method", "sift"],
            &["clatch-eval", "--ratio", "0.7", "--no-ratio"],
        ] {
            assert!(EvalArgs::try_parse_from(bad).is_err(), "{bad:?}");
        }
    }
}
