//! GPU against CPU, bit for bit: every descriptor, every skipped keypoint, and the golden file.
//!
//! Runs only with the `cuda` feature and a device; otherwise every test is reported as ignored with
//! `skipped: no CUDA device`, never as passed.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_describe")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("describe_reproduces_golden_file", gpu::golden_file),
        Trial::test("describe_every_angle_bin", gpu::every_angle_bin),
        Trial::test("describe_every_width", gpu::every_width),
        Trial::test(
            "describe_sizes_subpixel_and_borders",
            gpu::sizes_subpixel_and_borders,
        ),
        Trial::test("describe_a_million_random_keypoints", gpu::million_random),
        Trial::test("smoothed_pixels_equal_cpu", gpu::smoothed_pixels),
        Trial::test("describe_smoothed_equals_cpu", gpu::describe_smoothed),
        Trial::test(
            "detect_and_describe_smoothed_equals_cpu",
            gpu::detect_and_describe_smoothed,
        ),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::synthetic::SplitMix64;
    use clatch::{
        Backend, DescriptorConfig, DescriptorWidth, Extractor, ExtractorConfig, GrayView, KeyPoint,
        PatchWeights, Smoothing,
    };
    use libtest_mimic::Failed;

    use super::common::golden::{golden_path, render};
    use super::common::{Gray, astronaut, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    fn extractor(
        backend: Backend,
        bits: usize,
        weights: PatchWeights,
        smoothing: Smoothing,
    ) -> Extractor {
        let config = scale::budget(ExtractorConfig::default()).with_descriptor(
            DescriptorConfig::default()
                .with_width(DescriptorWidth::from_bits(bits).unwrap())
                .with_weights(weights)
                .with_smoothing(smoothing),
        );
        Extractor::new(backend, config).unwrap()
    }

    /// Describes `keypoints` on both backends and demands identical results; returns how many
    /// descriptors were compared.
    fn compare(
        image: &GrayView,
        keypoints: &[KeyPoint],
        bits: usize,
        weights: PatchWeights,
    ) -> Result<usize, Failed> {
        compare_smoothed(image, keypoints, bits, weights, Smoothing::None)
    }

    /// [`compare`] with `smoothing` before description.
    fn compare_smoothed(
        image: &GrayView,
        keypoints: &[KeyPoint],
        bits: usize,
        weights: PatchWeights,
        smoothing: Smoothing,
    ) -> Result<usize, Failed> {
        let cpu =
            extractor(Backend::Cpu, bits, weights.clone(), smoothing).describe(image, keypoints)?;
        let gpu = extractor(GPU, bits, weights, smoothing).describe(image, keypoints)?;
        if cpu.keypoint_index != gpu.keypoint_index || cpu.skipped != gpu.skipped {
            return Err(format!(
                "different keypoints described: cpu {} (skipped {}), gpu {} (skipped {})",
                cpu.keypoint_index.len(),
                cpu.skipped.len(),
                gpu.keypoint_index.len(),
                gpu.skipped.len()
            )
            .into());
        }
        let differing: Vec<usize> = (0..cpu.descriptors.len())
            .filter(|&i| cpu.descriptors.get(i) != gpu.descriptors.get(i))
            .collect();
        if let Some(&first) = differing.first() {
            let kp = keypoints[cpu.keypoint_index[first]];
            return Err(format!(
                "{} of {} descriptors differ ({bits} bits, {smoothing:?}); first: keypoint {:?}\n cpu {:x?}\n gpu {:x?}",
                differing.len(),
                cpu.descriptors.len(),
                kp,
                cpu.descriptors.get(first).unwrap(),
                gpu.descriptors.get(first).unwrap()
            )
            .into());
        }
        Ok(cpu.descriptors.len())
    }

    pub fn golden_file() -> Result<(), Failed> {
        let image = astronaut();
        let expected = std::fs::read_to_string(golden_path())?;
        let got = render(&image, GPU);
        if expected != got {
            let line = expected.lines().zip(got.lines()).position(|(e, g)| e != g);
            return Err(format!("GPU output differs from the golden file at line {line:?}").into());
        }
        println!(
            "golden file reproduced ({} lines)",
            expected.lines().count()
        );
        Ok(())
    }

    pub fn every_angle_bin() -> Result<(), Failed> {
        let image = astronaut();
        let mut keypoints = Vec::new();
        for bin in 0..2880 {
            let (x, y) = (
                140.0 + (bin % 48) as f32 * 5.0,
                140.0 + (bin / 48) as f32 * 4.0,
            );
            keypoints.push(KeyPoint::new(x, y).with_angle(bin as f32 / 8.0));
            keypoints.push(KeyPoint::new(x + 0.37, y - 0.81).with_angle(bin as f32 / 8.0 + 0.0625));
        }
        let mut rng = SplitMix64::new(11);
        for _ in 0..scale::pick(20_000, 1_000) {
            let x = 100.0 + (rng.below(312_000) as f32) / 1000.0;
            let y = 100.0 + (rng.below(312_000) as f32) / 1000.0;
            let angle = (rng.below(2_000_000) as f32) / 1000.0 - 1000.0;
            keypoints.push(KeyPoint::new(x, y).with_angle(angle));
        }
        let n = compare(&image.view(), &keypoints, 512, PatchWeights::default())?;
        println!("every angle bin: {n} descriptors, 0 differences");
        Ok(())
    }

    pub fn every_width() -> Result<(), Failed> {
        let image = astronaut();
        let mut rng = SplitMix64::new(5);
        let keypoints: Vec<KeyPoint> = (0..scale::pick(2000, 200))
            .map(|_| {
                KeyPoint::new(
                    60.0 + rng.below(392_000) as f32 / 1000.0,
                    60.0 + rng.below(392_000) as f32 / 1000.0,
                )
                .with_angle(rng.below(360_000) as f32 / 1000.0)
                .with_size(16.0 + rng.below(80) as f32)
            })
            .collect();
        let mut total = 0;
        for bits in (8..=512).step_by(8) {
            total += compare(&image.view(), &keypoints, bits, PatchWeights::default())?;
        }
        let gaussian: Vec<u32> = (0..64)
            .map(|i| {
                let (r, s) = (i / 8 - 4, i % 8 - 4);
                (64.0 * (-((r * r + s * s) as f64) / 18.0).exp()).round() as u32
            })
            .collect();
        total += compare(
            &image.view(),
            &keypoints,
            512,
            PatchWeights::new(&gaussian)?,
        )?;
        total += compare(&image.view(), &keypoints, 512, PatchWeights::uniform())?;
        println!("every width and three weightings: {total} descriptors, 0 differences");
        Ok(())
    }

    pub fn sizes_subpixel_and_borders() -> Result<(), Failed> {
        let image = rectangles(700, 500, 3);
        let mut rng = SplitMix64::new(17);
        let mut keypoints = Vec::new();
        for size in [1.0f32, 7.5, 16.0, 31.0, 64.0, 100.0, 200.0, 333.3, 1024.0] {
            for _ in 0..scale::pick(3000, 300) {
                // Anywhere in the image, borders included: many windows do not fit and are skipped.
                let x = rng.below(699_000) as f32 / 1000.0;
                let y = rng.below(499_000) as f32 / 1000.0;
                let angle = rng.below(360_000) as f32 / 1000.0;
                keypoints.push(KeyPoint::new(x, y).with_size(size).with_angle(angle));
            }
            // Exactly at the edge of fitting, upright and rotated.
            for m in [31.0f32, 32.0, 33.0, 44.0, 45.0, 46.0] {
                let half = m * size / 64.0;
                for (x, y) in [
                    (half, 250.0),
                    (699.0 - half, 250.0),
                    (350.0, half),
                    (350.0, 499.0 - half),
                ] {
                    if (0.0..=699.0).contains(&x) && (0.0..=499.0).contains(&y) {
                        for angle in [0.0f32, 45.0, 90.0, 30.0, 180.0] {
                            keypoints.push(KeyPoint::new(x, y).with_size(size).with_angle(angle));
                        }
                    }
                }
            }
        }
        let n = compare(&image.view(), &keypoints, 512, PatchWeights::default())?;
        println!(
            "sizes, sub-pixel positions and borders: {n} descriptors of {} keypoints, 0 differences",
            keypoints.len()
        );
        Ok(())
    }

    pub fn million_random() -> Result<(), Failed> {
        let mut total = 0;
        for (seed, image) in [
            (1u64, noise_image(1024, 768, 21)),
            (2, rectangles(1920, 1080, 22)),
        ] {
            let mut rng = SplitMix64::new(seed);
            let (w, h) = (image.width as u64, image.height as u64);
            let keypoints: Vec<KeyPoint> = (0..scale::pick(700_000, 5_000))
                .map(|_| {
                    KeyPoint::new(
                        rng.below((w - 1) * 256) as f32 / 256.0,
                        rng.below((h - 1) * 256) as f32 / 256.0,
                    )
                    .with_size(8.0 + rng.below(120) as f32)
                    .with_angle(rng.below(3_600_000) as f32 / 10_000.0)
                })
                .collect();
            total += compare(&image.view(), &keypoints, 512, PatchWeights::default())?;
        }
        println!("random images: {total} descriptors, 0 differences");
        // Under CLATCH_TEST_SCALE=sanitizer, 10^4 keypoints instead of 1.4 * 10^6.
        let promised = scale::pick(1_000_000, 7_000);
        if total < promised {
            return Err(format!(
                "only {total} descriptors compared; the suite promises at least {promised}"
            )
            .into());
        }
        Ok(())
    }

    const SMOOTHINGS: [Smoothing; 2] = [Smoothing::Binomial3, Smoothing::Binomial5];

    /// The GPU's smoothed copy of an image against `clatch::describe::cpu::smooth`, pixel for pixel,
    /// on sizes that do and do not fill the 32x8 tiles, down to one pixel.
    pub fn smoothed_pixels() -> Result<(), Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        let mut images = vec![astronaut(), rectangles(700, 500, 3)];
        for (w, h, seed) in [
            (1, 1, 1),
            (1, 9, 2),
            (33, 1, 3),
            (31, 7, 4),
            (65, 17, 5),
            scale::pick((1023, 769, 6), (129, 67, 6)),
        ] {
            images.push(noise_image(w, h, seed));
        }
        let mut pixels = 0;
        for image in &images {
            for smoothing in [Smoothing::None, Smoothing::Binomial3, Smoothing::Binomial5] {
                let cpu = clatch::describe::cpu::smooth(&image.view(), smoothing);
                let gpu = clatch::cuda::hooks::debug_smoothed(&dev, &image.view(), smoothing)?;
                if let Some(i) = (0..cpu.len()).find(|&i| cpu.get(i) != gpu.get(i)) {
                    return Err(format!(
                        "{}x{} {smoothing:?}: pixel ({}, {}) cpu {:?} gpu {:?} ({} cpu pixels, {} gpu)",
                        image.width,
                        image.height,
                        i % image.width,
                        i / image.width,
                        cpu.get(i),
                        gpu.get(i),
                        cpu.len(),
                        gpu.len()
                    )
                    .into());
                }
                if cpu.len() != gpu.len() {
                    return Err(format!("{}x{}: sizes differ", image.width, image.height).into());
                }
                pixels += cpu.len();
            }
        }
        println!("smoothed images: {pixels} pixels, 0 differences");
        Ok(())
    }

    /// Description of given keypoints with smoothing: sub-pixel positions, every angle, sizes up to
    /// the borders, several widths and weightings. Also checks that smoothing changed the bits.
    pub fn describe_smoothed() -> Result<(), Failed> {
        let mut total = 0;
        for (seed, image) in [
            (23, astronaut()),
            (24, rectangles(700, 500, 3)),
            (25, noise_image(640, 480, 9)),
        ] {
            // Sizes 4..204: from windows far inside the image to many that do not fit.
            let keypoints: Vec<KeyPoint> = super::common::random_subpixel_keypoints(
                image.width - 1,
                image.height - 1,
                scale::pick(20_000, 500),
                seed,
            )
            .into_iter()
            .enumerate()
            .map(|(i, k)| k.with_size(4.0 + (i % 200) as f32))
            .collect();
            let view = image.view();
            for smoothing in SMOOTHINGS {
                for (bits, weights) in [
                    (512, PatchWeights::default()),
                    (136, PatchWeights::default()),
                    (512, PatchWeights::uniform()),
                ] {
                    total += compare_smoothed(&view, &keypoints, bits, weights, smoothing)?;
                }
                let plain = extractor(GPU, 512, PatchWeights::default(), Smoothing::None)
                    .describe(&view, &keypoints)?;
                let smoothed = extractor(GPU, 512, PatchWeights::default(), smoothing)
                    .describe(&view, &keypoints)?;
                if plain.descriptors == smoothed.descriptors {
                    return Err(
                        format!("{smoothing:?} did not change the GPU's descriptors").into(),
                    );
                }
            }
        }
        println!("smoothed description: {total} descriptors, 0 differences");
        Ok(())
    }

    /// Single-scale detection and description with smoothing, blocking and queued on a stream:
    /// keypoints (detected on the unsmoothed image) and descriptors equal the CPU's.
    pub fn detect_and_describe_smoothed() -> Result<(), Failed> {
        let stream = clatch::cuda::GpuStream::new(0)?;
        let mut total = 0;
        for image in scale::thin(
            [
                astronaut(),
                rectangles(1920, 1080, 22),
                noise_image(1023, 769, 6),
            ],
            3,
        ) {
            let view = image.view();
            let plain = extractor(Backend::Cpu, 512, PatchWeights::default(), Smoothing::None)
                .detect_and_describe(&view)?;
            for smoothing in SMOOTHINGS {
                let cpu = extractor(Backend::Cpu, 512, PatchWeights::default(), smoothing)
                    .detect_and_describe(&view)?;
                let gpu = extractor(GPU, 512, PatchWeights::default(), smoothing);
                let blocking = gpu.detect_and_describe(&view)?;
                let queued = gpu.detect_and_describe_async(&stream, &view)?.wait()?;
                for (how, got) in [("blocking", &blocking), ("asynchronous", &queued)] {
                    if super::common::first_keypoint_difference(&cpu.keypoints, &got.keypoints)
                        .is_some()
                        || cpu.descriptors != got.descriptors
                    {
                        return Err(format!(
                            "{}x{} {smoothing:?} ({how}): differs from the CPU",
                            image.width, image.height
                        )
                        .into());
                    }
                }
                if super::common::first_keypoint_difference(&cpu.keypoints, &plain.keypoints)
                    .is_some()
                {
                    return Err("smoothing moved the detected keypoints".into());
                }
                total += cpu.descriptors.len();
            }
        }
        println!("smoothed detect and describe: {total} descriptors, 0 differences");
        Ok(())
    }

    fn noise_image(width: usize, height: usize, seed: u64) -> Gray {
        Gray::new(
            clatch::synthetic::noise(width, height, seed).expect("synthetic image"),
            width,
            height,
        )
    }
}
