//! `clatch demo`: the embedded photo against a warped copy of itself, checked against the known warp.

use std::path::Path;

use clatch::GrayView;
use clatch::homography::warp;
use clatch_cli::photo::{SOURCE, demo_homography, embedded_photo};
use image::GrayImage;

use crate::draw::{check_picture_path, draw_matches, save_picture};
use crate::error::CliError;
use crate::pipeline::{self, PairRun, Settings};
use crate::progress::Progress;
use crate::report::{self, Evaluation};
use crate::{DemoArgs, settings};

/// Name used for the embedded photo in messages.
const NAME_A: &str = "astronaut.png (embedded)";
/// Name used for the warped copy in messages.
const NAME_B: &str = "astronaut.png (warped)";

/// Everything the demo computed.
pub struct DemoRun {
    /// The embedded photo (image A).
    pub original: GrayImage,
    /// Its warped copy (image B).
    pub warped: GrayImage,
    /// Features and matches.
    pub run: PairRun,
    /// Matches checked against `homography`.
    pub evaluation: Evaluation,
}

/// Decodes the embedded photo.
pub fn embedded_image() -> Result<GrayImage, CliError> {
    embedded_photo().map_err(|source| CliError::Embedded {
        name: NAME_A,
        source,
    })
}

/// Progress stages of [`run_demo`].
pub const DEMO_STAGES: u64 = 1 + pipeline::PAIR_STAGES;

/// Warps the embedded photo, matches the two views and checks the matches against the warp.
pub fn run_demo(
    settings: &Settings,
    tolerance: f64,
    progress: &Progress,
) -> Result<DemoRun, CliError> {
    progress.stage("warping the photo");
    let original = embedded_image()?;
    let (w, h) = original.dimensions();
    let homography = demo_homography(w as usize, h as usize);
    let view = GrayView::try_from(&original)?;
    let pixels = warp(&view, &homography, w as usize, h as usize)?;
    let warped = GrayImage::from_raw(w, h, pixels).expect("warp returns width x height pixels");
    progress.done();

    let run = pipeline::match_pair(
        settings,
        (&original, Path::new(NAME_A)),
        (&warped, Path::new(NAME_B)),
        progress,
    )?;
    let evaluation = report::evaluate(
        &run.matches,
        &run.a.features.keypoints,
        &run.b.features.keypoints,
        &homography,
        tolerance,
    );
    Ok(DemoRun {
        original,
        warped,
        run,
        evaluation,
    })
}

/// Runs `clatch demo`.
pub fn main(args: &DemoArgs) -> Result<(), CliError> {
    let subpixel = args.subpixel.library();
    let settings = settings(&args.backend, &args.detect, subpixel, Some(&args.matching))?;
    check_picture_path(&args.output)?;
    let progress = Progress::new(DEMO_STAGES + 1);
    let demo = run_demo(&settings, args.check.inlier_px, &progress)?;

    progress.stage("drawing the matches");
    let picture = draw_matches(
        &demo.original,
        &demo.warped,
        &demo.run.a.features.keypoints,
        &demo.run.b.features.keypoints,
        &demo.run.matches,
        &demo.evaluation.classes,
        args.draw.max_lines,
    );
    save_picture(&picture, &args.output)?;
    progress.done();
    progress.finish();

    let (w, h) = demo.original.dimensions();
    println!("clatch demo");
    println!("  image A     {SOURCE}, {w}x{h} gray");
    println!(
        "  image B     A warped by a known homography: rotation 30 deg, scale 0.9, slight perspective"
    );
    print!(
        "{}",
        report::pair_summary(
            &demo.run,
            [demo.original.dimensions(), demo.warped.dimensions()],
            &settings.matching,
            Some(&demo.evaluation),
        )
    );
    println!(
        "{}",
        report::picture_written(
            &args.output,
            picture.dimensions(),
            demo.run.matches.len(),
            args.draw.max_lines,
            "inliers green, outliers red",
        )
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clatch::{Backend, ExtractorConfig, MatchConfig};

    #[test]
    fn demo_matches_agree_with_the_true_homography() {
        let settings = Settings {
            backend: Backend::Cpu,
            extractor: ExtractorConfig::default(),
            matching: MatchConfig::default(),
            opencv_latch: None,
        };
        let start = std::time::Instant::now();
        let demo = run_demo(&settings, 3.0, &Progress::hidden()).unwrap();
        let e = &demo.evaluation;
        eprintln!(
            "demo: {} + {} keypoints, {} matches, {} inliers ({:.3}), mean {:.3} px, median {:.3} px, {:?}",
            demo.run.a.features.keypoints.len(),
            demo.run.b.features.keypoints.len(),
            demo.run.matches.len(),
            e.inliers,
            e.inlier_fraction(),
            e.mean_error,
            e.median_error,
            start.elapsed(),
        );
        assert!(demo.run.matches.len() >= 200, "{}", demo.run.matches.len());
        assert!(e.inlier_fraction() >= 0.8, "{}", e.inlier_fraction());
        assert!(e.median_error < 1.5, "{}", e.median_error);
    }
}
