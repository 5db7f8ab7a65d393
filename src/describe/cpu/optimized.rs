//! The fast CPU path: the same integers as the reference functions of the parent module, computed
//! with fewer instructions. It picks, once per call, AVX2 kernels ([`super::avx2`], when the CPU has
//! them) or portable ones ([`super::portable`], written so that the compiler vectorises them).
//!
//! The tests at the end check both kernels against the reference on random inputs.

use std::ops::Range;

use super::Window;
use crate::describe::triplets::TRIPLETS;
use crate::describe::{PATCH, SamplingFrame, WINDOW};
use crate::descriptor::DescriptorWidth;
use crate::gray_view::GrayView;

/// Index in a [`Window`] of the top-left pixel of each triplet's patches `a, b, c`.
pub(super) type PatchOffsets = [usize; 3];

/// [`TRIPLETS`] as window indices (`y · WINDOW + x`).
pub(super) static OFFSETS: [PatchOffsets; TRIPLETS.len()] = offsets();

const fn offsets() -> [PatchOffsets; TRIPLETS.len()] {
    let mut table = [[0; 3]; TRIPLETS.len()];
    let mut t = 0;
    while t < TRIPLETS.len() {
        let mut p = 0;
        while p < 3 {
            let (x, y) = (TRIPLETS[t][2 * p] as usize, TRIPLETS[t][2 * p + 1] as usize);
            // Every patch lies inside the window: the kernels read `PATCH` rows of `PATCH` pixels from
            // here without further checks (the AVX2 loads rely on it).
            assert!(x + PATCH <= WINDOW && y + PATCH <= WINDOW);
            table[t][p] = y * WINDOW + x;
            p += 1;
        }
        t += 1;
    }
    table
}

/// The window rows that the first `bits` triplets read with a nonzero weight: the rows a window
/// must be sampled on for them (with the default weights, which leave each patch's first row out,
/// rows 5..60). The other rows' samples are multiplied by 0 wherever they are read, so any value
/// they hold gives the same bits.
pub(super) fn weighted_rows(weights: &[i32; PATCH * PATCH], bits: usize) -> Range<usize> {
    let weighted = |r: usize| weights[r * PATCH..][..PATCH].iter().any(|&w| w != 0);
    let (Some(first), Some(last)) = ((0..PATCH).find(|&r| weighted(r)), (0..PATCH).rfind(|&r| weighted(r)))
    else {
        return 0..0;
    };
    let patch_rows = OFFSETS[..bits].iter().flatten().map(|&at| at / WINDOW);
    let top = patch_rows.clone().min().map_or(0, |y| y + first);
    let bottom = patch_rows.max().map_or(0, |y| y + last + 1);
    top..bottom.max(top)
}

/// A 0/1 weight per patch pixel as a lane mask: -1 (all bits set) where the weight is 1, 0 elsewhere.
pub(super) type PixelMask = [i16; PATCH * PATCH];

/// The kernels one `describe` call uses.
#[derive(Clone, Copy, Debug)]
pub(super) enum Kernels {
    /// AVX2 gathers and 16-bit multiply-adds (x86-64 CPUs that report AVX2 at run time).
    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
    Avx2(super::avx2::Avx2),
    /// Plain Rust, auto-vectorised by the compiler.
    Portable,
}

impl Kernels {
    /// The fastest kernels this CPU runs.
    pub(super) fn detect() -> Self {
        #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
        if let Some(avx2) = super::avx2::Avx2::detect() {
            return Kernels::Avx2(avx2);
        }
        Kernels::Portable
    }

    /// Samples window rows `rows` (at least; the others may be left as they were) of a frame that
    /// fits the image: exactly [`super::sample_window`] on those rows.
    pub(super) fn sample(
        self,
        img: &GrayView,
        frame: &SamplingFrame,
        rows: Range<usize>,
        window: &mut Window,
    ) {
        let Some(plan) = SamplePlan::new(img, frame) else {
            return super::sample_window(img, frame, window);
        };
        match self {
            #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
            Kernels::Avx2(avx2) => avx2.sample_window(img, &plan, rows, window),
            Kernels::Portable => super::portable::sample_window(img, &plan, rows, window),
        }
    }

    /// The first `width` bits for 0/1 weights given as a mask: exactly [`super::window_bits`].
    pub(super) fn masked_bits(
        self,
        window: &Window,
        width: DescriptorWidth,
        mask: &PixelMask,
        out: &mut [u64],
    ) {
        match self {
            #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
            Kernels::Avx2(avx2) => avx2.masked_bits(window, width, mask, out),
            Kernels::Portable => {
                super::portable::masked_bits(window, &OFFSETS[..width.bits()], mask, out)
            }
        }
    }
}

/// A window's sample positions in 32-bit integers, relative to the pixel of the keypoint, with the
/// bounds of what the fast samplers read: for each sample, 4 bytes from its top-left pixel and 4 from
/// the pixel below (the clamped neighbours of the reference have weight 0, so reading the next pixel
/// instead is exact). `None` (the reference then samples) only for windows that come within a row of
/// the end of the buffer, or for images too large for 32-bit offsets.
///
/// Only [`SamplePlan::new`] makes one (the field is private), so holding one means its bounds were
/// checked; the unsafe AVX2 sampler relies on that.
#[derive(Clone, Copy, Debug)]
pub(super) struct SamplePlan(PlanFields);

/// What a [`SamplePlan`] holds (readable through it).
#[derive(Clone, Copy, Debug)]
pub(super) struct PlanFields {
    /// Index in the image data of the keypoint's whole-pixel position `(x0, y0)`.
    pub(super) base: usize,
    /// Row stride of the image.
    pub(super) stride: usize,
    /// One past the last byte any gather reads.
    pub(super) end: usize,
    /// Relative 16.16 position plus the 24.8 rounding half (`frac + 128 + (u - 32) eu + (v - 32) ev`)
    /// of window pixel `(0, 0)`.
    pub(super) start: [i32; 2],
    /// Steps along a window row and down a column (16.16).
    pub(super) step_u: [i32; 2],
    pub(super) step_v: [i32; 2],
}

impl SamplePlan {
    /// The plan of a frame that [`SamplingFrame::fits`] the image.
    ///
    /// With `o = 65536 O + f` (`O` whole pixels), `P8 = (o + d + 128) >> 8 = 256 O + ((f + d + 128) >> 8)`
    /// exactly, so the sample's pixel is `O + (R >> 16)` and its fraction `(R >> 8) & 255` for the
    /// relative `R = f + d + 128`, which fits 32 bits for any supported size.
    pub(super) fn new(img: &GrayView, frame: &SamplingFrame) -> Option<Self> {
        let whole = frame.origin.map(|o| o >> 16);
        let half = (WINDOW / 2) as i64;
        let start: [i64; 2] = [0, 1].map(|axis| {
            (frame.origin[axis] & 0xffff) + 128 - half * (frame.step_u[axis] + frame.step_v[axis])
        });
        // Each coordinate is monotone in u and v, so its extremes over the window are at corners
        // (`as i32` below is exact because every value lies between them). The pixel offset
        // `(y >> 16) stride + (x >> 16)` is not (the floors), so it is bounded from the separate
        // extremes of its two terms.
        let last = (WINDOW - 1) as i64;
        let corners = [(0, 0), (last, 0), (0, last), (last, last)].map(|(u, v)| {
            [0, 1].map(|axis| start[axis] + u * frame.step_u[axis] + v * frame.step_v[axis])
        });
        let extreme = |axis: usize, pick: fn(i64, i64) -> i64| {
            corners
                .iter()
                .map(|r| r[axis])
                .reduce(pick)
                .expect("four corners")
        };
        let (low, high) = (
            [0, 1].map(|a| extreme(a, i64::min)),
            [0, 1].map(|a| extreme(a, i64::max)),
        );
        let stride = img.stride() as i64;
        let lowest = (low[1] >> 16) * stride + (low[0] >> 16);
        let highest = (high[1] >> 16) * stride + (high[0] >> 16);
        let fits_i32 = |v: i64| i32::try_from(v).is_ok();
        // Every lane value (positions, `(y >> 16) stride`, offsets) lies between these.
        let lanes_fit = [low, high].iter().flatten().all(|&r| fits_i32(r))
            && [
                lowest,
                highest,
                (low[1] >> 16) * stride,
                (high[1] >> 16) * stride,
            ]
            .iter()
            .all(|&v| fits_i32(v));
        // Products `u · step` (u < 64) and the 8-lane strides stay in range too.
        let steps_fit = frame
            .step_u
            .iter()
            .chain(&frame.step_v)
            .all(|&s| fits_i32(s * WINDOW as i64));
        let base = whole[1] * stride + whole[0];
        // A sample reads 4 bytes from its top-left pixel and 4 from the pixel below.
        let end = base + highest + stride + 4;
        // `highest >= 0` (the keypoint's own pixel is sampled) puts `base + stride` before `end`.
        let inside = base + lowest >= 0 && highest >= 0 && end <= img.data().len() as i64;
        if !(lanes_fit && steps_fit && inside) {
            return None;
        }
        Some(Self(PlanFields {
            base: base as usize,
            stride: img.stride(),
            end: end as usize,
            start: start.map(|s| s as i32),
            step_u: frame.step_u.map(|s| s as i32),
            step_v: frame.step_v.map(|s| s as i32),
        }))
    }
}

impl std::ops::Deref for SamplePlan {
    type Target = PlanFields;

    fn deref(&self) -> &PlanFields {
        &self.0
    }
}

/// The mask of 0/1 weights, `None` if some weight is larger.
pub(super) fn pixel_mask(weights: &[i32; PATCH * PATCH]) -> Option<PixelMask> {
    weights
        .iter()
        .all(|&w| w == 0 || w == 1)
        .then(|| weights.map(|w| -(w as i16)))
}

#[cfg(test)]
mod tests {
    use super::super::{sample_window, window_bits};
    use super::*;
    use crate::angle::ANGLE_BINS;
    use crate::describe::PatchWeights;
    use crate::keypoint::KeyPoint;
    use crate::synthetic::SplitMix64;

    /// Every kernel set this machine can run (the portable one always).
    fn all_kernels() -> Vec<Kernels> {
        let mut kernels = vec![Kernels::Portable];
        if !matches!(Kernels::detect(), Kernels::Portable) {
            kernels.push(Kernels::detect());
        } else {
            eprintln!("note: no AVX2 on this CPU, only the portable kernels are tested");
        }
        kernels
    }

    /// A random frame that fits a `w` x `h` image: any bin, size and 1/256-pixel position; tried until
    /// one fits (small sizes fit anywhere).
    fn random_frame(rng: &mut SplitMix64, w: usize, h: usize, bin: usize) -> SamplingFrame {
        loop {
            let size = match rng.below(4) {
                0 => 1.0 + rng.below(64) as f32 / 8.0,
                1 => 64.0,
                _ => 1.0 + rng.below(1023 * 16) as f32 / 16.0,
            };
            let x = rng.below(256 * (w as u64 - 1) + 1) as f32 / 256.0;
            let y = rng.below(256 * (h as u64 - 1) + 1) as f32 / 256.0;
            let kp = KeyPoint::new(x, y).with_angle(bin as f32 / 8.0);
            let kp = KeyPoint { size, ..kp };
            let frame = SamplingFrame::of(&kp);
            if frame.fits(w, h) {
                return frame;
            }
        }
    }

    /// Frames whose windows touch the image's edges: angle 0, size 64, a corner sample exactly on the
    /// first or last row or column. The bottom-right one ends at the last byte of the buffer when the
    /// stride equals the width; the right one reads (with weight 0) the byte past its row's end.
    fn edge_frames(w: usize, h: usize) -> Vec<SamplingFrame> {
        let (right, bottom) = ((w - 32) as f32, (h - 32) as f32);
        let (mid_x, mid_y) = ((w / 2) as f32, (h / 2) as f32);
        [
            (32.0, 32.0),
            (right, mid_y),
            (mid_x, bottom),
            (right, bottom),
        ]
        .map(|(x, y)| {
            let frame = SamplingFrame::of(&KeyPoint::new(x, y));
            assert!(frame.fits(w, h), "({x}, {y}) in {w}x{h}");
            frame
        })
        .to_vec()
    }

    #[test]
    fn fast_sampling_equals_the_reference_for_every_bin() {
        let mut rng = SplitMix64::new(17);
        // Square, wide, tall images; strides equal to and larger than the width, one longer than the
        // AVX2 sampler's 16-bit offsets take.
        let shapes = [
            (97, 89, 97),
            (160, 70, 171),
            (70, 150, 70),
            (400, 300, 40_003),
        ];
        for (shape, &(w, h, stride)) in shapes.iter().enumerate() {
            let data: Vec<u8> = (0..stride * h).map(|_| rng.next_u64() as u8).collect();
            let img = GrayView::new(&data, w, h, stride).unwrap();
            let mut frames: Vec<SamplingFrame> = (0..ANGLE_BINS)
                .filter(|bin| bin % 4 == shape)
                .map(|bin| random_frame(&mut rng, w, h, bin))
                .collect();
            frames.extend(edge_frames(w, h));
            // The default keypoints: whole-pixel positions, size 40 (the AVX2 sampler's local copy).
            frames.extend((0..ANGLE_BINS).filter(|bin| bin % 4 == shape).filter_map(|bin| {
                let (x, y) = (30 + rng.below(w as u64 - 60), 30 + rng.below(h as u64 - 60));
                let kp = KeyPoint::new(x as f32, y as f32).with_angle(bin as f32 / 8.0);
                let frame = SamplingFrame::of(&KeyPoint { size: 40.0, ..kp });
                frame.fits(w, h).then_some(frame)
            }));
            // The fast samplers take all but the windows that reach the buffer's last row.
            let planned = frames
                .iter()
                .filter(|f| SamplePlan::new(&img, f).is_some())
                .count();
            assert!(
                planned * 10 > frames.len() * 9,
                "{planned} of {}",
                frames.len()
            );
            for frame in frames {
                let mut expected: Window = [0; WINDOW * WINDOW];
                sample_window(&img, &frame, &mut expected);
                for kernels in all_kernels() {
                    let mut got: Window = [-1; WINDOW * WINDOW];
                    kernels.sample(&img, &frame, 0..WINDOW, &mut got);
                    assert!(got == expected, "{kernels:?} {frame:?} on {w}x{h}/{stride}");
                }
            }
        }
    }

    #[test]
    fn a_plan_bounds_every_read_of_its_window() {
        // Each sample reads 4 bytes at its top-left pixel and 4 at the pixel below: all must lie
        // before `end` (the AVX2 gathers rely on it), for any bin, size and position.
        let mut rng = SplitMix64::new(29);
        let (w, h, stride) = (300, 260, 311);
        let data = vec![0u8; stride * h];
        let img = GrayView::new(&data, w, h, stride).unwrap();
        let mut planned = 0;
        for bin in (0..ANGLE_BINS).step_by(7) {
            let frame = random_frame(&mut rng, w, h, bin);
            let Some(plan) = SamplePlan::new(&img, &frame) else {
                continue;
            };
            planned += 1;
            for (u, v) in (0..WINDOW * WINDOW).map(|i| (i % WINDOW, i / WINDOW)) {
                let [x, y] = frame.sample_position(u, v).map(|p| (p >> 8) as usize);
                let top_left = y * stride + x;
                assert!(top_left + stride + 4 <= plan.end, "{frame:?} ({u}, {v})");
                let relative = top_left as i64 - plan.base as i64;
                assert!(i32::try_from(relative).is_ok(), "{frame:?} ({u}, {v})");
            }
        }
        assert!(planned > 300, "{planned}");
    }

    #[test]
    fn masked_bits_equal_the_reference_for_every_mask_and_width() {
        let mut rng = SplitMix64::new(23);
        for round in 0..60 {
            let mut window: Window = [0; WINDOW * WINDOW];
            // Full-range noise, and every fourth round a nearly flat window (many equal SSDs).
            let flat = round % 4 == 3;
            for p in window.iter_mut() {
                *p = if flat {
                    100 + rng.below(2) as i16
                } else {
                    rng.below(256) as i16
                };
            }
            let random: Vec<u32> = (0..64).map(|_| rng.below(2) as u32).collect();
            let masks = [
                PatchWeights::latch_7x7(),
                PatchWeights::uniform(),
                PatchWeights::new(&random).unwrap_or_else(|_| PatchWeights::uniform()),
            ];
            let width = DescriptorWidth::from_bits(8 * (1 + rng.below(64) as usize)).unwrap();
            for weights in masks {
                let weights = weights.as_array().map(|w| w as i32);
                let mask = pixel_mask(&weights).expect("0/1 weights");
                let mut expected = vec![0u64; width.words()];
                window_bits(&window, width, &weights, &mut expected);
                for kernels in all_kernels() {
                    let mut got = vec![!0u64; width.words()];
                    kernels.masked_bits(&window, width, &mask, &mut got);
                    assert_eq!(got, expected, "{kernels:?} round {round} {width:?}");
                }
            }
        }
    }

    #[test]
    fn weighted_rows_of_the_default_and_other_weights() {
        let rows = |w: PatchWeights, bits| weighted_rows(&w.as_array().map(|w| w as i32), bits);
        assert_eq!(rows(PatchWeights::latch_7x7(), 512), 5..60);
        assert_eq!(rows(PatchWeights::uniform(), 512), 4..60);
        // Only the last patch row weighted: the patches' tops plus 7.
        let mut last = [0u32; 64];
        last[63] = 1;
        let tops = OFFSETS[..8].iter().flatten().map(|&at| at / WINDOW);
        let (top, bottom) = (tops.clone().min().unwrap(), tops.max().unwrap());
        assert_eq!(rows(PatchWeights::new(&last).unwrap(), 8), top + 7..bottom + 8);
    }

    #[test]
    fn only_0_1_weights_make_a_mask() {
        let mut weights = PatchWeights::latch_7x7().as_array().map(|w| w as i32);
        assert_eq!(
            pixel_mask(&weights).unwrap()[..9],
            [0, 0, 0, 0, 0, 0, 0, 0, 0]
        );
        assert_eq!(pixel_mask(&weights).unwrap()[9], -1);
        weights[9] = 2;
        assert_eq!(pixel_mask(&weights), None);
    }
}
