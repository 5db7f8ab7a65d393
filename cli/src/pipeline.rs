//! Detect, describe and match, timing each stage.

use std::path::Path;
use std::time::{Duration, Instant};

use clatch::{
    Backend, Extractor, ExtractorConfig, Features, GrayView, KeyPoint, Match, MatchConfig, Matcher,
    OpencvLatch,
};
use image::GrayImage;

use crate::error::CliError;
use crate::progress::Progress;

/// Progress stages of [`extract`].
pub const EXTRACT_STAGES: u64 = 2;
/// Progress stages of [`match_pair`].
pub const PAIR_STAGES: u64 = 2 * EXTRACT_STAGES + 1;

/// Everything that decides the results.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Where the work runs.
    pub backend: Backend,
    /// Detector and descriptor settings.
    pub extractor: ExtractorConfig,
    /// Which matches are kept.
    pub matching: MatchConfig,
    /// Describe with OpenCV-compatible LATCH instead of the extractor's CLATCH (the extractor still
    /// detects the keypoints and their orientation).
    pub opencv_latch: Option<OpencvLatch>,
}

/// The features of one image and how long they took.
#[derive(Clone, Debug)]
pub struct Extracted {
    /// Keypoints and their descriptors (row `i` describes keypoint `i`).
    pub features: Features,
    /// Wall time of detection (with `describe` `None`: of detection and description together).
    pub detect: Duration,
    /// Wall time of description, when it was timed apart from detection; `None` when it ran inside
    /// detection (a pyramid describes on its levels; sub-pixel positions are found after it).
    pub describe: Option<Duration>,
}

/// The result of matching image A (queries) against image B (gallery).
#[derive(Clone, Debug)]
pub struct PairRun {
    /// The backend that did the work.
    pub backend: Backend,
    /// Features of image A.
    pub a: Extracted,
    /// Features of image B.
    pub b: Extracted,
    /// Matches, A's keypoint in `query`, B's in `train`, in query order.
    pub matches: Vec<Match>,
    /// Wall time of matching.
    pub matching: Duration,
    /// Why matching was skipped, if it was.
    pub skipped: Option<String>,
}

/// Detects and describes one image; `name` labels errors. With a pyramid, description happens on the
/// levels inside detection, and with sub-pixel positions description needs the whole-pixel positions
/// detection had, so in both cases the whole time is reported as detection.
pub fn extract(
    extractor: &Extractor,
    img: &GrayImage,
    name: &Path,
    progress: &Progress,
) -> Result<Extracted, CliError> {
    let config = extractor.config();
    if config.pyramid.is_some() || config.detector.subpixel != clatch::Subpixel::None {
        let view = GrayView::try_from(img).map_err(CliError::in_image(name))?;
        progress.stage("detecting and describing keypoints");
        let start = Instant::now();
        let features = extractor
            .detect_and_describe(&view)
            .map_err(CliError::in_image(name))?;
        let detect = start.elapsed();
        progress.done();
        return Ok(Extracted {
            features,
            detect,
            describe: None,
        });
    }
    extract_with(extractor, img, name, progress, |view, keypoints| {
        extractor.describe(view, keypoints)
    })
}

/// Detects with `extractor` and describes with OpenCV-compatible LATCH on the extractor's backend.
pub fn extract_opencv(
    extractor: &Extractor,
    latch: &OpencvLatch,
    img: &GrayImage,
    name: &Path,
    progress: &Progress,
) -> Result<Extracted, CliError> {
    if extractor.config().pyramid.is_some() {
        return Err(CliError::OptionConflict {
            options: "--opencv-latch with --pyramid".into(),
            reason:
                "OpenCV-compatible LATCH describes full-resolution keypoints only, not those of \
                     the other pyramid levels; drop --pyramid or --opencv-latch"
                    .into(),
        });
    }
    extract_with(extractor, img, name, progress, |view, keypoints| {
        extractor.describe_opencv(latch, view, keypoints)
    })
}

/// Detects with `extractor`, describes with `describe`, timing both.
fn extract_with(
    extractor: &Extractor,
    img: &GrayImage,
    name: &Path,
    progress: &Progress,
    describe: impl FnOnce(&GrayView, &[KeyPoint]) -> clatch::Result<Features>,
) -> Result<Extracted, CliError> {
    let in_image = || CliError::in_image(name);
    let view = GrayView::try_from(img).map_err(in_image())?;

    progress.stage("detecting keypoints");
    let start = Instant::now();
    let keypoints = extractor.detect(&view).map_err(in_image())?;
    let detect = start.elapsed();
    progress.done();

    progress.stage("describing keypoints");
    let start = Instant::now();
    let features = describe(&view, &keypoints).map_err(in_image())?;
    let describe = start.elapsed();
    progress.done();

    Ok(Extracted {
        features,
        detect,
        describe: Some(describe),
    })
}

/// Extracts features from both images and matches A's against B's.
pub fn match_pair(
    settings: &Settings,
    (img_a, name_a): (&GrayImage, &Path),
    (img_b, name_b): (&GrayImage, &Path),
    progress: &Progress,
) -> Result<PairRun, CliError> {
    let extractor = Extractor::new(settings.backend, settings.extractor.clone())?;
    let matcher = Matcher::new(settings.backend, settings.matching.clone())?;
    let extract_one = |img: &GrayImage, name: &Path| match &settings.opencv_latch {
        None => extract(&extractor, img, name, progress),
        Some(latch) => extract_opencv(&extractor, latch, img, name, progress),
    };
    let a = extract_one(img_a, name_a)?;
    let b = extract_one(img_b, name_b)?;

    progress.stage("matching descriptors");
    let (qa, tb) = (&a.features.descriptors, &b.features.descriptors);
    // The ratio test needs two gallery descriptors; with fewer there is nothing to match.
    let needed = settings.matching.neighbours_needed();
    let skipped = if qa.is_empty() {
        Some(format!("{} has no keypoints", name_a.display()))
    } else if tb.len() < needed {
        Some(format!(
            "{} has {} keypoint(s); matching needs at least {needed}",
            name_b.display(),
            tb.len()
        ))
    } else {
        None
    };
    let start = Instant::now();
    let matches = if skipped.is_none() {
        matcher.match_descriptors(qa, tb)?
    } else {
        Vec::new()
    };
    let matching = start.elapsed();
    progress.done();

    Ok(PairRun {
        backend: settings.backend,
        a,
        b,
        matches,
        matching,
        skipped,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> Settings {
        Settings {
            backend: Backend::Cpu,
            extractor: ExtractorConfig::default(),
            matching: MatchConfig::default(),
            opencv_latch: None,
        }
    }

    #[test]
    fn featureless_images_give_no_matches_not_an_error() {
        let flat = GrayImage::from_pixel(100, 100, image::Luma([128]));
        let run = match_pair(
            &settings(),
            (&flat, Path::new("a")),
            (&flat, Path::new("b")),
            &Progress::hidden(),
        )
        .unwrap();
        assert!(run.matches.is_empty());
        assert!(run.skipped.unwrap().contains("no keypoints"));
    }

    #[test]
    fn a_pyramid_extracts_in_one_stage_and_refuses_opencv_latch() {
        let (w, h) = (400, 300);
        let pixels = clatch::synthetic::rectangles(w, h, 4).expect("synthetic image");
        let img = GrayImage::from_raw(w as u32, h as u32, pixels.clone()).unwrap();
        let config = ExtractorConfig::default().with_pyramid(Some(clatch::Pyramid::new(2, 2.0)));
        let extractor = Extractor::new(Backend::Cpu, config).unwrap();
        let got = extract(&extractor, &img, Path::new("a"), &Progress::hidden()).unwrap();
        let view = GrayView::new(&pixels, w, h, w).unwrap();
        assert_eq!(got.features, extractor.detect_and_describe(&view).unwrap());
        assert!(got.features.keypoints.iter().any(|k| k.octave == 1));
        assert_eq!(
            got.describe, None,
            "timed with detection, not reported as zero"
        );
        let latch = clatch::OpencvLatch::default();
        assert!(matches!(
            extract_opencv(
                &extractor,
                &latch,
                &img,
                Path::new("a"),
                &Progress::hidden()
            ),
            Err(CliError::OptionConflict { options, .. }) if options.contains("--pyramid")
        ));
    }

    #[test]
    fn an_image_matches_itself() {
        let (w, h) = (200, 160);
        let pixels = clatch::synthetic::rectangles(w, h, 3).expect("synthetic image");
        let img = GrayImage::from_raw(w as u32, h as u32, pixels).unwrap();
        let run = match_pair(
            &settings(),
            (&img, Path::new("a")),
            (&img, Path::new("a")),
            &Progress::hidden(),
        )
        .unwrap();
        assert!(!run.matches.is_empty());
        assert!(
            run.matches
                .iter()
                .all(|m| m.query == m.train && m.distance == 0)
        );
    }
}
