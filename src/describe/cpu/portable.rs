//! Portable fast kernels: the reference arithmetic rearranged so that bounds checks leave the inner
//! loops and the compiler vectorises the patch sums (any target; the fallback where AVX2 is absent).

use super::Window;
use super::fast::{PatchOffsets, PixelMask, SamplePlan};
use crate::describe::{PATCH, WINDOW};
use crate::image::GrayView;

/// Exactly [`super::sample_window`] for a window with a plan, in three passes per window row: the
/// positions (vectorised), the pixel pairs (scalar loads, one bounds check per pair) and the
/// interpolation (vectorised).
pub(super) fn sample_window(img: &GrayView, plan: &SamplePlan, window: &mut Window) {
    let data = &img.data()[..plan.end];
    let (base, stride) = (plan.base as isize, plan.stride as isize);
    for (v, out_row) in window.chunks_exact_mut(WINDOW).enumerate() {
        let row = [0, 1].map(|axis| plan.start[axis] + v as i32 * plan.step_v[axis]);
        let position = |u: usize, axis: usize| row[axis] + u as i32 * plan.step_u[axis];
        let offset: [isize; WINDOW] = std::array::from_fn(|u| {
            let (x, y) = (position(u, 0), position(u, 1));
            base + (y >> 16) as isize * stride + (x >> 16) as isize
        });
        let fraction =
            |axis| -> [i32; WINDOW] { std::array::from_fn(|u| (position(u, axis) >> 8) & 255) };
        let (fx, fy) = (fraction(0), fraction(1));
        // Bytes 0, 1 of each pair: the sample's pixel and its right neighbour.
        let pair = |at: isize| -> [u8; 2] {
            let at = at as usize;
            data[at..at + 2]
                .try_into()
                .expect("inside the plan's bounds")
        };
        let top: [[u8; 2]; WINDOW] = std::array::from_fn(|u| pair(offset[u]));
        let bottom: [[u8; 2]; WINDOW] = std::array::from_fn(|u| pair(offset[u] + stride));
        for (u, out) in out_row.iter_mut().enumerate() {
            // p0 (256 - f) + p1 f = 256 p0 + (p1 - p0) f: the same integer.
            let lerp = |[p0, p1]: [u8; 2]| 256 * p0 as i32 + (p1 as i32 - p0 as i32) * fx[u];
            let (upper, lower) = (lerp(top[u]), lerp(bottom[u]));
            *out = ((256 * upper + (lower - upper) * fy[u] + (1 << 15)) >> 16) as i16;
        }
    }
}

/// Span of window indices one patch covers from its top-left pixel.
const PATCH_SPAN: usize = (PATCH - 1) * WINDOW + PATCH;

/// The pixels of the patch at `at` (rows `WINDOW` apart): one bounds check for the whole patch.
fn patch(window: &Window, at: usize) -> &[i16; PATCH_SPAN] {
    window[at..at + PATCH_SPAN]
        .try_into()
        .expect("a span of PATCH_SPAN")
}

/// Exactly [`super::window_bits`] for 0/1 weights, by `(a - b)² - (c - b)² = (a - c)(a + c - 2b)`:
/// both factors fit `i16`, so each row is a 16-bit multiply-add (SSE2 `pmaddwd`); the sum is exact in
/// `i32` like the reference.
pub(super) fn masked_bits(
    window: &Window,
    offsets: &[PatchOffsets],
    mask: &PixelMask,
    out: &mut [u64],
) {
    out.fill(0);
    for (t, &[a, b, c]) in offsets.iter().enumerate() {
        let (a, b, c) = (patch(window, a), patch(window, b), patch(window, c));
        // One row's sum; the rows are written out, not looped over, so that the compiler vectorises
        // along each row (8 lanes) instead of gathering across rows.
        let row = |r: usize| -> i32 {
            let row = |p: &[i16; PATCH_SPAN]| -> [i16; PATCH] {
                p[r * WINDOW..r * WINDOW + PATCH].try_into().unwrap()
            };
            let (a, b, c) = (row(a), row(b), row(c));
            let m = &mask[r * PATCH..][..PATCH];
            (0..PATCH)
                .map(|s| ((a[s] - c[s]) & m[s]) as i32 * (a[s] + c[s] - b[s] - b[s]) as i32)
                .sum()
        };
        let d = row(0) + row(1) + row(2) + row(3) + row(4) + row(5) + row(6) + row(7);
        if d < 0 {
            out[t / 64] |= 1 << (t % 64);
        }
    }
}
