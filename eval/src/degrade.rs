//! Photometric degradations for the synthetic pairs: additive Gaussian noise and Gaussian blur, both
//! deterministic so that every run (and the OpenCV script, which reads the written files) sees the
//! same pixels.

use clatch::synthetic::SplitMix64;
use image::GrayImage;

/// Standard deviations of the added noise, in gray levels.
pub const NOISE_SIGMAS: [f64; 5] = [5.0, 10.0, 15.0, 20.0, 25.0];

/// Standard deviations of the blur, in pixels.
pub const BLUR_SIGMAS: [f64; 3] = [1.0, 2.0, 3.0];

/// The seed of the noise of standard deviation `sigma`: fixed, so runs repeat.
pub fn noise_seed(sigma: f64) -> u64 {
    0xC1A7_C400_0000_0000 ^ sigma.to_bits()
}

/// A uniform number in (0, 1]: 53 random bits, never 0 (Box–Muller takes its logarithm).
fn unit_open(rng: &mut SplitMix64) -> f64 {
    ((rng.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
}

/// `img` plus independent Gaussian noise of standard deviation `sigma` (Box–Muller on SplitMix64
/// from `seed`), rounded and clamped to 0..=255.
pub fn add_noise(img: &GrayImage, sigma: f64, seed: u64) -> GrayImage {
    let mut rng = SplitMix64::new(seed);
    let mut out = img.clone();
    let mut spare: Option<f64> = None;
    for pixel in out.pixels_mut() {
        let z = match spare.take() {
            Some(z) => z,
            None => {
                let radius = (-2.0 * unit_open(&mut rng).ln()).sqrt();
                let angle = std::f64::consts::TAU * unit_open(&mut rng);
                spare = Some(radius * angle.sin());
                radius * angle.cos()
            }
        };
        pixel.0[0] = (pixel.0[0] as f64 + sigma * z).round().clamp(0.0, 255.0) as u8;
    }
    out
}

/// The normalised Gaussian kernel of standard deviation `sigma`, radius `ceil(3 sigma)`.
fn kernel(sigma: f64) -> Vec<f64> {
    let radius = (3.0 * sigma).ceil().max(0.0) as i64;
    let weights: Vec<f64> = (-radius..=radius)
        .map(|d| (-((d * d) as f64) / (2.0 * sigma * sigma)).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    weights.into_iter().map(|w| w / total).collect()
}

/// `img` blurred by a Gaussian of standard deviation `sigma` pixels (separable, edge pixels
/// repeated beyond the border), rounded to 0..=255. `sigma` <= 0 returns the image unchanged.
pub fn gaussian_blur(img: &GrayImage, sigma: f64) -> GrayImage {
    if sigma.is_nan() || sigma <= 0.0 {
        return img.clone();
    }
    let k = kernel(sigma);
    let radius = (k.len() / 2) as i64;
    let (w, h) = (img.width() as i64, img.height() as i64);
    // One pass along a line: `at(i)` reads position i, clamped into 0..len.
    let smooth = |len: i64, at: &dyn Fn(i64) -> f64, i: i64| -> f64 {
        k.iter()
            .enumerate()
            .map(|(j, weight)| weight * at((i + j as i64 - radius).clamp(0, len - 1)))
            .sum()
    };
    let mut rows = vec![0.0f64; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let at = |i: i64| img.get_pixel(i as u32, y as u32).0[0] as f64;
            rows[(y * w + x) as usize] = smooth(w, &at, x);
        }
    }
    GrayImage::from_fn(w as u32, h as u32, |x, y| {
        let at = |i: i64| rows[(i * w + x as i64) as usize];
        let v = smooth(h, &at, y as i64);
        image::Luma([v.round().clamp(0.0, 255.0) as u8])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mean and standard deviation of `b - a`.
    fn difference_stats(a: &GrayImage, b: &GrayImage) -> (f64, f64) {
        let d: Vec<f64> = a
            .pixels()
            .zip(b.pixels())
            .map(|(p, q)| q.0[0] as f64 - p.0[0] as f64)
            .collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let var = d.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / d.len() as f64;
        (mean, var.sqrt())
    }

    #[test]
    fn noise_has_the_asked_deviation_and_repeats() {
        let grey = GrayImage::from_pixel(200, 150, image::Luma([128]));
        for sigma in NOISE_SIGMAS {
            let noisy = add_noise(&grey, sigma, noise_seed(sigma));
            let (mean, deviation) = difference_stats(&grey, &noisy);
            // 30,000 samples: the mean within 0.5, the deviation within 3 % (rounding adds 1/12).
            assert!(mean.abs() < 0.5, "sigma {sigma}: mean {mean}");
            assert!(
                (deviation - sigma).abs() < 0.03 * sigma,
                "sigma {sigma}: deviation {deviation}"
            );
            assert_eq!(noisy, add_noise(&grey, sigma, noise_seed(sigma)));
            assert_ne!(noisy, add_noise(&grey, sigma, noise_seed(sigma) + 1));
        }
        // Clamped, never wrapped (a wrapped +1 would read 0): a white image only darkens.
        let white = GrayImage::from_pixel(50, 50, image::Luma([255]));
        let noisy = add_noise(&white, 25.0, 7);
        assert!(noisy.pixels().all(|p| p.0[0] >= 255 - 6 * 25));
        assert!(difference_stats(&white, &noisy).0 < -5.0);
    }

    #[test]
    fn blur_keeps_flat_images_and_spreads_a_point_as_a_gaussian() {
        let flat = GrayImage::from_pixel(40, 30, image::Luma([77]));
        assert_eq!(gaussian_blur(&flat, 2.0), flat);
        assert_eq!(gaussian_blur(&flat, 0.0), flat);

        let mut point = GrayImage::new(41, 41);
        point.put_pixel(20, 20, image::Luma([255]));
        let mut previous_peak = 255;
        for sigma in BLUR_SIGMAS {
            let blurred = gaussian_blur(&point, sigma);
            let peak = blurred.get_pixel(20, 20).0[0];
            // The peak of a 2-D Gaussian holding 255: 255 / (2 pi sigma^2).
            let expected = 255.0 / (std::f64::consts::TAU * sigma * sigma);
            assert!(
                (peak as f64 - expected).abs() <= 0.1 * expected + 0.5,
                "{sigma}: {peak}"
            );
            assert!(peak < previous_peak);
            previous_peak = peak;
            // Symmetric about the point.
            for d in 1..8 {
                let right = blurred.get_pixel(20 + d, 20);
                assert_eq!(right, blurred.get_pixel(20 - d, 20));
                assert_eq!(right, blurred.get_pixel(20, 20 + d));
            }
        }
    }
}
