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
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::synthetic::SplitMix64;
    use clatch::{
        Backend, DescriptorConfig, DescriptorWidth, Extractor, ExtractorConfig, GrayView, KeyPoint,
        PatchWeights,
    };
    use libtest_mimic::Failed;

    use super::common::golden::{golden_path, render};
    use super::common::{Gray, astronaut, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    fn extractor(backend: Backend, bits: usize, weights: PatchWeights) -> Extractor {
        let config = ExtractorConfig {
            descriptor: DescriptorConfig {
                width: DescriptorWidth::from_bits(bits).unwrap(),
                weights,
            },
            ..ExtractorConfig::default()
        };
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
        let cpu = extractor(Backend::Cpu, bits, weights.clone()).describe(image, keypoints)?;
        let gpu = extractor(GPU, bits, weights).describe(image, keypoints)?;
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
                "{} of {} descriptors differ ({bits} bits); first: keypoint {:?}\n cpu {:x?}\n gpu {:x?}",
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

    fn noise_image(width: usize, height: usize, seed: u64) -> Gray {
        Gray::new(
            clatch::synthetic::noise(width, height, seed).expect("synthetic image"),
            width,
            height,
        )
    }
}
