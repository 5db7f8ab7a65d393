//! GPU faults and concurrency: device memory exhaustion is a typed error that leaves the context
//! usable; the widest images the API accepts work through the texture path; many host threads, each
//! on its own stream, get exactly the CPU's results.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_faults")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("out_of_memory_is_typed_and_recoverable", gpu::out_of_memory),
        Trial::test("widest_and_tallest_images", gpu::extreme_shapes),
        Trial::test("many_threads_many_streams", gpu::many_threads),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::synthetic::SplitMix64;
    use clatch::{Backend, Error, Extractor, ExtractorConfig, GrayView, KeyPoint};
    use libtest_mimic::Failed;

    use super::common::rectangles;

    const GPU: Backend = Backend::Cuda { device: 0 };

    pub fn out_of_memory() -> Result<(), Failed> {
        let huge = 1usize << 42; // 4 TiB
        match clatch::cuda::hooks::probe_allocation(0, huge) {
            Err(Error::DeviceOutOfMemory { bytes, .. }) if bytes == huge => {}
            other => {
                return Err(
                    format!("expected DeviceOutOfMemory of {huge} bytes, got {other:?}").into(),
                );
            }
        }
        // The context is still usable: a real describe after the failure matches the CPU.
        clatch::cuda::hooks::probe_allocation(0, 1 << 20)?;
        let image = rectangles(300, 200, 1);
        let keypoints = [KeyPoint::new(150.0, 100.0).with_angle(33.0)];
        let gpu =
            Extractor::new(GPU, ExtractorConfig::default())?.describe(&image.view(), &keypoints)?;
        let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
            .describe(&image.view(), &keypoints)?;
        if gpu != cpu {
            return Err("describe after an out-of-memory error differs from the CPU".into());
        }
        println!("4 TiB request: DeviceOutOfMemory; context usable afterwards");
        Ok(())
    }

    pub fn extreme_shapes() -> Result<(), Failed> {
        let max = clatch::MAX_IMAGE_SIDE;
        for (w, h) in [(max, 64), (64, max), (max, 300)] {
            let pixels =
                clatch::synthetic::noise(w, h, (w * 7 + h) as u64).expect("synthetic image");
            let image = GrayView::new(&pixels, w, h, w)?;
            let mut rng = SplitMix64::new(3);
            let keypoints: Vec<KeyPoint> = (0..2000)
                .map(|_| {
                    KeyPoint::new(rng.below(w as u64) as f32, rng.below(h as u64) as f32)
                        .with_size(16.0 + rng.below(48) as f32)
                        .with_angle(rng.below(360) as f32)
                })
                .collect();
            let gpu =
                Extractor::new(GPU, ExtractorConfig::default())?.describe(&image, &keypoints)?;
            let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
                .describe(&image, &keypoints)?;
            if gpu != cpu {
                return Err(format!("{w}x{h}: GPU and CPU differ").into());
            }
            println!("{w}x{h}: {} descriptors identical", cpu.descriptors.len());
        }
        Ok(())
    }

    pub fn many_threads() -> Result<(), Failed> {
        let threads = 16;
        let results: Vec<Result<usize, String>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    scope.spawn(move || -> Result<usize, String> {
                        let image = rectangles(640 + 16 * t, 480, 100 + t as u64);
                        let view = image.view();
                        let mut compared = 0;
                        for round in 0..5 {
                            let gpu = Extractor::new(GPU, ExtractorConfig::default())
                                .map_err(|e| e.to_string())?;
                            let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())
                                .map_err(|e| e.to_string())?;
                            let a = gpu.detect_and_describe(&view).map_err(|e| e.to_string())?;
                            let b = cpu.detect_and_describe(&view).map_err(|e| e.to_string())?;
                            if a != b {
                                return Err(format!(
                                    "thread {t}, round {round}: GPU and CPU differ"
                                ));
                            }
                            compared += a.descriptors.len();
                        }
                        Ok(compared)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or(Err("thread panicked".into())))
                .collect()
        });
        let mut total = 0;
        for r in results {
            total += r?;
        }
        println!("{threads} threads x 5 rounds: {total} descriptors identical to the CPU");
        Ok(())
    }
}
