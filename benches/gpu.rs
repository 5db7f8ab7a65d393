//! GPU timings: `cargo bench --features cuda --bench gpu`. Kernel times come from CUDA events around
//! each launch, after warm-up; the median of the repeats is reported with the device's name.
//!
//! With `CLATCH_BENCH_DUMP=DIR` it also writes each image (`DIR/<name>.pgm`) and its 10k keypoints
//! (`DIR/<name>_10000.csv`: x, y, size, angle), so `tools/peers.py` can time OpenCV's LATCH on the same
//! image and keypoints.

#[cfg(feature = "cuda")]
mod common;

#[cfg(not(feature = "cuda"))]
fn main() {
    println!("skipped: no CUDA device (built without the `cuda` feature)");
}

#[cfg(feature = "cuda")]
fn main() {
    use clatch::synthetic::SplitMix64;
    use clatch::{DescriptorConfig, GrayView, KeyPoint, PatchWeights};

    let Some(dev) = common::device_or_skip() else {
        return;
    };
    println!("device: {}", dev.name());
    // Issue bounds for 512 triplets x 64 pixels x 2 SSDs, each term a subtract and a multiply-add:
    // 131072 operations per descriptor; Hopper issues 64 INT32 or 128 FP32 lanes per SM and clock.
    let (sms, clock_khz) =
        clatch::cuda::hooks::multiprocessors_and_clock_khz(&dev).expect("attributes");
    let per_s = sms as f64 * clock_khz as f64 * 1e3;
    let int32_bound = per_s * 64.0 / 131_072.0;
    let fp32_bound = per_s * 128.0 / 131_072.0;
    println!(
        "bounds: {sms} SMs x {:.0} MHz, 512 x 64 x 2 SSD terms x 2 operations = 131072 per descriptor: \
         INT32-issue-bound {:.1} M descriptors/s, FP32-issue-bound {:.1} M descriptors/s",
        clock_khz as f64 / 1e3,
        int32_bound / 1e6,
        fp32_bound / 1e6
    );
    let median = |mut v: Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2] as f64
    };
    for (name, w, h) in [("1080p", 1920usize, 1080usize), ("5616x3744", 5616, 3744)] {
        let pixels = clatch::synthetic::rectangles(w, h, 9).expect("synthetic image");
        let image = GrayView::new(&pixels, w, h, w).unwrap();
        let dump = std::env::var_os("CLATCH_BENCH_DUMP").map(std::path::PathBuf::from);
        if let Some(dir) = &dump {
            let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
            pgm.extend_from_slice(&pixels);
            std::fs::write(dir.join(format!("{name}.pgm")), pgm).expect("write the image dump");
        }
        for n in [1_000usize, 10_000, 100_000, 1_000_000] {
            let mut rng = SplitMix64::new(n as u64);
            // Upright-to-any angle, default size, positions where the window always fits.
            let keypoints: Vec<KeyPoint> = (0..n)
                .map(|_| {
                    KeyPoint::new(
                        48.0 + rng.below((w as u64 - 97) * 16) as f32 / 16.0,
                        48.0 + rng.below((h as u64 - 97) * 16) as f32 / 16.0,
                    )
                    .with_angle(rng.below(2880) as f32 / 8.0)
                })
                .collect();
            if let Some(dir) = dump.as_ref().filter(|_| n == 10_000) {
                let rows: String = keypoints
                    .iter()
                    .map(|k| format!("{},{},{},{}\n", k.x, k.y, k.size, k.angle))
                    .collect();
                std::fs::write(
                    dir.join(format!("{name}_{n}.csv")),
                    format!("x,y,size,angle\n{rows}"),
                )
                .expect("write the keypoint dump");
            }
            // The default 0/1 mask runs the dp4a kernel; other weights run the general one.
            let doubled = PatchWeights::new(&[2; 64]).expect("valid weights");
            for (label, weights) in [
                ("7x7 mask", PatchWeights::default()),
                ("weights 2", doubled),
            ] {
                let config = DescriptorConfig::default().with_weights(weights);
                let times = clatch::cuda::hooks::time_describe_kernel(
                    &dev, &image, &keypoints, &config, 3, 15,
                )
                .expect("describe kernel");
                let ms = median(times);
                let rate = n as f64 / (ms * 1e-3);
                println!(
                    "describe {name:>9} {n:>8} keypoints, {label:>9}: median {ms:9.3} ms  {:8.1} M descriptors/s  \
                     {:6.2} ns/descriptor  {:5.1}% of the INT32 bound, {:5.1}% of the FP32 bound",
                    rate / 1e6,
                    ms * 1e6 / n as f64,
                    100.0 * rate / int32_bound,
                    100.0 * rate / fp32_bound
                );
            }
        }
    }
}
