//! The settings types are `#[non_exhaustive]` and built with `with_*` methods from outside the crate:
//! each method sets its own field to the value given and keeps every other field as it was.

use clatch::colmap::Photo;
use clatch::decode::DecodeLimits;
use clatch::verify::VerifyConfig;
use clatch::{
    Backend, DescriptorConfig, DescriptorWidth, DetectorConfig, Extractor, ExtractorConfig,
    KeyPoint, LevelBudget, MatchConfig, Matcher, PatchWeights, Pyramid, Ranking, Smoothing,
    Subpixel,
};

/// The fields of a settings value compared with another's: (name, equal in both).
type Fields = Vec<(&'static str, bool)>;

/// The comparison of these fields of two values, as [`only_its_field`] takes it.
macro_rules! fields {
    ($($field:ident),+) => {
        |a, b| vec![$((stringify!($field), a.$field == b.$field)),+]
    };
}

/// Each `cases` entry `(field, value)` differs from `base` in exactly `field`, by the comparison
/// `fields` makes.
fn only_its_field<T>(base: &T, cases: &[(&str, T)], fields: fn(&T, &T) -> Fields) {
    for (changed, value) in cases {
        for (name, equal) in fields(base, value) {
            assert_eq!(
                equal,
                name != *changed,
                "{}: field {name} after with_{changed}",
                std::any::type_name::<T>()
            );
        }
    }
}

#[test]
fn each_detector_method_sets_its_field_only() {
    let base = DetectorConfig::default();
    let cases = [
        ("threshold", base.clone().with_threshold(33)),
        ("max_keypoints", base.clone().with_max_keypoints(123)),
        ("budget_pixels", base.clone().with_budget_pixels(None)),
        ("keypoint_size", base.clone().with_keypoint_size(24.0)),
        ("grid", base.clone().with_grid(5)),
        (
            "level_budget",
            base.clone().with_level_budget(LevelBudget::Global),
        ),
        ("ranking", base.clone().with_ranking(Ranking::Harris)),
        ("subpixel", base.clone().with_subpixel(Subpixel::None)),
    ];
    only_its_field(
        &base,
        &cases,
        fields!(
            threshold,
            max_keypoints,
            budget_pixels,
            keypoint_size,
            grid,
            level_budget,
            ranking,
            subpixel
        ),
    );
    let all = base
        .with_threshold(33)
        .with_max_keypoints(123)
        .with_budget_pixels(Some(640 * 480))
        .with_keypoint_size(24.0)
        .with_grid(5)
        .with_level_budget(LevelBudget::Global)
        .with_ranking(Ranking::Harris)
        .with_subpixel(Subpixel::None);
    assert_eq!(
        (
            all.threshold,
            all.max_keypoints,
            all.keypoint_size,
            all.grid
        ),
        (33, 123, 24.0, 5)
    );
    assert_eq!(
        (all.level_budget, all.ranking, all.subpixel),
        (LevelBudget::Global, Ranking::Harris, Subpixel::None)
    );
    assert_eq!(all.budget_pixels, Some(640 * 480));
    all.validate().unwrap();
    assert!(all.with_budget_pixels(Some(0)).validate().is_err());
}

#[test]
fn the_budget_follows_the_image_only_where_set() {
    // 400x300 is 120000 pixels; with budget_pixels 30000 the budget is ceil(20 · 120000 / 30000)
    // = 80 (within 4 x 20), and the textured image has more corners than that.
    let (w, h) = (400, 300);
    let pixels = clatch::synthetic::noise(w, h, 5).unwrap();
    let image = clatch::GrayView::new(&pixels, w, h, w).unwrap();
    let detector = DetectorConfig::default().with_max_keypoints(20);
    assert_eq!(detector.budget(w, h), 20); // 2^20 pixels by default: this image keeps 20
    let count = |detector: DetectorConfig, pyramid: Option<Pyramid>| {
        let config = ExtractorConfig::default()
            .with_detector(detector)
            .with_pyramid(pyramid);
        let extractor = Extractor::new(Backend::Cpu, config).unwrap();
        extractor
            .detect_and_describe(&image)
            .unwrap()
            .keypoints
            .len()
    };
    for pyramid in [Some(Pyramid::DEFAULT), None] {
        assert_eq!(count(detector.clone(), pyramid), 20);
        let grown = detector.clone().with_budget_pixels(Some(30_000));
        assert_eq!(grown.budget(w, h), 80);
        assert_eq!(count(grown.clone(), pyramid), 80);
        // At most 4 times max_keypoints.
        assert_eq!(grown.with_budget_pixels(Some(1000)).budget(w, h), 80);
        assert_eq!(
            count(detector.clone().with_budget_pixels(Some(1000)), pyramid),
            80
        );
    }
}

#[test]
fn each_descriptor_method_sets_its_field_only() {
    let base = DescriptorConfig::default();
    let narrow = DescriptorWidth::from_bits(128).unwrap();
    let cases = [
        ("width", base.clone().with_width(narrow)),
        (
            "weights",
            base.clone().with_weights(PatchWeights::uniform()),
        ),
        (
            "smoothing",
            base.clone().with_smoothing(Smoothing::Binomial3),
        ),
    ];
    only_its_field(&base, &cases, fields!(width, weights, smoothing));
    assert_eq!(cases[0].1.width, narrow);
    assert_eq!(cases[1].1.weights, PatchWeights::uniform());
    assert_eq!(cases[2].1.smoothing, Smoothing::Binomial3);
}

#[test]
fn each_match_method_sets_its_field_only() {
    let base = MatchConfig::default();
    let cases = [
        ("ratio", base.clone().with_ratio(None)),
        ("cross_check", base.clone().with_cross_check(false)),
        ("max_distance", base.clone().with_max_distance(Some(70))),
    ];
    only_its_field(&base, &cases, fields!(ratio, cross_check, max_distance));
    assert_eq!(cases[0].1.ratio, None);
    assert!(!cases[1].1.cross_check);
    assert_eq!(cases[2].1.max_distance, Some(70));
    // A matcher takes what the methods built, and checks it as before.
    assert!(Matcher::new(Backend::Cpu, base.clone().with_ratio(Some(0.6))).is_ok());
    assert!(Matcher::new(Backend::Cpu, base.with_ratio(Some(1.5))).is_err());
}

#[test]
fn each_verify_method_sets_its_field_only() {
    let base = VerifyConfig::default();
    let cases = [
        ("max_error", base.clone().with_max_error(2.0)),
        (
            "neighbour_consistency",
            base.clone()
                .with_neighbour_consistency(Some(clatch::verify::NeighbourConsistency::default())),
        ),
        ("confidence", base.clone().with_confidence(0.99)),
        (
            "trials_multiplier",
            base.clone().with_trials_multiplier(1.0),
        ),
        ("min_num_trials", base.clone().with_min_num_trials(10)),
        ("max_num_trials", base.clone().with_max_num_trials(500)),
        ("min_inlier_ratio", base.clone().with_min_inlier_ratio(0.1)),
        ("min_num_inliers", base.clone().with_min_num_inliers(30)),
        (
            "min_e_f_inlier_ratio",
            base.clone().with_min_e_f_inlier_ratio(0.9),
        ),
        (
            "max_h_inlier_ratio",
            base.clone().with_max_h_inlier_ratio(0.7),
        ),
        (
            "detect_watermark",
            base.clone().with_detect_watermark(false),
        ),
        (
            "watermark_min_inlier_ratio",
            base.clone().with_watermark_min_inlier_ratio(0.5),
        ),
        (
            "watermark_border_size",
            base.clone().with_watermark_border_size(0.05),
        ),
        ("seed", base.clone().with_seed(9)),
    ];
    only_its_field(
        &base,
        &cases,
        fields!(
            max_error,
            neighbour_consistency,
            confidence,
            trials_multiplier,
            min_num_trials,
            max_num_trials,
            min_inlier_ratio,
            min_num_inliers,
            min_e_f_inlier_ratio,
            max_h_inlier_ratio,
            detect_watermark,
            watermark_min_inlier_ratio,
            watermark_border_size,
            seed
        ),
    );
    assert_eq!((cases[0].1.max_error, cases[13].1.seed), (2.0, 9));
}

#[test]
fn each_extractor_method_sets_its_field_only() {
    let base = ExtractorConfig::single_scale();
    let detector = DetectorConfig::default().with_threshold(40);
    let descriptor = DescriptorConfig::default().with_smoothing(Smoothing::Binomial5);
    let pyramid = Some(Pyramid::new(3, 2.0));
    let cases = [
        ("detector", base.clone().with_detector(detector.clone())),
        (
            "descriptor",
            base.clone().with_descriptor(descriptor.clone()),
        ),
        ("pyramid", base.clone().with_pyramid(pyramid)),
    ];
    only_its_field(&base, &cases, fields!(detector, descriptor, pyramid));
    assert_eq!(
        (
            &cases[0].1.detector,
            &cases[1].1.descriptor,
            cases[2].1.pyramid
        ),
        (&detector, &descriptor, pyramid)
    );
    // The default is the pyramid; `with_pyramid(None)` is the full-resolution path.
    assert_eq!(
        ExtractorConfig::default().with_pyramid(None).pyramid,
        None::<Pyramid>
    );
}

#[test]
fn pyramids_are_made_by_new_and_the_methods() {
    let p = Pyramid::new(5, 1.5);
    assert_eq!((p.levels, p.scale_factor), (5, 1.5));
    let levels = p.with_levels(3);
    assert_eq!((levels.levels, levels.scale_factor), (3, 1.5));
    let factor = p.with_scale_factor(2.0);
    assert_eq!((factor.levels, factor.scale_factor), (5, 2.0));
    assert_eq!(Pyramid::default(), Pyramid::DEFAULT);
    assert_eq!(Pyramid::DEFAULT, Pyramid::new(8, 1.2));
    // Still checked where it is used.
    let too_deep = ExtractorConfig::default().with_pyramid(Some(p.with_levels(33)));
    assert!(Extractor::new(Backend::Cpu, too_deep).is_err());
}

#[test]
fn decode_limits_and_photos_are_made_by_their_methods() {
    let limits = DecodeLimits::default().with_max_pixels(1234);
    assert_eq!(limits.max_pixels, 1234);
    assert_eq!(
        DecodeLimits::default().max_pixels,
        DecodeLimits::DEFAULT_MAX_PIXELS
    );

    let keypoints = vec![KeyPoint::new(1.0, 2.0)];
    let photo = Photo::new("a.jpg", 64, 48, keypoints.clone());
    assert_eq!(
        (
            photo.name.as_str(),
            photo.width,
            photo.height,
            photo.focal_35mm
        ),
        ("a.jpg", 64, 48, None)
    );
    assert_eq!(photo.keypoints, keypoints);
    let with_focal = photo.clone().with_focal_35mm(Some(35));
    assert_eq!(with_focal.focal_35mm, Some(35));
    assert_eq!(with_focal.with_focal_35mm(None), photo);
}
