//! Whole extraction calls against the device's busy time for them (extraction side):
//! `cargo bench --features cuda --bench gpu_extract_stream`.
//!
//! - A 1080p frame stream: `CLATCH_BENCH_FRAMES` (default 2000, at least 1000) frames from page-locked
//!   host memory (16 distinct synthetic frames, cycled), through `detect_and_describe_stream` (the
//!   pool's 4 streams, 8 frames in flight): frames/s of the whole run (wall clock) against the
//!   device-only bound, 1 / (device busy time of one frame), the busy time measured by CUDA events
//!   around the device work of a lone call (host round trips excluded; median of 50).
//! - One 5616x3744 photo already in host memory, pageable and page-locked, 20k keypoints: the whole
//!   blocking call (median of 20 after warm-up), with its device busy time.
//!
//! Configurations: the single-scale preset at threshold 20 (about 1.7k keypoints on the 1080p frame:
//! about 0.10 ms on the device) and the default pyramid; for the photo, single scale at threshold 2
//! capped at 20k (about 0.86 ms on the device) and the default pyramid at threshold
//! 10 capped at 20k. Every GPU result is checked against the CPU's once per configuration.

#[cfg(feature = "cuda")]
mod common;

#[cfg(not(feature = "cuda"))]
fn main() {
    println!("skipped: no CUDA device (built without the `cuda` feature)");
}

#[cfg(feature = "cuda")]
fn main() {
    use std::time::Instant;

    use clatch::cuda::hooks::{PinnedBytes, device_time, is_pinned_for_upload};
    use clatch::{Backend, Error, Extractor, ExtractorConfig, GrayView};

    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    let gpu_backend = Backend::Cuda { device: 0 };
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    // `base` with another threshold and keypoint cap, the same at every image size (the budget
    // that grows above a megapixel would turn the 20k cap of the large photo into 80k).
    let with = |mut base: ExtractorConfig, threshold: u8, max_keypoints: usize| {
        base.detector = base
            .detector
            .with_threshold(threshold)
            .with_max_keypoints(max_keypoints)
            .with_budget_pixels(None);
        base
    };
    let single = |threshold, max| with(ExtractorConfig::single_scale(), threshold, max);
    let pyramid = |threshold, max| with(ExtractorConfig::default(), threshold, max);
    // Pinned copies of `frames` (rows packed).
    let pin = |frames: &[Vec<u8>]| -> Vec<PinnedBytes> {
        frames
            .iter()
            .map(|f| {
                let mut p = PinnedBytes::new(0, f.len()).expect("page-locked host memory");
                p.as_mut_slice().expect("pinned bytes").copy_from_slice(f);
                p
            })
            .collect()
    };

    // --- The 1080p frame stream.
    let (w, h) = (1920usize, 1080usize);
    let n_frames: usize = std::env::var("CLATCH_BENCH_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000)
        .max(1000);
    let frames: Vec<Vec<u8>> = (0..16)
        .map(|i| clatch::synthetic::rectangles(w, h, 70 + i as u64).expect("synthetic image"))
        .collect();
    let pinned = pin(&frames);
    let views: Vec<GrayView> = pinned
        .iter()
        .map(|p| GrayView::new(p.as_slice().expect("pinned bytes"), w, h, w).unwrap())
        .collect();
    assert!(is_pinned_for_upload(0, views[0].data()).expect("pointer attributes"));
    for (name, config) in [
        ("single scale t20", single(20, usize::MAX)),
        ("default pyramid", ExtractorConfig::default()),
    ] {
        let gpu = Extractor::new(gpu_backend, config.clone()).unwrap();
        let cpu = Extractor::new(Backend::Cpu, config).unwrap();
        let expected = cpu.detect_and_describe(&views[0]).unwrap();
        assert_eq!(gpu.detect_and_describe(&views[0]).unwrap(), expected);
        let keypoints = expected.keypoints.len();
        let device_ms = median(
            (0..60)
                .map(|i| {
                    device_time(|| gpu.detect_and_describe(&views[i % views.len()]))
                        .expect("device time")
                        .1
                })
                .skip(10)
                .collect(),
        );
        let run = |n: usize| {
            let start = Instant::now();
            let mut kept = 0usize;
            let count = gpu
                .detect_and_describe_stream(
                    (0..n).map(|i| Ok::<_, Error>(&views[i % views.len()])),
                    |_, _, f| {
                        kept += f.keypoints.len();
                        Ok(())
                    },
                )
                .unwrap();
            assert_eq!(count, n);
            (start.elapsed().as_secs_f64(), kept)
        };
        run(100);
        let (seconds, kept) = run(n_frames);
        let fps = n_frames as f64 / seconds;
        let bound = 1e3 / device_ms;
        println!(
            "frame stream 1080p {name:>16}: {keypoints} keypoints/frame ({:.0} on average), {n_frames} frames from page-locked memory, \
             whole run {fps:8.0} frames/s; device busy {device_ms:.4} ms/frame = bound {bound:8.0} frames/s; {:.1}% of the bound",
            kept as f64 / n_frames as f64,
            100.0 * fps / bound
        );
    }

    // --- One 21 MP photo, pageable and page-locked.
    let (w, h) = (5616usize, 3744usize);
    let photo = clatch::synthetic::rectangles(w, h, 9).expect("synthetic image");
    let photo_pinned = pin(std::slice::from_ref(&photo));
    let pageable_view = GrayView::new(&photo, w, h, w).unwrap();
    let pinned_view =
        GrayView::new(photo_pinned[0].as_slice().expect("pinned bytes"), w, h, w).unwrap();
    for (name, config) in [
        ("single scale t2 top 20k", single(2, 20_000)),
        ("pyramid t10 top 20k", pyramid(10, 20_000)),
    ] {
        let gpu = Extractor::new(gpu_backend, config.clone()).unwrap();
        let cpu = Extractor::new(Backend::Cpu, config).unwrap();
        let expected = cpu.detect_and_describe(&pageable_view).unwrap();
        for (memory, view) in [("pageable", &pageable_view), ("page-locked", &pinned_view)] {
            assert_eq!(gpu.detect_and_describe(view).unwrap(), expected);
            for _ in 0..3 {
                gpu.detect_and_describe(view).unwrap();
            }
            let whole = median(
                (0..20)
                    .map(|_| {
                        let start = Instant::now();
                        gpu.detect_and_describe(view).unwrap();
                        start.elapsed().as_secs_f64() * 1e3
                    })
                    .collect(),
            );
            let device_ms = median(
                (0..10)
                    .map(|_| {
                        device_time(|| gpu.detect_and_describe(view))
                            .expect("device time")
                            .1
                    })
                    .collect(),
            );
            println!(
                "photo 5616x3744 {name:>24} from {memory:>11} memory: {} keypoints, whole call {whole:8.3} ms (median of 20), \
                 device busy {device_ms:.3} ms: whole/device {:.2}x",
                expected.keypoints.len(),
                whole / device_ms
            );
        }
    }
}
