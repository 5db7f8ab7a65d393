//! Running clatch on one pair and turning its features and matches into [`PairResult`]s.

use std::path::Path;

use clap::ValueEnum;
use clatch::{Backend, Extractor, ExtractorConfig, Features, GrayView, MatchConfig, OpencvLatch};
use clatch::{Match, Matcher};
use image::GrayImage;

use crate::error::{EvalError, ImageContext};
use crate::metrics::{PairTruth, candidates, ratio_curve};
use crate::pairs::{EvalPair, read_gray, read_homography};
use crate::results::PairResult;

/// What every clatch column shares, from the command line.
#[derive(Clone, Debug)]
pub struct Setup {
    /// Where the work runs.
    pub backend: Backend,
    /// Detector and descriptor settings.
    pub extractor: ExtractorConfig,
    /// Which matches are kept.
    pub matching: MatchConfig,
}

/// The clatch configurations evaluated; each is one column of the tables and one curve of the chart.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ClatchMethod {
    /// clatch as set by the detector, descriptor and matcher flags.
    Clatch,
    /// The same keypoints (clatch's detector, with its orientation) described by OpenCV-compatible
    /// LATCH with `cv2.xfeatures2d.LATCH_create`'s defaults, matched by the same matcher.
    ClatchOpencv,
}

/// `cv2.xfeatures2d.LATCH_create(bytes=64, rotationInvariance=True, half_ssd_size=3, sigma=2.0)`,
/// OpenCV's defaults and the configuration of the OpenCV LATCH column of `scripts/eval_opencv.py`.
pub fn opencv_default_latch() -> Result<OpencvLatch, EvalError> {
    Ok(OpencvLatch::new(64, true, 3, 2.0)?)
}

impl ClatchMethod {
    /// The column label.
    pub fn label(self) -> &'static str {
        match self {
            ClatchMethod::Clatch => "clatch",
            ClatchMethod::ClatchOpencv => "clatch (OpenCV-compatible)",
        }
    }

    /// The detector and descriptor settings this column runs with, and the OpenCV-compatible LATCH
    /// that describes its keypoints instead of CLATCH, if any.
    pub fn extraction(
        self,
        setup: &Setup,
    ) -> Result<(ExtractorConfig, Option<OpencvLatch>), EvalError> {
        Ok(match self {
            ClatchMethod::Clatch => (setup.extractor.clone(), None),
            // Full-resolution keypoints: OpenCV-compatible LATCH describes no other level (an
            // explicit --pyramid keeps this method out, see methods_to_run).
            ClatchMethod::ClatchOpencv => (
                setup.extractor.clone().with_pyramid(None),
                Some(opencv_default_latch()?),
            ),
        })
    }
}

/// The methods run when none is asked for.
pub const DEFAULT_METHODS: [ClatchMethod; 2] = [ClatchMethod::Clatch, ClatchMethod::ClatchOpencv];

/// The methods to run, and a note when the default list was cut. OpenCV-compatible LATCH describes
/// full-resolution (level 0) keypoints only, so with a pyramid it leaves the default list, and asking
/// for it is refused.
pub fn methods_to_run(
    asked: &[ClatchMethod],
    pyramid: bool,
) -> Result<(Vec<ClatchMethod>, Option<String>), EvalError> {
    let opencv = ClatchMethod::ClatchOpencv;
    if asked.is_empty() {
        if !pyramid {
            return Ok((DEFAULT_METHODS.to_vec(), None));
        }
        let kept = DEFAULT_METHODS
            .into_iter()
            .filter(|&m| m != opencv)
            .collect();
        let note = format!(
            "{} left out: OpenCV-compatible LATCH describes full-resolution keypoints only, not \
             the levels of --pyramid",
            opencv.label()
        );
        return Ok((kept, Some(note)));
    }
    if pyramid && asked.contains(&opencv) {
        return Err(EvalError::OptionConflict {
            options: "--method clatch-opencv with --pyramid".into(),
            reason: "OpenCV-compatible LATCH describes full-resolution keypoints only, not those \
                     of the other pyramid levels; drop --pyramid or that --method"
                .into(),
        });
    }
    // A method asked for twice is one column.
    let mut methods = Vec::new();
    for &m in asked {
        if !methods.contains(&m) {
            methods.push(m);
        }
    }
    Ok((methods, None))
}

/// A pair with its images and ground truth read.
pub struct LoadedPair {
    /// What was read.
    pub pair: EvalPair,
    /// Image A.
    pub a: GrayImage,
    /// Image B.
    pub b: GrayImage,
    /// Ground truth.
    pub truth: PairTruth,
}

/// Reads a pair's images and homography.
pub fn load_pair(pair: &EvalPair, tolerance: f64) -> Result<LoadedPair, EvalError> {
    let h = read_homography(&pair.homography)?;
    let (a, b) = (read_gray(&pair.image_a)?, read_gray(&pair.image_b)?);
    // Parsing refused singular matrices already.
    let truth = PairTruth::new(h, a.dimensions(), b.dimensions(), tolerance).ok_or_else(|| {
        EvalError::Homography {
            path: pair.homography.clone(),
            reason: "the matrix is singular".into(),
        }
    })?;
    Ok(LoadedPair {
        pair: pair.clone(),
        a,
        b,
        truth,
    })
}

/// What one column found on one pair.
#[derive(Clone, Debug)]
pub struct ColumnRun {
    /// Keypoints and descriptors of image A.
    pub a: Features,
    /// Keypoints and descriptors of image B.
    pub b: Features,
    /// The configured matcher's matches, A's keypoint in `query`, B's in `train`.
    pub matches: Vec<Match>,
}

/// Detects and describes one image: CLATCH on every level, or `latch` on the detector's keypoints.
fn features(
    extractor: &Extractor,
    latch: Option<&OpencvLatch>,
    img: &GrayImage,
    path: &Path,
) -> Result<Features, EvalError> {
    let view = GrayView::try_from(img).in_image(path)?;
    let features = match latch {
        None => extractor.detect_and_describe(&view),
        Some(latch) => extractor
            .detect(&view)
            .and_then(|keypoints| extractor.describe_opencv(latch, &view, &keypoints)),
    };
    features.in_image(path)
}

/// Detects, describes and matches one loaded pair as `method` does.
pub fn run_column(
    method: ClatchMethod,
    setup: &Setup,
    loaded: &LoadedPair,
) -> Result<ColumnRun, EvalError> {
    let (config, latch) = method.extraction(setup)?;
    let extractor = Extractor::new(setup.backend, config)?;
    let pair = &loaded.pair;
    let a = features(&extractor, latch.as_ref(), &loaded.a, &pair.image_a)?;
    let b = features(&extractor, latch.as_ref(), &loaded.b, &pair.image_b)?;
    // The matcher refuses a pair it cannot match (no query, or fewer gallery descriptors than the
    // neighbours it compares); such a pair simply has no match.
    let matches = if !setup
        .matching
        .can_match(a.descriptors.len(), b.descriptors.len())
    {
        Vec::new()
    } else {
        Matcher::new(setup.backend, setup.matching.clone())?
            .match_descriptors(&a.descriptors, &b.descriptors)?
    };
    Ok(ColumnRun { a, b, matches })
}

/// The configured matches of a run (from the library) and its ratio-test curve (from 2-NN lists).
pub fn evaluate_run(
    method: &str,
    loaded: &LoadedPair,
    run: &ColumnRun,
    setup: &Setup,
    ratios: &[f32],
) -> Result<PairResult, EvalError> {
    let (kps_a, kps_b) = (&run.a.keypoints, &run.b.keypoints);
    let truth = &loaded.truth;
    let correct = |m: &Match| truth.is_correct(&kps_a[m.query as usize], &kps_b[m.train as usize]);
    let config = &setup.matching;
    let (qa, tb) = (&run.a.descriptors, &run.b.descriptors);

    let curve_candidates = if qa.is_empty() || tb.len() < 2 {
        Vec::new()
    } else {
        let matcher = Matcher::new(setup.backend, config.clone())?;
        let knn = matcher.knn(qa, tb, 2)?;
        // Cross-check: the query must be the nearest query of its train descriptor.
        let reverse = if config.cross_check {
            Some(matcher.knn(tb, qa, 1)?)
        } else {
            None
        };
        let keep = |m: &Match| {
            reverse
                .as_ref()
                .is_none_or(|r| r.as_slice()[m.train as usize].train == m.query)
                && config.max_distance.is_none_or(|max| m.distance <= max)
        };
        candidates(&knn, keep, correct)
    };

    Ok(PairResult {
        method: method.to_string(),
        pair: loaded.pair.name.clone(),
        group: loaded.pair.group.clone(),
        param: loaded.pair.param,
        size_a: loaded.a.dimensions(),
        size_b: loaded.b.dimensions(),
        keypoints: (kps_a.len(), kps_b.len()),
        overlap: truth.overlap(kps_a, kps_b),
        matches: run.matches.len(),
        correct: run.matches.iter().filter(|m| correct(m)).count(),
        curve: ratio_curve(&curve_candidates, ratios),
    })
}

/// Detects, describes and matches one loaded pair with `method`, and judges it.
pub fn evaluate_pair(
    method: ClatchMethod,
    setup: &Setup,
    loaded: &LoadedPair,
    ratios: &[f32],
) -> Result<PairResult, EvalError> {
    let run = run_column(method, setup, loaded)?;
    evaluate_run(method.label(), loaded, &run, setup, ratios)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::ratio_grid;
    use crate::pairs::{SyntheticSource, write_synthetic};
    use clatch::DescriptorWidth;

    fn setup(matching: MatchConfig) -> Setup {
        Setup {
            backend: Backend::Cpu,
            extractor: ExtractorConfig::default(),
            matching,
        }
    }

    /// The embedded photo and its synthetic views, written to a temporary folder.
    fn astronaut_pairs(tag: &str) -> (std::path::PathBuf, Vec<EvalPair>) {
        let dir =
            std::env::temp_dir().join(format!("clatch-eval-run-{}-{tag}", std::process::id()));
        let source = SyntheticSource {
            name: "astronaut".into(),
            image: clatch_cli::photo::embedded_photo().unwrap(),
        };
        let pairs = write_synthetic(&source, &dir).unwrap();
        (dir, pairs)
    }

    #[test]
    fn identity_pair_is_all_correct_and_rotation_pair_mostly() {
        let (dir, pairs) = astronaut_pairs("identity");
        let s = setup(MatchConfig::default());
        let grid = ratio_grid();

        let same = load_pair(&pairs[0], 3.0).unwrap();
        assert_eq!(same.pair.name, "astronaut rot 0");
        let r = evaluate_pair(ClatchMethod::Clatch, &s, &same, &grid).unwrap();
        // The same image twice: every keypoint matches itself at distance 0 and sits in the overlap.
        assert_eq!(r.keypoints.0, r.keypoints.1);
        assert_eq!(r.overlap, r.keypoints);
        assert!(r.matches > 0);
        assert_eq!(r.correct, r.matches);
        assert_eq!(
            r.matching_score(),
            Some(r.matches as f64 / r.keypoints.0 as f64)
        );

        let rot = load_pair(&pairs[2], 3.0).unwrap();
        assert_eq!(rot.pair.name, "astronaut rot 30");
        let r = evaluate_pair(ClatchMethod::Clatch, &s, &rot, &grid).unwrap();
        assert!(r.precision().unwrap() > 0.8, "{r:?}");
        // More permissive thresholds keep at least as much, and at 0.8 the curve agrees with the
        // library's matcher (ratio 0.8 with cross-check).
        for w in r.curve.windows(2) {
            assert!(w[0].kept <= w[1].kept && w[0].correct_kept <= w[1].correct_kept);
        }
        let at_08 = r.curve.iter().find(|p| p.ratio == 0.8).unwrap();
        assert_eq!((at_08.kept, at_08.correct_kept), (r.matches, r.correct));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn opencv_column_describes_clatch_keypoints_with_opencv_latch() {
        let (dir, pairs) = astronaut_pairs("opencv");
        let s = setup(MatchConfig::default());
        let grid = ratio_grid();
        let method = ClatchMethod::ClatchOpencv;
        assert_eq!(method.label(), "clatch (OpenCV-compatible)");
        let (config, latch) = method.extraction(&s).unwrap();
        assert_eq!(latch, Some(OpencvLatch::new(64, true, 3, 2.0).unwrap()));
        assert_eq!(config.pyramid, None);
        assert!(s.extractor.pyramid.is_some(), "the default has a pyramid");
        let (clatch_config, no_latch) = ClatchMethod::Clatch.extraction(&s).unwrap();
        assert_eq!((clatch_config, no_latch), (s.extractor.clone(), None));

        let rot = load_pair(&pairs[2], 3.0).unwrap();
        assert_eq!(rot.pair.name, "astronaut rot 30");
        let run = run_column(method, &s, &rot).unwrap();
        // The keypoints are the detector's (with its angles); the descriptors are the library's
        // OpenCV-compatible ones for them, not CLATCH's.
        let extractor =
            Extractor::new(Backend::Cpu, ExtractorConfig::default().with_pyramid(None)).unwrap();
        for (img, got) in [(&rot.a, &run.a), (&rot.b, &run.b)] {
            let view = GrayView::try_from(img).unwrap();
            let detected = extractor.detect(&view).unwrap();
            assert!(detected.iter().any(|k| k.angle != 0.0));
            let latch = latch.as_ref().unwrap();
            let expected = extractor.describe_opencv(latch, &view, &detected).unwrap();
            assert!(!expected.keypoints.is_empty());
            assert_eq!(*got, expected);
            assert_eq!(got.descriptors.width(), DescriptorWidth::FULL);
            let clatch = extractor.describe(&view, &detected).unwrap();
            assert_ne!(*got, clatch, "CLATCH descriptors");
        }

        // Its figures: labelled, matched by the configured matcher, judged by the homography.
        let r = evaluate_run(method.label(), &rot, &run, &s, &grid).unwrap();
        assert_eq!(r.method, "clatch (OpenCV-compatible)");
        assert_eq!(r.keypoints, (run.a.keypoints.len(), run.b.keypoints.len()));
        assert!(r.matches > 0 && r.correct > 0, "{r:?}");
        let at_08 = r.curve.iter().find(|p| p.ratio == 0.8).unwrap();
        assert_eq!((at_08.kept, at_08.correct_kept), (r.matches, r.correct));
        assert_eq!(evaluate_pair(method, &s, &rot, &grid).unwrap(), r);

        // The same image twice: every match is correct.
        let same = load_pair(&pairs[0], 3.0).unwrap();
        let r = evaluate_pair(method, &s, &same, &grid).unwrap();
        assert!(r.matches > 0);
        assert_eq!(r.correct, r.matches);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_pyramid_leaves_the_opencv_column_out_of_the_default_list_and_refuses_it_when_asked() {
        use ClatchMethod::{Clatch, ClatchOpencv};
        assert_eq!(
            methods_to_run(&[], false).unwrap(),
            (DEFAULT_METHODS.to_vec(), None)
        );
        let (methods, note) = methods_to_run(&[], true).unwrap();
        assert_eq!(methods, [Clatch]);
        assert!(note.unwrap().contains(ClatchOpencv.label()));
        assert_eq!(
            methods_to_run(&[ClatchOpencv], false).unwrap(),
            (vec![ClatchOpencv], None)
        );
        assert_eq!(
            methods_to_run(&[ClatchOpencv, Clatch, ClatchOpencv], false).unwrap(),
            (vec![ClatchOpencv, Clatch], None)
        );
        let e = methods_to_run(&[Clatch, ClatchOpencv], true).unwrap_err();
        assert!(
            matches!(e, EvalError::OptionConflict { .. }) && e.to_string().contains("--pyramid"),
            "{e}"
        );
    }

    #[test]
    fn without_cross_check_the_curve_still_agrees_with_the_matcher() {
        let (dir, pairs) = astronaut_pairs("nocross");
        let config = MatchConfig::default()
            .with_ratio(Some(0.9))
            .with_cross_check(false)
            .with_max_distance(Some(120));
        let loaded = load_pair(&pairs[15], 3.0).unwrap();
        let r = evaluate_pair(ClatchMethod::Clatch, &setup(config), &loaded, &[0.9]).unwrap();
        assert_eq!(
            (r.curve[0].kept, r.curve[0].correct_kept),
            (r.matches, r.correct)
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
