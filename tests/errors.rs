//! Every bad input gives its exact typed `clatch::Error` through the public API, never a panic.

use clatch::describe::MAX_WEIGHT_SUM;
use clatch::{
    Backend, DescriptorConfig, DescriptorSet, DescriptorWidth, DetectorConfig, Error, Extractor,
    ExtractorConfig, GrayView, KeyPoint, MatchConfig, Matcher, PatchWeights,
};

fn extractor() -> Extractor {
    Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap()
}

fn image(width: usize, height: usize) -> Vec<u8> {
    clatch::synthetic::noise(width, height, 5).expect("synthetic image")
}

fn width(bits: usize) -> DescriptorWidth {
    DescriptorWidth::from_bits(bits).unwrap()
}

fn set(bits: usize, count: usize) -> DescriptorSet {
    let w = width(bits);
    let words = (0..count * w.words()).map(|i| i as u64 * 0x9E37).collect();
    DescriptorSet::from_words(w, words).unwrap()
}

fn matcher(ratio: Option<f32>) -> Matcher {
    Matcher::new(
        Backend::Cpu,
        MatchConfig::default()
            .with_ratio(ratio)
            .with_cross_check(true)
            .with_max_distance(None),
    )
    .unwrap()
}

/// Describes `bad` placed at index 2 after two valid keypoints on a 100x80 image.
fn describe_with(bad: KeyPoint) -> clatch::Result<clatch::Features> {
    let pixels = image(100, 80);
    let view = GrayView::new(&pixels, 100, 80, 100).unwrap();
    let ok = KeyPoint::new(50.0, 40.0);
    extractor().describe(&view, &[ok, ok, bad])
}

fn assert_bad_keypoint(bad: KeyPoint, field: &str) {
    let result = describe_with(bad);
    assert!(
        matches!(result, Err(Error::InvalidKeyPoint { index: 2, field: f, .. }) if f == field),
        "{bad:?}: {result:?}"
    );
}

// ---- images ----

#[test]
fn zero_width_image() {
    assert!(matches!(
        GrayView::new(&[], 0, 10, 0),
        Err(Error::EmptyImage {
            width: 0,
            height: 10
        })
    ));
}

#[test]
fn zero_height_image() {
    let pixels = image(10, 1);
    assert!(matches!(
        GrayView::new(&pixels, 10, 0, 10),
        Err(Error::EmptyImage {
            width: 10,
            height: 0
        })
    ));
}

#[test]
fn zero_sized_image_with_empty_buffer() {
    assert!(matches!(
        GrayView::new(&[], 0, 0, 0),
        Err(Error::EmptyImage {
            width: 0,
            height: 0
        })
    ));
}

#[test]
fn stride_smaller_than_width() {
    let pixels = image(100, 100);
    assert!(matches!(
        GrayView::new(&pixels, 100, 100, 99),
        Err(Error::StrideTooSmall {
            width: 100,
            stride: 99
        })
    ));
}

#[test]
fn buffer_too_small() {
    // 70x70 with stride 80 needs 80 * 69 + 70 = 5590 bytes; one fewer is an error, exactly that many is not.
    let pixels = image(80, 70);
    assert!(matches!(
        GrayView::new(&pixels[..5589], 70, 70, 80),
        Err(Error::BufferTooSmall {
            width: 70,
            height: 70,
            stride: 80,
            needed: 5590,
            got: 5589
        })
    ));
    assert!(GrayView::new(&pixels[..5590], 70, 70, 80).is_ok());
    assert!(matches!(
        GrayView::new(&[], 1, 1, 1),
        Err(Error::BufferTooSmall {
            needed: 1,
            got: 0,
            ..
        })
    ));
}

#[test]
fn image_too_large() {
    let pixels = vec![0u8; 32_768];
    assert!(matches!(
        GrayView::new(&pixels, 32_768, 1, 32_768),
        Err(Error::ImageTooLarge {
            width: 32_768,
            height: 1,
            max: 32_767
        })
    ));
}

/// A stride so large that `stride * (height - 1) + width` overflows `usize` must be rejected with
/// `BufferTooSmall` (no buffer can hold such an image). Today `GrayView::new` computes
/// `stride * (height - 1) + width` unchecked: with overflow checks (the test profile) it panics with
/// "attempt to multiply with overflow"; in release it wraps (here to `10`), the check passes, and the first
/// `row(1)` then indexes `data[2^63..]` and panics.
#[test]
fn huge_stride_is_an_error_not_a_panic() {
    let pixels = vec![0u8; 64];
    let result =
        std::panic::catch_unwind(|| GrayView::new(&pixels, 10, 3, 1usize << 63).map(|v| v.width()));
    assert!(
        matches!(result, Ok(Err(Error::BufferTooSmall { .. }))),
        "{result:?}"
    );
}

#[test]
fn detect_on_an_image_smaller_than_the_window() {
    let pixels = image(64, 64);
    for (w, h) in [(63, 64), (64, 63), (10, 10)] {
        let view = GrayView::new(&pixels, w, h, w).unwrap();
        let result = extractor().detect(&view);
        assert!(
            matches!(result, Err(Error::ImageTooSmall { width, height, min: 64 }) if (width, height) == (w, h)),
            "{w}x{h}: {result:?}"
        );
        assert!(matches!(
            extractor().detect_and_describe(&view),
            Err(Error::ImageTooSmall { min: 64, .. })
        ));
    }
    // 64x64 itself is accepted (and, single scale, too small to have a keypoint with the 48-pixel
    // margin of 64-pixel windows).
    let view = GrayView::new(&pixels, 64, 64, 64).unwrap();
    let single_scale = Extractor::new(Backend::Cpu, ExtractorConfig::single_scale()).unwrap();
    assert_eq!(single_scale.detect(&view).unwrap(), vec![]);
    assert!(extractor().detect(&view).is_ok());
}

#[test]
fn describe_on_an_image_smaller_than_the_window() {
    let pixels = image(64, 64);
    for (w, h) in [(63, 64), (64, 63)] {
        let view = GrayView::new(&pixels, w, h, w).unwrap();
        let result = extractor().describe(&view, &[KeyPoint::new(31.0, 31.0)]);
        assert!(
            matches!(result, Err(Error::ImageTooSmall { width, height, min: 64 }) if (width, height) == (w, h)),
            "{w}x{h}: {result:?}"
        );
        // Even with no keypoints: the image is checked first.
        assert!(matches!(
            extractor().describe(&view, &[]),
            Err(Error::ImageTooSmall { .. })
        ));
    }
}

// ---- keypoints ----

#[test]
fn nan_x() {
    assert_bad_keypoint(KeyPoint::new(f32::NAN, 40.0), "x");
}

#[test]
fn infinite_x() {
    assert_bad_keypoint(KeyPoint::new(f32::INFINITY, 40.0), "x");
    assert_bad_keypoint(KeyPoint::new(f32::NEG_INFINITY, 40.0), "x");
}

#[test]
fn negative_x() {
    assert_bad_keypoint(KeyPoint::new(-0.5, 40.0), "x");
    assert_bad_keypoint(KeyPoint::new(-f32::MIN_POSITIVE, 40.0), "x");
}

#[test]
fn x_past_the_last_column() {
    // 100 columns: x = 99 is the last pixel centre (valid, though its window is skipped), 99.01 is outside.
    assert_bad_keypoint(KeyPoint::new(99.01, 40.0), "x");
    let described = describe_with(KeyPoint::new(99.0, 40.0)).unwrap();
    assert_eq!(described.keypoint_index, vec![0, 1]);
    assert_eq!(described.skipped.len(), 1);
}

#[test]
fn nan_y() {
    assert_bad_keypoint(KeyPoint::new(50.0, f32::NAN), "y");
}

#[test]
fn infinite_y() {
    assert_bad_keypoint(KeyPoint::new(50.0, f32::INFINITY), "y");
    assert_bad_keypoint(KeyPoint::new(50.0, f32::NEG_INFINITY), "y");
}

#[test]
fn negative_y() {
    assert_bad_keypoint(KeyPoint::new(50.0, -1.0), "y");
}

#[test]
fn y_past_the_last_row() {
    assert_bad_keypoint(KeyPoint::new(50.0, 79.5), "y");
}

#[test]
fn nan_size() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_size(f32::NAN), "size");
}

#[test]
fn infinite_size() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_size(f32::INFINITY), "size");
}

#[test]
fn negative_size() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_size(-64.0), "size");
}

#[test]
fn zero_size() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_size(0.0), "size");
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_size(0.999), "size");
}

#[test]
fn size_over_1024() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_size(1024.5), "size");
    // The limits themselves are accepted (1024 does not fit this image: skipped, not an error).
    let described = describe_with(KeyPoint::new(50.0, 40.0).with_size(1024.0)).unwrap();
    assert_eq!(described.skipped.len(), 1);
    assert_eq!(
        describe_with(KeyPoint::new(50.0, 40.0).with_size(1.0))
            .unwrap()
            .keypoint_index,
        vec![0, 1, 2]
    );
}

#[test]
fn infinite_angle() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_angle(f32::INFINITY), "angle");
    assert_bad_keypoint(
        KeyPoint::new(50.0, 40.0).with_angle(f32::NEG_INFINITY),
        "angle",
    );
}

#[test]
fn nan_angle() {
    assert_bad_keypoint(KeyPoint::new(50.0, 40.0).with_angle(f32::NAN), "angle");
}

#[test]
fn huge_finite_angle_is_fine() {
    let described = describe_with(KeyPoint::new(50.0, 40.0).with_angle(f32::MAX)).unwrap();
    assert_eq!(described.keypoint_index, vec![0, 1, 2]);
}

#[test]
fn zero_keypoints_give_an_empty_result() {
    let pixels = image(100, 80);
    let view = GrayView::new(&pixels, 100, 80, 100).unwrap();
    let described = extractor().describe(&view, &[]).unwrap();
    assert!(described.descriptors.is_empty());
    assert_eq!(described.descriptors.len(), 0);
    assert_eq!(described.descriptors.width(), DescriptorWidth::FULL);
    assert!(described.keypoint_index.is_empty());
    assert!(described.skipped.is_empty());
}

// ---- matching ----

#[test]
fn empty_gallery() {
    let empty = DescriptorSet::empty(DescriptorWidth::FULL);
    let query = set(512, 3);
    assert!(matches!(
        matcher(None).knn(&query, &empty, 1),
        Err(Error::EmptyGallery)
    ));
    assert!(matches!(
        matcher(None).match_descriptors(&query, &empty),
        Err(Error::EmptyGallery)
    ));
    assert!(matches!(
        matcher(Some(0.8)).match_descriptors(&query, &empty),
        Err(Error::EmptyGallery)
    ));
}

#[test]
fn k_zero() {
    assert!(matches!(
        matcher(None).knn(&set(512, 3), &set(512, 4), 0),
        Err(Error::InvalidK { k: 0, gallery: 4 })
    ));
}

#[test]
fn k_larger_than_the_gallery() {
    assert!(matches!(
        matcher(None).knn(&set(512, 3), &set(512, 4), 5),
        Err(Error::InvalidK { k: 5, gallery: 4 })
    ));
    assert!(matches!(
        matcher(None).knn(&set(512, 3), &set(512, 4), usize::MAX),
        Err(Error::InvalidK { gallery: 4, .. })
    ));
    assert_eq!(
        matcher(None)
            .knn(&set(512, 3), &set(512, 4), 4)
            .unwrap()
            .len(),
        3
    );
}

#[test]
fn descriptor_width_mismatch() {
    let (query, train) = (set(256, 3), set(512, 4));
    assert!(matches!(
        matcher(None).knn(&query, &train, 1),
        Err(Error::DescriptorWidthMismatch {
            query_bits: 256,
            train_bits: 512
        })
    ));
    assert!(matches!(
        matcher(Some(0.8)).match_descriptors(&query, &train),
        Err(Error::DescriptorWidthMismatch {
            query_bits: 256,
            train_bits: 512
        })
    ));
    // Same number of words (72 and 128 bits are both 2 words), different widths.
    assert!(matches!(
        matcher(None).knn(&set(128, 1), &set(72, 1), 1),
        Err(Error::DescriptorWidthMismatch {
            query_bits: 128,
            train_bits: 72
        })
    ));
}

#[test]
fn ratio_test_with_a_one_descriptor_gallery() {
    assert!(matches!(
        matcher(Some(0.8)).match_descriptors(&set(512, 3), &set(512, 1)),
        Err(Error::InvalidK { k: 2, gallery: 1 })
    ));
    // Without the ratio test one gallery descriptor is enough.
    assert_eq!(
        matcher(None)
            .match_descriptors(&set(512, 3), &set(512, 1))
            .unwrap()
            .len(),
        1,
        "cross-check keeps only the nearest query of the single gallery descriptor"
    );
}

#[test]
fn bad_ratio() {
    for ratio in [f32::NAN, 0.0, 1.5, -0.5, f32::INFINITY, 1.0000001] {
        let result = Matcher::new(Backend::Cpu, MatchConfig::default().with_ratio(Some(ratio)));
        assert!(
            matches!(result, Err(Error::InvalidConfig { field: "ratio", .. })),
            "{ratio}: {result:?}"
        );
    }
    for ratio in [1.0, f32::MIN_POSITIVE, 0.5] {
        let config = MatchConfig::default().with_ratio(Some(ratio));
        assert!(Matcher::new(Backend::Cpu, config).is_ok(), "{ratio}");
    }
}

#[test]
fn descriptor_buffer_length() {
    assert!(matches!(
        DescriptorSet::from_words(width(72), vec![0; 3]),
        Err(Error::DescriptorBufferLength {
            words: 3,
            words_per_descriptor: 2
        })
    ));
}

// ---- weights ----

#[test]
fn weights_of_wrong_length() {
    for len in [63, 65, 0] {
        assert!(
            matches!(
                PatchWeights::new(&vec![1; len]),
                Err(Error::WeightsLength { expected: 64, got }) if got == len
            ),
            "{len}"
        );
    }
}

#[test]
fn weights_overflowing() {
    let mut weights = vec![0u32; 64];
    weights[0] = MAX_WEIGHT_SUM as u32;
    assert!(PatchWeights::new(&weights).is_ok(), "the maximum itself");
    weights[63] = 1;
    assert!(matches!(
        PatchWeights::new(&weights),
        Err(Error::WeightsOverflow { sum, max: MAX_WEIGHT_SUM }) if sum == MAX_WEIGHT_SUM + 1
    ));
    // u32::MAX everywhere: the sum must not wrap.
    assert!(matches!(
        PatchWeights::new(&[u32::MAX; 64]),
        Err(Error::WeightsOverflow { sum, .. }) if sum == 64 * u32::MAX as u64
    ));
}

#[test]
fn weights_all_zero() {
    assert!(matches!(
        PatchWeights::new(&[0; 64]),
        Err(Error::WeightsAllZero)
    ));
}

#[test]
fn weights_at_the_limit_describe_without_overflow() {
    // The largest allowed weights on maximal-contrast pixels: d stays inside i32 (overflow checks are on).
    let mut w = vec![0u32; 64];
    w[9] = MAX_WEIGHT_SUM as u32;
    let config = ExtractorConfig::default()
        .with_descriptor(DescriptorConfig::default().with_weights(PatchWeights::new(&w).unwrap()));
    let pixels: Vec<u8> = (0..100 * 100)
        .map(|i| if (i / 7 + i / 700) % 2 == 0 { 0 } else { 255 })
        .collect();
    let view = GrayView::new(&pixels, 100, 100, 100).unwrap();
    let extractor = Extractor::new(Backend::Cpu, config).unwrap();
    let described = extractor
        .describe(&view, &[KeyPoint::new(50.0, 50.0)])
        .unwrap();
    assert_eq!(described.descriptors.len(), 1);
}

// ---- configurations ----

fn detector_error(detector: DetectorConfig) -> clatch::Result<Extractor> {
    Extractor::new(
        Backend::Cpu,
        ExtractorConfig::default().with_detector(detector),
    )
}

#[test]
fn detector_threshold_0_and_255() {
    for threshold in [0, 255] {
        let result = detector_error(DetectorConfig::default().with_threshold(threshold));
        assert!(
            matches!(&result, Err(Error::InvalidConfig { field: "threshold", value, .. }) if *value == threshold.to_string()),
            "{threshold}: {result:?}"
        );
    }
    for threshold in [1, 254] {
        assert!(detector_error(DetectorConfig::default().with_threshold(threshold)).is_ok());
    }
}

#[test]
fn pyramid_levels_and_factor_out_of_range() {
    let with = |levels, scale_factor, keypoint_size| {
        Extractor::new(
            Backend::Cpu,
            ExtractorConfig::default()
                .with_detector(DetectorConfig::default().with_keypoint_size(keypoint_size))
                .with_pyramid(Some(clatch::Pyramid::new(levels, scale_factor))),
        )
    };
    for (levels, factor, size, field) in [
        (0, 2.0, 64.0, "pyramid.levels"),
        (33, 1.01, 1.0, "pyramid.levels"),
        // 64 · 2^5 = 2048 > 1024; with size 32 the same pyramid is fine.
        (6, 2.0, 64.0, "pyramid.levels"),
        (3, 1.0, 64.0, "pyramid.scale_factor"),
        (3, 0.5, 64.0, "pyramid.scale_factor"),
        (3, 2.5, 64.0, "pyramid.scale_factor"),
        (3, f32::NAN, 64.0, "pyramid.scale_factor"),
    ] {
        let result = with(levels, factor, size);
        assert!(
            matches!(&result, Err(Error::InvalidConfig { field: f, .. }) if *f == field),
            "{levels} {factor} {size}: {result:?}"
        );
    }
    assert!(with(6, 2.0, 32.0).is_ok());
    assert!(with(1, 1.5, 1024.0).is_ok());
}

#[test]
fn detector_max_keypoints_0() {
    assert!(matches!(
        detector_error(DetectorConfig::default().with_max_keypoints(0)),
        Err(Error::InvalidConfig {
            field: "max_keypoints",
            ..
        })
    ));
}

#[test]
fn detector_keypoint_size() {
    for size in [0.0, 0.5, 1024.5, f32::NAN, f32::INFINITY, -64.0] {
        let result = detector_error(DetectorConfig::default().with_keypoint_size(size));
        assert!(
            matches!(
                result,
                Err(Error::InvalidConfig {
                    field: "keypoint_size",
                    ..
                })
            ),
            "{size}: {result:?}"
        );
    }
}

#[test]
fn descriptor_width_0_7_520() {
    for bits in [0, 7, 520, 100, 513] {
        assert!(
            matches!(
                DescriptorWidth::from_bits(bits),
                Err(Error::InvalidDescriptorWidth { bits: b }) if b == bits
            ),
            "{bits}"
        );
    }
    assert!(matches!(
        DescriptorWidth::from_bytes(0),
        Err(Error::InvalidDescriptorWidth { bits: 0 })
    ));
    assert!(matches!(
        DescriptorWidth::from_bytes(65),
        Err(Error::InvalidDescriptorWidth { bits: 520 })
    ));
    for bits in [8, 136, 512] {
        assert_eq!(DescriptorWidth::from_bits(bits).unwrap().bits(), bits);
    }
}

// ---- descriptor sets ----

#[test]
fn descriptor_index_past_the_end_is_none() {
    let s = set(512, 3);
    assert!(s.get(2).is_some());
    assert!(s.get(3).is_none());
    assert!(s.descriptor(3).is_none());
    assert!(s.get(1000).is_none());
}

/// `DescriptorSet::get` is documented to return `None` past the end, but computes `i * per` and
/// `(i + 1) * per` unchecked (src/descriptor.rs): for `i = 2^61` and 8 words per descriptor the product
/// overflows. With overflow checks (the test profile) it panics; in release it wraps to `0..8` and
/// returns descriptor 0 for an index far past the end (checked: `Ok(Some(..))`).
#[test]
fn huge_descriptor_index_is_none_not_a_panic_or_row_0() {
    let s = set(512, 3);
    let result = std::panic::catch_unwind(|| s.get(1 << 61).map(|row| row.to_vec()));
    assert!(matches!(result, Ok(None)), "{result:?}");
    let result = std::panic::catch_unwind(|| s.descriptor(1 << 61));
    assert!(matches!(result, Ok(None)), "{result:?}");
    let result = std::panic::catch_unwind(|| s.get(usize::MAX).is_none());
    assert!(matches!(result, Ok(true)), "{result:?}");
}
