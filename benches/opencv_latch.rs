//! OpenCV-compatible LATCH: description of 5000 keypoints on a 1024x768 synthetic image (throughput in
//! descriptors per second), OpenCV's defaults (32 bytes, sigma 2) and 64 bytes, on the CPU and, with the
//! `cuda` feature and a device, on the GPU (whole call: host blur, upload, kernel, download).
//!
//! `cargo bench --bench opencv_latch` (`--features cuda` for the GPU rows)

use std::hint::black_box;
use std::time::Duration;

use clatch::synthetic::SplitMix64;
use clatch::{Backend, Extractor, ExtractorConfig, GrayView, KeyPoint, OpencvLatch};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

const WIDTH: usize = 1024;
const HEIGHT: usize = 768;
const KEYPOINTS: usize = 5000;

fn backends() -> Vec<Backend> {
    #[allow(unused_mut)]
    let mut backends = vec![Backend::Cpu];
    #[cfg(feature = "cuda")]
    match clatch::cuda::hooks::device(0) {
        Ok(_) => backends.push(Backend::Cuda { device: 0 }),
        Err(e) => println!("skipped: no CUDA device ({e})"),
    }
    backends
}

fn opencv_latch(c: &mut Criterion) {
    let pixels = clatch::synthetic::rectangles(WIDTH, HEIGHT, 1).expect("synthetic image");
    let image = GrayView::new(&pixels, WIDTH, HEIGHT, WIDTH).unwrap();
    let mut rng = SplitMix64::new(2);
    // Inside OpenCV's 27-pixel border: every keypoint is described.
    let keypoints: Vec<KeyPoint> = (0..KEYPOINTS)
        .map(|_| {
            KeyPoint::new(
                28.0 + rng.below((WIDTH as u64 - 56) * 4) as f32 / 4.0,
                28.0 + rng.below((HEIGHT as u64 - 56) * 4) as f32 / 4.0,
            )
            .with_angle(rng.below(36_000) as f32 / 100.0)
        })
        .collect();
    let mut group = c.benchmark_group("opencv latch 1024x768, 5000 keypoints");
    group
        .measurement_time(Duration::from_secs(4))
        .sample_size(10)
        .throughput(Throughput::Elements(KEYPOINTS as u64));
    for backend in backends() {
        let extractor = Extractor::new(backend, ExtractorConfig::default()).unwrap();
        for latch in [
            OpencvLatch::default(),
            OpencvLatch::new(64, true, 3, 2.0).unwrap(),
        ] {
            let described = extractor
                .describe_opencv(&latch, &image, &keypoints)
                .unwrap();
            assert!(described.skipped.is_empty());
            let id = BenchmarkId::new(backend.to_string(), format!("{} bytes", latch.bytes()));
            group.bench_with_input(id, &latch, |b, latch| {
                b.iter(|| {
                    extractor
                        .describe_opencv(latch, black_box(&image), black_box(&keypoints))
                        .unwrap()
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, opencv_latch);
criterion_main!(benches);
