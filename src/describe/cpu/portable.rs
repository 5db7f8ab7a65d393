//! Portable fast kernels: the reference arithmetic rearranged so that bounds checks leave the inner
//! loops and the compiler vectorises the patch sums (any target; the fallback where AVX2 is absent).

use super::Window;
use super::optimized::{PatchOffsets, PixelMask, SamplePlan};
use crate::describe::{PATCH, WINDOW};
use crate::gray_view::GrayView;

/// Exactly [`super::sample_window`] on window rows `rows` for a window with a plan, in three passes per window row: the
/// positions (vectorised), the pixel pairs (scalar loads, one bounds check per pair) and the
/// interpolation (vectorised).
pub(super) fn sample_window(
    img: &GrayView,
    plan: &SamplePlan,
    rows: std::ops::Range<usize>,
    window: &mut Window,
) {
    let data = &img.data()[..plan.end];
    let (step, stride) = (plan.step_u, plan.stride as i32);
    let (mut offset, mut fx, mut fy) = ([0i32; WINDOW], [0i32; WINDOW], [0i32; WINDOW]);
    let mut pixels = [[0i32; WINDOW]; 4];
    let (first, end) = (rows.start, rows.end);
    for (v, out_row) in window.chunks_exact_mut(WINDOW).enumerate().take(end).skip(first) {
        let row = [0, 1].map(|axis| plan.start[axis] + v as i32 * plan.step_v[axis]);
        for u in 0..WINDOW {
            let (x, y) = (row[0] + u as i32 * step[0], row[1] + u as i32 * step[1]);
            // In range by the plan's construction.
            offset[u] = (y >> 16) * stride + (x >> 16);
            fx[u] = (x >> 8) & 255;
            fy[u] = (y >> 8) & 255;
        }
        for (u, &relative) in offset.iter().enumerate() {
            let at = plan.base.wrapping_add_signed(relative as isize);
            // The sample's pixel and its right neighbour, in its row and the next.
            let (top, bottom) = (
                &data[at..at + 2],
                &data[at + plan.stride..at + plan.stride + 2],
            );
            pixels[0][u] = top[0] as i32;
            pixels[1][u] = top[1] as i32;
            pixels[2][u] = bottom[0] as i32;
            pixels[3][u] = bottom[1] as i32;
        }
        for (u, out) in out_row.iter_mut().enumerate() {
            // p0 (256 - f) + p1 f = 256 p0 + (p1 - p0) f: the same integer.
            let lerp = |p0: i32, p1: i32| 256 * p0 + (p1 - p0) * fx[u];
            let upper = lerp(pixels[0][u], pixels[1][u]);
            let lower = lerp(pixels[2][u], pixels[3][u]);
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
