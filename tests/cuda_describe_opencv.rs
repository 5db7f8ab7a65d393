//! OpenCV-compatible LATCH, GPU against CPU, bit for bit: every descriptor and every skipped keypoint,
//! over every width, rotation on and off, sigma 0 and 2, several patch sizes, many angles, sub-pixel and
//! border positions, and an image whose rows are padded. (The CPU is checked against cv2 itself by
//! `tests/opencv_latch.rs`.)
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
    common::gpu::feature_missing("cuda_describe_opencv")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("opencv_every_configuration", gpu::every_configuration),
        Trial::test("opencv_many_angles", gpu::many_angles),
        Trial::test(
            "opencv_borders_and_patch_sizes",
            gpu::borders_and_patch_sizes,
        ),
        Trial::test("opencv_padded_rows", gpu::padded_rows),
        Trial::test("opencv_half_a_million_keypoints", gpu::half_a_million),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::describe::opencv::OPENCV_BYTES;
    use clatch::synthetic::SplitMix64;
    use clatch::{Backend, Extractor, ExtractorConfig, GrayView, KeyPoint, OpencvLatch};
    use libtest_mimic::Failed;

    use super::common::{Gray, astronaut, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    /// Describes on both backends and demands identical results; returns the descriptors compared.
    fn compare(
        image: &GrayView,
        keypoints: &[KeyPoint],
        latch: &OpencvLatch,
    ) -> Result<usize, Failed> {
        let on = |backend| Extractor::new(backend, ExtractorConfig::default());
        let cpu = on(Backend::Cpu)?.describe_opencv(latch, image, keypoints)?;
        let gpu = on(GPU)?.describe_opencv(latch, image, keypoints)?;
        if cpu.keypoint_index != gpu.keypoint_index || cpu.skipped != gpu.skipped {
            return Err(format!(
                "{latch:?}: different keypoints described: cpu {} (skipped {}), gpu {} (skipped {})",
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
                "{latch:?}: {} of {} descriptors differ; first: keypoint {kp:?}\n cpu {:x?}\n gpu {:x?}",
                differing.len(),
                cpu.descriptors.len(),
                cpu.descriptors.get(first).unwrap(),
                gpu.descriptors.get(first).unwrap()
            )
            .into());
        }
        if cpu.descriptors.to_opencv_bytes() != gpu.descriptors.to_opencv_bytes() {
            return Err(format!("{latch:?}: OpenCV byte rows differ").into());
        }
        Ok(cpu.descriptors.len())
    }

    fn random_keypoints(image: &Gray, count: usize, seed: u64) -> Vec<KeyPoint> {
        super::common::random_subpixel_keypoints(image.width, image.height, count, seed)
    }

    fn latch(bytes: usize, rotation: bool, half: usize, sigma: f64) -> OpencvLatch {
        OpencvLatch::new(bytes, rotation, half, sigma).expect("valid settings")
    }

    pub fn every_configuration() -> Result<(), Failed> {
        let images = [
            astronaut(),
            Gray::new(
                clatch::synthetic::noise(640, 480, 1).expect("synthetic image"),
                640,
                480,
            ),
            rectangles(800, 600, 2),
        ];
        let mut total = 0;
        for (n, image) in images.iter().enumerate() {
            let keypoints = random_keypoints(image, scale::pick(5000, 500), 10 + n as u64);
            for bytes in OPENCV_BYTES {
                for rotation in [true, false] {
                    for sigma in [0.0, 2.0] {
                        total +=
                            compare(&image.view(), &keypoints, &latch(bytes, rotation, 3, sigma))?;
                    }
                }
            }
        }
        println!(
            "3 images x 7 widths x rotation on/off x sigma 0/2: {total} descriptors, 0 differences"
        );
        Ok(())
    }

    pub fn many_angles() -> Result<(), Failed> {
        let image = astronaut();
        let mut rng = SplitMix64::new(3);
        // Every 0.01 degree in [-720, 720], plus random float angles (any mantissa) up to ±10^4 degrees
        // (under CLATCH_TEST_SCALE=sanitizer every 0.1 degree, a tenth of the random angles).
        let mut keypoints: Vec<KeyPoint> = (-72_000..=72_000)
            .step_by(scale::pick(1, 10))
            .map(|i| {
                KeyPoint::new(
                    60.0 + rng.below(390 * 8) as f32 / 8.0,
                    60.0 + rng.below(390 * 8) as f32 / 8.0,
                )
                .with_angle(i as f32 / 100.0)
            })
            .collect();
        for _ in 0..scale::pick(100_000, 10_000) {
            let angle = f32::from_bits(rng.next_u64() as u32 & 0x7fff_ffff);
            if angle.is_finite() && angle < 1e4 {
                let sign = if rng.below(2) == 0 { -1.0 } else { 1.0 };
                keypoints.push(KeyPoint::new(256.0, 256.0).with_angle(sign * angle));
            }
        }
        let n = compare(&image.view(), &keypoints, &latch(64, true, 3, 2.0))?;
        println!("many angles: {n} descriptors, 0 differences");
        Ok(())
    }

    pub fn borders_and_patch_sizes() -> Result<(), Failed> {
        let mut total = 0;
        for (w, h) in [(200usize, 150usize), (201, 151), (49, 49), (60, 300)] {
            let image = Gray::new(
                clatch::synthetic::noise(w, h, (w * h) as u64).expect("synthetic image"),
                w,
                h,
            );
            for half in [0usize, 1, 3, 6, 24] {
                // A quarter-pixel grid over both border zones of both axes, half pixels included.
                let b = 24.0 + half as f32;
                let zone = |len: usize| -> Vec<f32> {
                    let far = len as f32 - 1.0 - b;
                    (-12..=12)
                        .flat_map(|q| [b + q as f32 / 4.0, far + q as f32 / 4.0])
                        .filter(|&v| (0.0..len as f32).contains(&v))
                        .collect()
                };
                let (xs, ys) = (zone(w), zone(h));
                let mut keypoints = Vec::new();
                for (i, &x) in xs.iter().enumerate() {
                    for (j, &y) in ys.iter().enumerate() {
                        keypoints.push(KeyPoint::new(x, y).with_angle((i * 31 + j * 7) as f32));
                    }
                }
                keypoints.extend(random_keypoints(&image, 500, half as u64));
                for (rotation, sigma) in [(true, 2.0), (false, 0.0), (true, 0.0)] {
                    total += compare(&image.view(), &keypoints, &latch(16, rotation, half, sigma))?;
                }
            }
        }
        println!("borders and half_ssd_size 0/1/3/6/24: {total} descriptors, 0 differences");
        Ok(())
    }

    pub fn padded_rows() -> Result<(), Failed> {
        // Rows 1000 bytes apart for a 700-pixel-wide image: the sigma-0 path uploads the caller's rows.
        let (w, h, stride) = (700usize, 400usize, 1000usize);
        let mut rng = SplitMix64::new(4);
        let pixels: Vec<u8> = (0..stride * h).map(|_| rng.next_u64() as u8).collect();
        let image = GrayView::new(&pixels, w, h, stride)?;
        let gray = Gray::new(vec![0; w * h], w, h);
        let keypoints = random_keypoints(&gray, 5000, 5);
        let mut total = 0;
        for sigma in [0.0, 2.0, 0.8] {
            total += compare(&image, &keypoints, &latch(64, true, 3, sigma))?;
        }
        println!("padded rows: {total} descriptors, 0 differences");
        Ok(())
    }

    pub fn half_a_million() -> Result<(), Failed> {
        let image = rectangles(1920, 1080, 6);
        let keypoints = random_keypoints(&image, scale::pick(500_000, 20_000), 7);
        let n = compare(&image.view(), &keypoints, &latch(64, true, 3, 2.0))?;
        println!("1920x1080: {n} descriptors, 0 differences");
        Ok(())
    }
}
