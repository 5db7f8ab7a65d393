//! The reference OpenCV-compatible LATCH on the CPU (see the parent module for the numeric contract).

use crate::parallel::*;

use super::{OPENCV_CENTRES, OpencvLatch, Placed, Placement};
use crate::describe::Described;
use crate::descriptor::DescriptorSet;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;

/// `SSD(a, b)` and `SSD(c, b)` of one triplet over `(2h + 1)²` patches around absolute centres.
#[inline]
fn triplet_ssds(image: &GrayView, centres: [(i32, i32); 3], h: i32) -> (i32, i32) {
    let side = (2 * h + 1) as usize;
    let patch_row =
        |(x, y): (i32, i32), dy: i32| &image.row((y + dy) as usize)[(x - h) as usize..][..side];
    let (mut sum_a, mut sum_c) = (0i32, 0i32);
    for dy in -h..=h {
        let [a, b, c] = centres.map(|centre| patch_row(centre, dy));
        for ((&a, &b), &c) in a.iter().zip(b).zip(c) {
            let (da, dc) = (a as i32 - b as i32, c as i32 - b as i32);
            sum_a += da * da;
            sum_c += dc * dc;
        }
    }
    (sum_a, sum_c)
}

/// The first `bits` bits of one keypoint's descriptor, packed least significant bit first. The
/// placement must have passed the border rule, so every patch lies inside the image.
pub fn keypoint_bits(
    image: &GrayView,
    placement: &Placement,
    half_ssd_size: usize,
    bits: usize,
    out: &mut [u64],
) {
    out.fill(0);
    for (t, c) in OPENCV_CENTRES[..bits].iter().enumerate() {
        let centres = [0, 2, 4].map(|i| {
            let (x, y) = placement.rotate(c[i], c[i + 1]);
            (placement.x + x, placement.y + y)
        });
        let (sum_a, sum_c) = triplet_ssds(image, centres, half_ssd_size as i32);
        if sum_a < sum_c {
            out[t / 64] |= 1 << (t % 64);
        }
    }
}

/// Describes the placed keypoints (in parallel over keypoints) on the blurred image.
pub fn describe(
    image: &GrayView,
    keypoints: &[KeyPoint],
    latch: &OpencvLatch,
    placed: Placed,
) -> Described {
    let Placed {
        keypoint_index,
        skipped,
        placements,
    } = placed;
    debug_assert_eq!(keypoint_index.len(), placements.len());
    debug_assert!(keypoint_index.iter().all(|&i| i < keypoints.len()));
    let width = latch.width();
    let per = width.words();
    let blurred = if placements.is_empty() {
        None
    } else {
        latch.blurred(image)
    };
    let source = match &blurred {
        Some(pixels) => GrayView::new(pixels, image.width(), image.height(), image.width())
            .expect("the blur keeps the image's size"),
        None => *image,
    };
    let mut words = vec![0u64; placements.len() * per];
    words
        .par_chunks_mut(per)
        .zip(placements.par_iter())
        .for_each(|(out, placement)| {
            keypoint_bits(&source, placement, latch.half_ssd_size(), width.bits(), out);
        });
    Described {
        descriptors: DescriptorSet::from_words(width, words).expect("whole rows by construction"),
        keypoint_index,
        skipped,
    }
}

#[cfg(test)]
impl OpencvLatch {
    /// Placement and description on the CPU, as the façade runs them.
    fn describe_cpu(
        &self,
        image: &GrayView,
        keypoints: &[KeyPoint],
    ) -> crate::error::Result<Described> {
        let placed = self.place(image, keypoints)?;
        Ok(describe(image, keypoints, self, placed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::describe::SkipReason;

    /// The bit of triplet `t` recomputed from scratch with `i64` sums, OpenCV's loop as written.
    fn naive_bit(image: &GrayView, kp: &KeyPoint, t: usize, rotate: bool, h: i32) -> bool {
        let (c, s) = if rotate {
            super::super::cos_sin(kp.angle)
        } else {
            (1.0, 0.0)
        };
        let p = OPENCV_CENTRES[t].map(|v| v as f32);
        let mut centre = [(0i64, 0i64); 3];
        for k in 0..3 {
            let (x, y) = (p[2 * k], p[2 * k + 1]);
            let rx = ((x * c - y * s) as i64).clamp(-24, 24);
            let ry = ((x * s + y * c) as i64).clamp(-24, 24);
            centre[k] = (
                rx + (kp.x as f64 + 0.5) as i64,
                ry + (kp.y as f64 + 0.5) as i64,
            );
        }
        let px = |(x, y): (i64, i64)| image.at(x as usize, y as usize) as i64;
        let (mut sa, mut sc) = (0i64, 0i64);
        for dy in -h as i64..=h as i64 {
            for dx in -h as i64..=h as i64 {
                let at = |k: usize| px((centre[k].0 + dx, centre[k].1 + dy));
                sa += (at(0) - at(1)).pow(2);
                sc += (at(2) - at(1)).pow(2);
            }
        }
        sa < sc
    }

    #[test]
    fn bits_equal_a_naive_recomputation() {
        let (w, h) = (160, 120);
        let pixels = crate::synthetic::noise(w, h, 7).expect("synthetic image");
        let image = GrayView::new(&pixels, w, h, w).unwrap();
        let mut rng = crate::synthetic::SplitMix64::new(3);
        let keypoints: Vec<KeyPoint> = (0..60)
            .map(|_| {
                KeyPoint::new(
                    rng.below(w as u64 * 100) as f32 / 100.0,
                    rng.below(h as u64 * 100) as f32 / 100.0,
                )
                .with_angle(rng.below(72_000) as f32 / 100.0 - 360.0)
            })
            .collect();
        for (rotate, half) in [(true, 3usize), (false, 3), (true, 0), (true, 5)] {
            let latch = OpencvLatch::new(64, rotate, half, 0.0).unwrap();
            let described = latch.describe_cpu(&image, &keypoints).unwrap();
            assert!(described.descriptors.len() > 10, "enough keypoints inside");
            for (row, &i) in described.keypoint_index.iter().enumerate() {
                let d = described.descriptors.descriptor(row).unwrap();
                for t in 0..512 {
                    assert_eq!(
                        d.bit(t).expect("t < 512"),
                        naive_bit(&image, &keypoints[i], t, rotate, half as i32),
                        "keypoint {i}, triplet {t}, rotate {rotate}, h {half}"
                    );
                }
            }
            assert_eq!(
                described.keypoint_index.len() + described.skipped.len(),
                keypoints.len()
            );
        }
    }

    #[test]
    fn clatch_equals_opencv_latch_where_their_rules_meet() {
        // docs/opencv_compat.md: with size 64, angle 0, integer positions, the default 7x7 weights, and
        // OpenCV's rotation and blur off, CLATCH's window patches are OpenCV's 7x7 patches.
        let (w, h) = (200, 160);
        let pixels = crate::synthetic::noise(w, h, 4).expect("synthetic image");
        let image = GrayView::new(&pixels, w, h, w).unwrap();
        let keypoints: Vec<KeyPoint> = (0..100)
            .map(|i| KeyPoint::new((40 + i % 120) as f32, (40 + i / 2 % 80) as f32))
            .collect();
        let clatch = crate::describe::cpu::describe(
            &image,
            &keypoints,
            &crate::describe::DescriptorConfig::default(),
        );
        let opencv = OpencvLatch::new(64, false, 3, 0.0)
            .unwrap()
            .describe_cpu(&image, &keypoints)
            .unwrap();
        assert_eq!(clatch.keypoint_index.len(), keypoints.len());
        assert_eq!(clatch, opencv);
    }

    #[test]
    fn narrower_widths_are_prefixes() {
        let (w, h) = (100, 100);
        let pixels = crate::synthetic::noise(w, h, 2).expect("synthetic image");
        let image = GrayView::new(&pixels, w, h, w).unwrap();
        let kps = [KeyPoint::new(50.0, 50.0).with_angle(-1.0)];
        let full = OpencvLatch::new(64, true, 3, 2.0)
            .unwrap()
            .describe_cpu(&image, &kps)
            .unwrap()
            .descriptors
            .to_opencv_bytes();
        for bytes in [1, 2, 4, 8, 16, 32] {
            let short = OpencvLatch::new(bytes, true, 3, 2.0)
                .unwrap()
                .describe_cpu(&image, &kps)
                .unwrap()
                .descriptors
                .to_opencv_bytes();
            assert_eq!(short, full[..bytes]);
        }
    }

    #[test]
    fn small_images_skip_everything_and_bad_keypoints_are_errors() {
        let pixels = vec![7u8; 40 * 40];
        let image = GrayView::new(&pixels, 40, 40, 40).unwrap();
        let latch = OpencvLatch::default();
        let described = latch
            .describe_cpu(&image, &[KeyPoint::new(20.0, 20.0)])
            .unwrap();
        assert!(described.descriptors.is_empty());
        assert_eq!(described.skipped[0].reason, SkipReason::OpencvBorder);
        let nan = KeyPoint::new(20.0, 20.0).with_angle(f32::NAN);
        assert!(matches!(
            latch.describe_cpu(&image, &[nan]),
            Err(crate::Error::InvalidKeyPoint { field: "angle", .. })
        ));
    }
}
