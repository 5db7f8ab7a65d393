//! Several images in flight on separate streams against the same images one after another:
//! `cargo bench --features cuda --bench gpu_streams`. Whole detect + describe calls, uploads and
//! downloads included; wall-clock time of the batch (every stream synchronised), median of 10 runs after
//! warm-up.

#[cfg(feature = "cuda")]
mod common;

#[cfg(not(feature = "cuda"))]
fn main() {
    println!("skipped: no CUDA device (built without the `cuda` feature)");
}

#[cfg(feature = "cuda")]
fn main() {
    use std::time::Instant;

    use clatch::cuda::GpuStream;
    use clatch::{Backend, Extractor, ExtractorConfig, GrayView};

    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    let (w, h, n) = (1920usize, 1080usize, 8usize);
    let frames: Vec<Vec<u8>> = (0..n)
        .map(|i| clatch::synthetic::rectangles(w, h, 70 + i as u64).expect("synthetic image"))
        .collect();
    let views: Vec<GrayView> = frames
        .iter()
        .map(|f| GrayView::new(f, w, h, w).unwrap())
        .collect();
    let extractor =
        Extractor::new(Backend::Cuda { device: 0 }, ExtractorConfig::default()).unwrap();
    let streams: Vec<GpuStream> = (0..n).map(|_| GpuStream::new(0).unwrap()).collect();
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let sequential = || {
        let t = Instant::now();
        for view in &views {
            extractor.detect_and_describe(view).unwrap();
        }
        t.elapsed().as_secs_f64() * 1e3
    };
    // (wall ms, of which ms spent queueing on the host)
    let in_flight_split = || {
        let t = Instant::now();
        let pending: Vec<_> = views
            .iter()
            .zip(&streams)
            .map(|(view, stream)| extractor.detect_and_describe_async(stream, view).unwrap())
            .collect();
        let queued = t.elapsed().as_secs_f64() * 1e3;
        for p in pending {
            p.wait().unwrap();
        }
        (t.elapsed().as_secs_f64() * 1e3, queued)
    };
    let in_flight = || in_flight_split().0;
    for _ in 0..3 {
        sequential();
        in_flight();
    }
    let seq = median((0..10).map(|_| sequential()).collect());
    let par = median((0..10).map(|_| in_flight()).collect());
    let queued = median((0..10).map(|_| in_flight_split().1).collect());
    println!("  of the in-flight batch, queueing on the host takes {queued:.3} ms (median)");
    println!(
        "{n} x {w}x{h} detect+describe: one after another {seq:.3} ms, {n} streams in flight {par:.3} ms: {:.2}x throughput",
        seq / par
    );
}
