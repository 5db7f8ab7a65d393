//! Portable fast kernels: the reference arithmetic rearranged so that bounds checks leave the inner
//! loops and the compiler vectorises the patch sums (any target; the fallback where AVX2 is absent).

use super::Window;
use super::fast::{PatchOffsets, PixelMask};
use crate::describe::{PATCH, SamplingFrame, WINDOW};
use crate::image::GrayView;

/// Exactly [`super::sample_window`]: one index computation per sample instead of two row slices,
/// and the clamp as a 0 step (the clamped neighbour's weight is 0 anyway, but it must be readable).
pub(super) fn sample_window(img: &GrayView, frame: &SamplingFrame, window: &mut Window) {
    let (data, stride) = (img.data(), img.stride());
    let (last_x, last_y) = (img.width() - 1, img.height() - 1);
    let half = (WINDOW / 2) as i64;
    for (v, out_row) in window.chunks_exact_mut(WINDOW).enumerate() {
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
            let right = usize::from(x0 < last_x);
            let down = if y0 < last_y { stride } else { 0 };
            let i = y0 * stride + x0;
            let pixel = |j: usize| data[j] as i32;
            // p00 (256 - f) + p01 f = 256 p00 + (p01 - p00) f: the same integer.
            let upper = 256 * pixel(i) + (pixel(i + right) - pixel(i)) * fx;
            let lower = 256 * pixel(i + down) + (pixel(i + down + right) - pixel(i + down)) * fx;
            *out = ((256 * upper + (lower - upper) * fy + (1 << 15)) >> 16) as i16;
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
