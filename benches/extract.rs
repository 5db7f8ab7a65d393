//! Extraction benchmarks on a 1024x768 synthetic image: description of ~2000 and ~10000 keypoints
//! (throughput in keypoints = descriptors per second), detection alone, detection + description
//! with and without the pyramid option, and the CPU describe on one thread and on all threads, same
//! photograph and keypoints (`assets/astronaut.png` enlarged to 1024x768, 5000 detected keypoints: the
//! image `tools/cpu_vs_opencv.py` compares with OpenCV), and the smoothing before description alone on
//! a 2832x2128 image (a 6-megapixel photo).
//!
//! `cargo bench --bench extract`

use std::hint::black_box;
use std::time::Duration;

use clatch::synthetic::SplitMix64;
use clatch::{Backend, Extractor, ExtractorConfig, GrayView, KeyPoint, Smoothing};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

const WIDTH: usize = 1024;
const HEIGHT: usize = 768;

/// `n` keypoints inside the detector margin, random angles: every one is described.
fn keypoints(n: usize) -> Vec<KeyPoint> {
    // The margin of 64-pixel windows: these keypoints have the default size of `KeyPoint::new`.
    let margin = ExtractorConfig::single_scale().detector.margin();
    let mut rng = SplitMix64::new(1);
    (0..n)
        .map(|_| {
            let x = margin + rng.below((WIDTH - 2 * margin) as u64) as usize;
            let y = margin + rng.below((HEIGHT - 2 * margin) as u64) as usize;
            KeyPoint::new(x as f32, y as f32).with_angle(rng.below(3600) as f32 / 10.0)
        })
        .collect()
}

fn extraction(c: &mut Criterion) {
    let pixels = clatch::synthetic::rectangles(WIDTH, HEIGHT, 1).expect("synthetic image");
    let image = GrayView::new(&pixels, WIDTH, HEIGHT, WIDTH).unwrap();
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();

    let mut group = c.benchmark_group("describe 1024x768");
    group
        .measurement_time(Duration::from_secs(4))
        .sample_size(10);
    for n in [2000, 10000] {
        let kps = keypoints(n);
        assert!(extractor.describe(&image, &kps).unwrap().skipped.is_empty());
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::from_parameter(n), &kps, |b, kps| {
            b.iter(|| {
                extractor
                    .describe(black_box(&image), black_box(kps))
                    .unwrap()
            })
        });
    }
    group.finish();

    let mut group = c.benchmark_group("detect 1024x768");
    group
        .measurement_time(Duration::from_secs(4))
        .sample_size(20);
    let found = extractor.detect(&image).unwrap().len();
    group.throughput(Throughput::Elements((WIDTH * HEIGHT) as u64));
    group.bench_function(
        BenchmarkId::new("pixels", format!("{found} keypoints")),
        |b| b.iter(|| extractor.detect(black_box(&image)).unwrap()),
    );
    group.finish();

    // Whole calls on a photograph, per keypoint (throughput in keypoints): the default (8-level pyramid,
    // sub-pixel positions) against the single-scale speed preset, which was the default before.
    let (photo, _) = astronaut_and_keypoints();
    let photo = GrayView::new(photo.as_raw(), WIDTH, HEIGHT, WIDTH).unwrap();
    let mut group = c.benchmark_group("detect_and_describe photo 1024x768");
    group
        .measurement_time(Duration::from_secs(6))
        .sample_size(10);
    let pyramid_3_2 = ExtractorConfig::default().with_pyramid(Some(clatch::Pyramid::new(3, 2.0)));
    for (name, config) in [
        ("single_scale preset", ExtractorConfig::single_scale()),
        ("default", ExtractorConfig::default()),
        ("pyramid 3:2", pyramid_3_2),
    ] {
        let extractor = Extractor::new(Backend::Cpu, config).unwrap();
        let found = extractor.detect(&photo).unwrap().len();
        group.throughput(Throughput::Elements(found as u64));
        group.bench_function(BenchmarkId::new(name, format!("{found} keypoints")), |b| {
            b.iter(|| extractor.detect_and_describe(black_box(&photo)).unwrap())
        });
    }
    group.finish();
}

/// The embedded photograph enlarged to 1024x768 (bilinear) and its 5000 strongest keypoints.
fn astronaut_and_keypoints() -> (image::GrayImage, Vec<KeyPoint>) {
    let decoded = image::load_from_memory(include_bytes!("../assets/astronaut.png")).unwrap();
    let gray = clatch::decode::gray_from_dynamic(&decoded);
    let big = image::imageops::resize(
        &gray,
        WIDTH as u32,
        HEIGHT as u32,
        image::imageops::FilterType::Triangle,
    );
    let mut config = ExtractorConfig::single_scale();
    config.detector.max_keypoints = 5000;
    config.detector.threshold = 6;
    let view = GrayView::new(big.as_raw(), WIDTH, HEIGHT, WIDTH).unwrap();
    let keypoints = Extractor::new(Backend::Cpu, config)
        .unwrap()
        .detect(&view)
        .unwrap();
    (big, keypoints)
}

fn describe_threads(c: &mut Criterion) {
    let (big, kps) = astronaut_and_keypoints();
    let image = GrayView::new(big.as_raw(), WIDTH, HEIGHT, WIDTH).unwrap();
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default()).unwrap();
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut group = c.benchmark_group(format!(
        "cpu describe astronaut 1024x768, {} keypoints",
        kps.len()
    ));
    group
        .measurement_time(Duration::from_secs(4))
        .sample_size(20)
        .throughput(Throughput::Elements(kps.len() as u64));
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        assert!(extractor.describe(&image, &kps).unwrap().skipped.is_empty());
        group.bench_function(BenchmarkId::new("threads", threads), |b| {
            b.iter(|| {
                pool.install(|| {
                    extractor
                        .describe(black_box(&image), black_box(&kps))
                        .unwrap()
                })
            })
        });
    }
    group.finish();
}

/// `describe::cpu::smooth` of a 2832x2128 image (the whole image, as description smooths it).
fn smoothing(c: &mut Criterion) {
    let (w, h) = (2832, 2128);
    let pixels = clatch::synthetic::noise(w, h, 3).expect("synthetic image");
    let image = GrayView::new(&pixels, w, h, w).unwrap();
    let mut group = c.benchmark_group("smooth 2832x2128");
    group
        .measurement_time(Duration::from_secs(4))
        .sample_size(20)
        .throughput(Throughput::Elements((w * h) as u64));
    for smoothing in [Smoothing::Binomial3, Smoothing::Binomial5] {
        group.bench_function(BenchmarkId::from_parameter(format!("{smoothing:?}")), |b| {
            b.iter(|| clatch::describe::cpu::smooth(black_box(&image), smoothing))
        });
    }
    group.finish();
}

criterion_group!(benches, extraction, describe_threads, smoothing);
criterion_main!(benches);
