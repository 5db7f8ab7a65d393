//! GPU detection timings: `cargo bench --features cuda --bench gpu_detect`.
//!
//! - detection alone: all of its launches (scores + suppression, scan, scatter, orientation) between two
//!   CUDA events on its stream, after warm-up; the image upload and the read-back are excluded;
//! - detection + description: the detection time plus the describe kernel's event-timed time on the
//!   detected keypoints (both device-only), and the wall-clock time of the whole
//!   `Extractor::detect_and_describe` call (uploads, host round trip and read-backs included), with the
//!   CPU reference's wall-clock time beside it.
//!
//! - the pyramid option (1, 3 levels of factor 2, 8 of factor 1.2) on 1080p: wall clock of the whole
//!   call on both backends.
//!
//! Medians of the repeats are reported with the device's name.

#[cfg(feature = "cuda")]
mod common;

#[cfg(not(feature = "cuda"))]
fn main() {
    println!("skipped: no CUDA device (built without the `cuda` feature)");
}

#[cfg(feature = "cuda")]
fn main() {
    use std::time::Instant;

    use clatch::{Backend, DetectorConfig, Extractor, ExtractorConfig, GrayView};

    const WARMUP: usize = 3;
    const REPEATS: usize = 15;

    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let wall = |runs: usize, f: &mut dyn FnMut()| {
        median(
            (0..runs)
                .map(|_| {
                    let start = Instant::now();
                    f();
                    start.elapsed().as_secs_f64() * 1e3
                })
                .collect(),
        )
    };
    for (name, w, h) in [("1080p", 1920usize, 1080usize), ("5616x3744", 5616, 3744)] {
        let pixels = clatch::synthetic::rectangles(w, h, 9).expect("synthetic image");
        let image = GrayView::new(&pixels, w, h, w).unwrap();
        // The default threshold (20) finds ~1.7k (1080p) and ~2.3k (5616x3744) corners on this image;
        // threshold 2 also fires on its +-2 noise: 11.5k and 54k survivors, cut to 20k on the large one.
        for (threshold, max_keypoints) in [(20u8, usize::MAX), (2, 20_000)] {
            let detector = DetectorConfig::default()
                .with_threshold(threshold)
                .with_max_keypoints(max_keypoints);
            let (times, keypoints) =
                clatch::cuda::hooks::time_detect(&dev, &image, &detector, WARMUP, REPEATS)
                    .expect("detection kernels");
            let detect_ms = median(times.into_iter().map(f64::from).collect());
            let limit = if max_keypoints == usize::MAX {
                format!("t {threshold:>2}, all")
            } else {
                format!("t {threshold:>2}, max {max_keypoints}")
            };
            println!(
                "detect          {name:>9} ({limit:>14}): {:>7} keypoints  median {detect_ms:8.3} ms  {:7.1} Mpixel/s",
                keypoints.len(),
                (w * h) as f64 / detect_ms / 1e3
            );
            if keypoints.is_empty() {
                continue;
            }
            let describe_ms = median(
                clatch::cuda::hooks::time_describe_kernel(
                    &dev,
                    &image,
                    &keypoints,
                    &Default::default(),
                    WARMUP,
                    REPEATS,
                )
                .expect("describe kernel")
                .into_iter()
                .map(f64::from)
                .collect(),
            );
            println!(
                "detect+describe {name:>9} ({limit:>14}): {:>7} keypoints  median {:8.3} ms on the device (detect {detect_ms:.3} + describe {describe_ms:.3})",
                keypoints.len(),
                detect_ms + describe_ms
            );
            let config = ExtractorConfig::default().with_detector(detector);
            let gpu = Extractor::new(Backend::Cuda { device: 0 }, config.clone()).unwrap();
            let cpu = Extractor::new(Backend::Cpu, config).unwrap();
            gpu.detect_and_describe(&image).unwrap();
            let gpu_ms = wall(REPEATS, &mut || {
                gpu.detect_and_describe(&image).unwrap();
            });
            let cpu_ms = wall(3, &mut || {
                cpu.detect_and_describe(&image).unwrap();
            });
            println!(
                "detect+describe {name:>9} ({limit:>14}): wall clock, whole call: GPU {gpu_ms:8.3} ms, CPU ({} threads) {cpu_ms:8.3} ms",
                rayon::current_num_threads()
            );
        }
    }
    // The pyramid option: whole calls (levels, detection per level, the host's top-N, description per
    // level, read-backs), default detector.
    let (w, h) = (1920usize, 1080usize);
    let pixels = clatch::synthetic::rectangles(w, h, 9).expect("synthetic image");
    let image = GrayView::new(&pixels, w, h, w).unwrap();
    for (levels, scale_factor) in [(1usize, 2.0f32), (3, 2.0), (8, 1.2)] {
        let config = ExtractorConfig::default()
            .with_pyramid(Some(clatch::Pyramid::new(levels, scale_factor)));
        let gpu = Extractor::new(Backend::Cuda { device: 0 }, config.clone()).unwrap();
        let cpu = Extractor::new(Backend::Cpu, config).unwrap();
        let found = gpu.detect_and_describe(&image).unwrap().keypoints.len();
        let gpu_ms = wall(REPEATS, &mut || {
            gpu.detect_and_describe(&image).unwrap();
        });
        let cpu_ms = wall(3, &mut || {
            cpu.detect_and_describe(&image).unwrap();
        });
        println!(
            "pyramid {levels}:{scale_factor} 1080p: {found:>6} keypoints, wall clock, whole call: GPU {gpu_ms:8.3} ms, CPU ({} threads) {cpu_ms:8.3} ms",
            rayon::current_num_threads()
        );
    }
}
