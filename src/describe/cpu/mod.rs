//! The reference descriptor (see the parent module for the numeric contract).
//!
//! [`sample_window`] and [`window_bits`] are the contract written out plainly. [`describe`] computes
//! the same integers faster (`cpu/optimized.rs`): AVX2 kernels when the CPU has them (`cpu/avx2.rs`,
//! detected at run time), portable ones otherwise (`cpu/portable.rs`), each tested equal to the two
//! reference functions. `BENCHMARKS.md` has the figures.

#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
mod avx2;
mod optimized;
mod portable;
mod smooth;

pub use smooth::smooth;

use crate::parallel::*;

use super::triplets::TRIPLETS;
use super::{
    Described, DescriptorConfig, PATCH, SamplingFrame, SkipReason, Skipped, Smoothing, WINDOW,
};
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;

/// A sampled window, row-major `WINDOW x WINDOW` (values 0..=255, widened to `i16` so the patch sums
/// vectorise with 16-bit lanes).
pub type Window = [i16; WINDOW * WINDOW];

/// Samples the window of a frame that [`SamplingFrame::fits`] the image.
pub fn sample_window(img: &GrayView, frame: &SamplingFrame, window: &mut Window) {
    let (last_x, last_y) = (img.width() - 1, img.height() - 1);
    let half = (WINDOW / 2) as i64;
    for (v, out_row) in window.chunks_exact_mut(WINDOW).enumerate() {
        // `frame.sample_position(u, v)` advanced along the row by exact integer steps (the same values
        // without the multiplications): `p` is the 16.16 position plus the rounding half of 24.8.
        let dv = v as i64 - half;
        let mut p = [0, 1].map(|axis| {
            frame.origin[axis] - half * frame.step_u[axis] + dv * frame.step_v[axis] + 128
        });
        for out in out_row.iter_mut() {
            let (sx, sy) = (p[0] >> 8, p[1] >> 8);
            p[0] += frame.step_u[0];
            p[1] += frame.step_u[1];
            let (x0, y0) = ((sx >> 8) as usize, (sy >> 8) as usize);
            let (fx, fy) = ((sx & 255) as i32, (sy & 255) as i32);
            let (x1, y1) = ((x0 + 1).min(last_x), (y0 + 1).min(last_y));
            let (top, bottom) = (img.row(y0), img.row(y1));
            let upper = top[x0] as i32 * (256 - fx) + top[x1] as i32 * fx;
            let lower = bottom[x0] as i32 * (256 - fx) + bottom[x1] as i32 * fx;
            *out = ((upper * (256 - fy) + lower * fy + (1 << 15)) >> 16) as i16;
        }
    }
}

/// Weighted SSD difference `Σ w (A - B)² - Σ w (C - B)²` of one triplet: the reference form.
#[inline]
fn triplet_difference(window: &Window, triplet: &[u8; 6], weights: &[i32; PATCH * PATCH]) -> i32 {
    let [ax, ay, bx, by, cx, cy] = triplet.map(|v| v as usize);
    let mut d = 0i32;
    for r in 0..PATCH {
        let a = &window[(ay + r) * WINDOW + ax..][..PATCH];
        let b = &window[(by + r) * WINDOW + bx..][..PATCH];
        let c = &window[(cy + r) * WINDOW + cx..][..PATCH];
        let w = &weights[r * PATCH..][..PATCH];
        for s in 0..PATCH {
            let (da, dc) = (a[s] as i32 - b[s] as i32, c[s] as i32 - b[s] as i32);
            d += w[s] * (da * da - dc * dc);
        }
    }
    d
}

/// The first `width` bits of the descriptor of a sampled window, packed least significant bit first.
pub fn window_bits(
    window: &Window,
    width: DescriptorWidth,
    weights: &[i32; PATCH * PATCH],
    out: &mut [u64],
) {
    out.fill(0);
    for (t, triplet) in TRIPLETS[..width.bits()].iter().enumerate() {
        if triplet_difference(window, triplet, weights) < 0 {
            out[t / 64] |= 1 << (t % 64);
        }
    }
}

/// Describes validated keypoints on the CPU, in parallel over keypoints.
///
/// With [`DescriptorConfig::smoothing`], the windows sample [`smooth`]`(img)` instead of `img` (which
/// frames fit does not change: the smoothed image has the same size). Each keypoint goes through the
/// fast kernels of `cpu/optimized.rs` (the same integers as [`sample_window`] and [`window_bits`],
/// tested equal), into one window buffer per worker, of which only the rows some triplet reads with
/// a nonzero weight are sampled; weights other than 0/1 use [`window_bits`] itself.
pub fn describe(img: &GrayView, keypoints: &[KeyPoint], config: &DescriptorConfig) -> Described {
    let width = config.width;
    let per = width.words();
    let weights = config.weights.as_array().map(|w| w as i32);
    let kernels = optimized::Kernels::detect();
    let mask = optimized::pixel_mask(&weights);
    let rows = optimized::weighted_rows(&weights, width.bits());
    let frames: Vec<Option<SamplingFrame>> = keypoints
        .iter()
        .map(|kp| Some(SamplingFrame::of(kp)).filter(|f| f.fits(img.width(), img.height())))
        .collect();
    let keypoint_index: Vec<usize> = (0..keypoints.len())
        .filter(|&i| frames[i].is_some())
        .collect();
    let skipped = (0..keypoints.len())
        .filter(|&i| frames[i].is_none())
        .map(|keypoint| Skipped {
            keypoint,
            reason: SkipReason::WindowOutsideImage,
        })
        .collect();
    let smoothed = (config.smoothing != Smoothing::None && !keypoint_index.is_empty())
        .then(|| smooth(img, config.smoothing));
    let smoothed_view = smoothed.as_ref().map(|pixels| {
        GrayView::new(pixels, img.width(), img.height(), img.width()).expect("the input's geometry")
    });
    let img = smoothed_view.as_ref().unwrap_or(img);
    let mut words = vec![0u64; keypoint_index.len() * per];
    words
        .par_chunks_mut(per)
        .zip(keypoint_index.par_iter())
        .for_each_init(
            || Box::new([0i16; WINDOW * WINDOW]),
            |window, (out, &i)| {
                let frame = frames[i]
                    .as_ref()
                    .expect("only fitting frames are described");
                kernels.sample(img, frame, rows.clone(), window);
                match &mask {
                    Some(mask) => kernels.masked_bits(window, width, mask, out),
                    None => window_bits(window, width, &weights, out),
                }
            },
        );
    Described {
        descriptors: DescriptorSet::from_words(width, words).expect("whole rows by construction"),
        keypoint_index,
        skipped,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::describe::PatchWeights;

    #[test]
    fn unit_frame_samples_pixels_exactly() {
        // size 64, angle 0, integer position: window pixel (u, v) is image pixel (x + u - 32, y + v - 32).
        let (w, h) = (100, 90);
        let buf = crate::synthetic::noise(w, h, 3).expect("synthetic image");
        let img = GrayView::new(&buf, w, h, w).unwrap();
        let frame = SamplingFrame::of(&KeyPoint::new(40.0, 45.0));
        assert!(frame.fits(w, h));
        let mut window: Window = [0; WINDOW * WINDOW];
        sample_window(&img, &frame, &mut window);
        for v in 0..WINDOW {
            for u in 0..WINDOW {
                assert_eq!(
                    window[v * WINDOW + u],
                    img.at(40 + u - 32, 45 + v - 32) as i16
                );
            }
        }
    }

    #[test]
    fn half_pixel_offset_averages_neighbours_rounding_half_up() {
        // Columns alternate 10, 21: halfway between them the sample is (10 + 21) / 2 = 15.5 -> 16.
        let (w, h) = (80, 80);
        let buf: Vec<u8> = (0..w * h)
            .map(|i| if i % 2 == 0 { 10 } else { 21 })
            .collect();
        let img = GrayView::new(&buf, w, h, w).unwrap();
        let frame = SamplingFrame::of(&KeyPoint::new(40.5, 40.0));
        let mut window: Window = [0; WINDOW * WINDOW];
        sample_window(&img, &frame, &mut window);
        assert!(window.iter().all(|&s| s == 16));
    }

    #[test]
    fn a_crafted_triplet_decides_its_bit() {
        // Triplet 0 compares patch a (top-left 41,22) and patch c (51,24) with anchor b (47,47). Make the
        // window 0 except patch a = 0-ish anchor region: anchor 100, a = 100 (SSD 0), c = 0 (SSD > 0):
        // bit 0 must be 1. Swap a and c: bit 0 must be 0. Equal SSDs: bit 0 is 0 (strict comparison).
        let [ax, ay, bx, by, cx, cy] = TRIPLETS[0].map(|v| v as usize);
        let paint = |window: &mut Window, x: usize, y: usize, value: i16| {
            for r in 0..PATCH {
                for s in 0..PATCH {
                    window[(y + r) * WINDOW + x + s] = value;
                }
            }
        };
        let weights = PatchWeights::default().as_array().map(|w| w as i32);
        let width = DescriptorWidth::from_bits(8).unwrap();
        let mut bits = [0u64];
        for (a, c, expected) in [(100, 0, 1), (0, 100, 0), (100, 100, 0)] {
            let mut window: Window = [0; WINDOW * WINDOW];
            paint(&mut window, bx, by, 100);
            paint(&mut window, ax, ay, a);
            paint(&mut window, cx, cy, c);
            window_bits(&window, width, &weights, &mut bits);
            assert_eq!(bits[0] & 1, expected, "a = {a}, c = {c}");
        }
    }

    #[test]
    fn weights_decide_which_pixels_count() {
        // Only pixel (row 0, column 0) of each patch differs; the default weights ignore it, uniform ones
        // do not.
        let [ax, ay, ..] = TRIPLETS[0].map(|v| v as usize);
        let mut window: Window = [50; WINDOW * WINDOW];
        window[ay * WINDOW + ax] = 0;
        let width = DescriptorWidth::from_bits(8).unwrap();
        let mut bits = [0u64];
        window_bits(
            &window,
            width,
            &PatchWeights::latch_7x7().as_array().map(|w| w as i32),
            &mut bits,
        );
        let ignored = bits[0] & 1;
        window_bits(
            &window,
            width,
            &PatchWeights::uniform().as_array().map(|w| w as i32),
            &mut bits,
        );
        assert_eq!(ignored, 0, "equal SSDs give 0");
        assert_eq!(
            bits[0] & 1,
            0,
            "a differs from the anchor, so SSD(a, b) > SSD(c, b)"
        );
        window[ay * WINDOW + ax] = 50;
        let [.., cx, cy] = TRIPLETS[0].map(|v| v as usize);
        window[cy * WINDOW + cx] = 0;
        window_bits(
            &window,
            width,
            &PatchWeights::uniform().as_array().map(|w| w as i32),
            &mut bits,
        );
        assert_eq!(bits[0] & 1, 1, "now c differs, so SSD(a, b) < SSD(c, b)");
        window_bits(
            &window,
            width,
            &PatchWeights::latch_7x7().as_array().map(|w| w as i32),
            &mut bits,
        );
        assert_eq!(bits[0] & 1, 0, "and the 7x7 weights do not see it");
    }

    #[test]
    fn scaling_the_weights_keeps_the_bits() {
        // d scales with the weights, so its sign, the bit, does not change.
        let mut rng = crate::synthetic::SplitMix64::new(9);
        for round in 0..20 {
            let mut window: Window = [0; WINDOW * WINDOW];
            for p in window.iter_mut() {
                *p = (rng.next_u64() % 256) as i16;
            }
            let random: Vec<u32> = (0..64).map(|_| 1 + (rng.next_u64() % 9) as u32).collect();
            for weights in [
                PatchWeights::latch_7x7(),
                PatchWeights::new(&random).unwrap(),
            ] {
                let w = weights.as_array().map(|w| w as i32);
                let (mut once, mut thrice) = ([0u64; 8], [0u64; 8]);
                window_bits(&window, DescriptorWidth::FULL, &w, &mut once);
                window_bits(
                    &window,
                    DescriptorWidth::FULL,
                    &w.map(|w| 3 * w),
                    &mut thrice,
                );
                assert_eq!(once, thrice, "round {round}");
                assert_ne!(once, [0; 8], "round {round}: some bit is set");
            }
        }
    }

    #[test]
    fn describe_equals_the_reference_for_every_weighting() {
        // The fast path of `describe` against `sample_window` + `window_bits`, keypoint by keypoint, on
        // a strided image: random positions (1/64 pixel), sizes and angles, some windows outside.
        let (w, h, stride) = (300, 220, 307);
        let mut rng = crate::synthetic::SplitMix64::new(5);
        let data: Vec<u8> = (0..stride * h).map(|_| rng.next_u64() as u8).collect();
        let img = GrayView::new(&data, w, h, stride).unwrap();
        let keypoints: Vec<KeyPoint> = (0..300)
            .map(|_| {
                let x = rng.below(64 * (w as u64 - 1)) as f32 / 64.0;
                let y = rng.below(64 * (h as u64 - 1)) as f32 / 64.0;
                let kp = KeyPoint::new(x, y).with_angle(rng.below(2880) as f32 / 8.0);
                KeyPoint {
                    size: 1.0 + rng.below(160) as f32 / 2.0,
                    ..kp
                }
            })
            .collect();
        let random_mask: Vec<u32> = (0..64).map(|_| (rng.next_u64() % 2) as u32).collect();
        let random_weights: Vec<u32> = (0..64).map(|_| (rng.next_u64() % 7) as u32).collect();
        for (weights, bits) in [
            (PatchWeights::latch_7x7(), 512),
            (PatchWeights::latch_7x7(), 136),
            (PatchWeights::uniform(), 512),
            (PatchWeights::new(&random_mask).unwrap(), 256),
            (PatchWeights::new(&random_weights).unwrap(), 512),
        ] {
            let config = DescriptorConfig {
                width: DescriptorWidth::from_bits(bits).unwrap(),
                weights,
                smoothing: Smoothing::None,
            };
            let described = describe(&img, &keypoints, &config);
            assert!(described.keypoint_index.len() > 100 && !described.skipped.is_empty());
            let w32 = config.weights.as_array().map(|w| w as i32);
            for (row, &i) in described.keypoint_index.iter().enumerate() {
                let mut window: Window = [0; WINDOW * WINDOW];
                sample_window(&img, &SamplingFrame::of(&keypoints[i]), &mut window);
                let mut expected = vec![0u64; config.width.words()];
                window_bits(&window, config.width, &w32, &mut expected);
                assert_eq!(
                    described.descriptors.get(row).unwrap(),
                    &expected[..],
                    "{i}"
                );
            }
        }
    }

    #[test]
    fn smoothing_describes_the_smoothed_image() {
        // Describing with smoothing = describing the smoothed image without; and on noise, smoothing
        // changes bits (so the option is not ignored).
        let (w, h) = (200, 150);
        let buf = crate::synthetic::noise(w, h, 4).expect("synthetic image");
        let img = GrayView::new(&buf, w, h, w).unwrap();
        let mut rng = crate::synthetic::SplitMix64::new(8);
        let keypoints: Vec<KeyPoint> = (0..200)
            .map(|_| {
                KeyPoint::new(
                    rng.below(256 * (w as u64 - 1)) as f32 / 256.0,
                    rng.below(256 * (h as u64 - 1)) as f32 / 256.0,
                )
                .with_angle(rng.below(2880) as f32 / 8.0)
                .with_size(8.0 + rng.below(100) as f32)
            })
            .collect();
        let plain = describe(&img, &keypoints, &DescriptorConfig::default());
        for smoothing in [Smoothing::Binomial3, Smoothing::Binomial5] {
            let config = DescriptorConfig {
                smoothing,
                ..DescriptorConfig::default()
            };
            let described = describe(&img, &keypoints, &config);
            let pixels = smooth(&img, smoothing);
            let smoothed = GrayView::new(&pixels, w, h, w).unwrap();
            let expected = describe(&smoothed, &keypoints, &DescriptorConfig::default());
            assert_eq!(described, expected, "{smoothing:?}");
            assert_eq!(described.keypoint_index, plain.keypoint_index);
            assert!(!described.keypoint_index.is_empty() && !described.skipped.is_empty());
            let differing = (0..plain.descriptors.len())
                .filter(|&i| plain.descriptors.get(i) != described.descriptors.get(i))
                .count();
            assert!(
                differing * 2 > plain.descriptors.len(),
                "{smoothing:?}: only {differing} descriptors changed"
            );
        }
    }
}
