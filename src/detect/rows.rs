//! FAST scores of whole row segments, [`LANES`] pixels at a time, for [`super::cpu::score_map`]: the
//! integers of [`super::cpu::fast_score`] wherever that score exceeds the threshold, 0 elsewhere.
//!
//! Why saturating `u8` lanes give the same integers: with `s = max(B, D)` the exact score,
//! `B = max_k min_j (c[k+j] - p)` and `D = max_k min_j (p - c[k+j])`, the same minima and maxima of
//! the saturated differences `max(c - p, 0)` and `max(p - c, 0)` give `max(B, 0)` and `max(D, 0)`
//! (min and max commute with `max(·, 0)`), so `max(s, 0)`: equal to `s` wherever `s > threshold ≥ 0`,
//! the only pixels whose score is kept. Every lane is computed on its own, so the segments may
//! overlap (the last one is moved back to end at the segment's end) without changing a value.
//!
//! The same code is compiled twice: with AVX2 (32-byte registers) where the CPU reports it at run
//! time, and for the target's baseline (SSE2 on x86-64) otherwise; being integer code, both give the
//! same bytes (a test compares them with the scalar reference).

use super::FAST_CIRCLE;
use crate::gray_view::GrayView;

/// Pixels scored together.
pub(super) const LANES: usize = 32;

// The suppression gathers one bit per lane into a `u32`.
const _: () = assert!(LANES <= 32);

type Lanes = [u8; LANES];

/// How the rows are scored on this CPU (chosen once per score map).
#[derive(Clone, Copy, Debug)]
pub(super) enum RowKernel {
    /// The code below compiled with AVX2 (x86-64 CPUs that report it at run time).
    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
    Avx2,
    /// The code below for the target's baseline.
    Portable,
}

impl RowKernel {
    /// The fastest kernel this CPU runs.
    pub(super) fn detect() -> Self {
        #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
        if std::arch::is_x86_feature_detected!("avx2") {
            return RowKernel::Avx2;
        }
        RowKernel::Portable
    }

    /// Scores of row `y` for `x` in `xs` into `out` (`out[i]` for `x = xs.start + i`): the FAST score
    /// where it exceeds `threshold`, 0 elsewhere. Every circle must lie inside the image
    /// (`xs.start ≥ 3`, `xs.end + 3 ≤ width`, `3 ≤ y < height - 3`) and `xs` hold at least [`LANES`]
    /// pixels.
    pub(super) fn score_row(
        self,
        img: &GrayView,
        y: usize,
        xs: std::ops::Range<usize>,
        threshold: u8,
        out: &mut [u8],
    ) {
        let rows: [&[u8]; 7] = std::array::from_fn(|j| img.row(y + j - 3));
        match self {
            #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
            // SAFETY: `RowKernel::Avx2` is only made when the CPU reports AVX2 (`detect`); the
            // function is otherwise safe code.
            RowKernel::Avx2 => unsafe { score_row_avx2(rows, xs, threshold, out) },
            RowKernel::Portable => score_row(rows, xs, threshold, out),
        }
    }
    /// Non-maximum suppression of the middle row of `rows` (three rows of one score map): calls
    /// `keep(x)`, in increasing `x`, for each pixel of `1..` that the suppression keeps, [`LANES`]
    /// pixels at a time, and returns the pixels left at the row's end (before `width - 1`) for the
    /// caller to test one by one.
    pub(super) fn suppress_row(
        self,
        rows: [&[u8]; 3],
        keep: &mut impl FnMut(usize),
    ) -> std::ops::Range<usize> {
        match self {
            #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
            // SAFETY: as in `score_row`.
            RowKernel::Avx2 => unsafe { suppress_row_avx2(rows, keep) },
            RowKernel::Portable => suppress_row(rows, keep),
        }
    }
}

/// [`suppress_row`] compiled with AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
#[target_feature(enable = "avx2")]
unsafe fn suppress_row_avx2(rows: [&[u8]; 3], keep: &mut impl FnMut(usize)) -> std::ops::Range<usize> {
    suppress_row(rows, keep)
}

/// See [`RowKernel::suppress_row`]. A pixel is kept iff its score is positive, `>` the three above
/// and the left one, `>=` the right one and the three below.
#[inline(always)]
fn suppress_row(rows: [&[u8]; 3], keep: &mut impl FnMut(usize)) -> std::ops::Range<usize> {
    let [above, here, below] = rows;
    let width = here.len();
    assert!(above.len() == width && below.len() == width);
    let lanes = |row: &[u8], x: usize| -> Lanes { row[x..x + LANES].try_into().expect("LANES bytes") };
    let mut x = 1;
    while x + LANES < width {
        let s = lanes(here, x);
        if s.iter().fold(0, |any, &v| any | v) != 0 {
            let earlier = [lanes(above, x - 1), lanes(above, x), lanes(above, x + 1), lanes(here, x - 1)];
            let later = [lanes(here, x + 1), lanes(below, x - 1), lanes(below, x), lanes(below, x + 1)];
            let mut bits = 0u32;
            for i in 0..LANES {
                let mut kept = s[i] > 0;
                for n in &earlier {
                    kept &= s[i] > n[i];
                }
                for n in &later {
                    kept &= s[i] >= n[i];
                }
                bits |= (kept as u32) << i;
            }
            while bits != 0 {
                keep(x + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
        x += LANES;
    }
    x..width.saturating_sub(1).max(x)
}

/// [`score_row`] compiled with AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
#[target_feature(enable = "avx2")]
unsafe fn score_row_avx2(rows: [&[u8]; 7], xs: std::ops::Range<usize>, threshold: u8, out: &mut [u8]) {
    score_row(rows, xs, threshold, out)
}

/// See [`RowKernel::score_row`]; `rows[j]` is image row `y + j - 3`.
#[inline(always)]
fn score_row(rows: [&[u8]; 7], xs: std::ops::Range<usize>, threshold: u8, out: &mut [u8]) {
    let n = xs.len();
    assert!(n >= LANES && out.len() == n && xs.start >= 3);
    let mut i = 0;
    loop {
        // The last segment ends at the row's end, overlapping the one before.
        let start = i.min(n - LANES);
        let lanes: &mut Lanes = (&mut out[start..start + LANES]).try_into().expect("LANES bytes");
        score_lanes(&rows, xs.start + start, threshold, lanes);
        if start + LANES == n {
            break;
        }
        i += LANES;
    }
}

/// The scores of pixels `x..x + LANES` of the middle row of `rows`.
#[inline(always)]
fn score_lanes(rows: &[&[u8]; 7], x: usize, threshold: u8, out: &mut Lanes) {
    let at = |[dx, dy]: [i32; 2]| -> &Lanes {
        let row = rows[(dy + 3) as usize];
        (&row[(x as i32 + dx) as usize..][..LANES]).try_into().expect("LANES bytes")
    };
    let p = at([0, 0]);
    // The quick test of `may_be_corners` (two adjacent compass pixels beyond the threshold on the
    // same side), a necessary condition, side by side: a side no pixel passes it on has no arc
    // beyond the threshold, so its saturated maximum (at most the threshold) never decides a kept
    // score and is left at 0; segments where neither side passes are all 0.
    // (Four calls, not an array `map`, whose closure would be compiled outside the AVX2 code.)
    let (n, e, s, w) = (at(FAST_CIRCLE[0]), at(FAST_CIRCLE[4]), at(FAST_CIRCLE[8]), at(FAST_CIRCLE[12]));
    let (mut any_brighter, mut any_darker) = (0u8, 0u8);
    for i in 0..LANES {
        let b = |v: u8| (v.saturating_sub(p[i]) > threshold) as u8;
        let d = |v: u8| (p[i].saturating_sub(v) > threshold) as u8;
        let (bn, be, bs, bw) = (b(n[i]), b(e[i]), b(s[i]), b(w[i]));
        let (dn, de, ds, dw) = (d(n[i]), d(e[i]), d(s[i]), d(w[i]));
        any_brighter |= (bn & be) | (be & bs) | (bs & bw) | (bw & bn);
        any_darker |= (dn & de) | (de & ds) | (ds & dw) | (dw & dn);
    }
    if any_brighter | any_darker == 0 {
        *out = [0; LANES];
        return;
    }
    let b = if any_brighter != 0 { side_maximum::<true>(rows, x, p) } else { [0; LANES] };
    let d = if any_darker != 0 { side_maximum::<false>(rows, x, p) } else { [0; LANES] };
    for i in 0..LANES {
        let score = b[i].max(d[i]);
        out[i] = if score > threshold { score } else { 0 };
    }
}

/// Lane by lane, [`arc_maximum`] of the saturated differences of the circle pixels to the centre `p`:
/// circle minus centre (`BRIGHTER`) or centre minus circle.
#[inline(always)]
fn side_maximum<const BRIGHTER: bool>(rows: &[&[u8]; 7], x: usize, p: &Lanes) -> Lanes {
    let mut ring = [[0u8; LANES]; 16];
    for (differences, [dx, dy]) in ring.iter_mut().zip(FAST_CIRCLE) {
        let c: &Lanes = (&rows[(dy + 3) as usize][(x as i32 + dx) as usize..][..LANES])
            .try_into()
            .expect("LANES bytes");
        for i in 0..LANES {
            differences[i] = if BRIGHTER {
                c[i].saturating_sub(p[i])
            } else {
                p[i].saturating_sub(c[i])
            };
        }
    }
    arc_maximum(&ring)
}

/// Lane by lane, the largest over the 16 arcs of nine contiguous circle pixels of the smallest value
/// on the arc (indices modulo 16), by sliding minima as in `arc_score`.
#[inline(always)]
fn arc_maximum(ring: &[Lanes; 16]) -> Lanes {
    let (mut min2, mut min4) = ([[0u8; LANES]; 16], [[0u8; LANES]; 16]);
    for k in 0..16 {
        for i in 0..LANES {
            min2[k][i] = ring[k][i].min(ring[(k + 1) & 15][i]);
        }
    }
    for k in 0..16 {
        for i in 0..LANES {
            min4[k][i] = min2[k][i].min(min2[(k + 2) & 15][i]);
        }
    }
    let mut best = [0u8; LANES];
    for k in 0..16 {
        for i in 0..LANES {
            let min9 = min4[k][i].min(min4[(k + 4) & 15][i]).min(ring[(k + 8) & 15][i]);
            best[i] = best[i].max(min9);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kernels() -> Vec<RowKernel> {
        let mut kernels = vec![RowKernel::Portable];
        #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
        if std::arch::is_x86_feature_detected!("avx2") {
            kernels.push(RowKernel::Avx2);
        }
        kernels
    }

    #[test]
    fn every_kernel_suppresses_as_the_plain_rule() {
        // Sparse maps with runs of equal scores, rows of every width around the lane count.
        let mut rng = crate::synthetic::SplitMix64::new(23);
        for kernel in kernels() {
            for width in (1..3).chain(LANES - 2..LANES + 5).chain([3 * LANES + 7, 100]) {
                let rows: [Vec<u8>; 3] = std::array::from_fn(|_| {
                    (0..width)
                        .map(|_| match rng.below(6) {
                            0 => 5,
                            1 => 4 + rng.below(4) as u8,
                            _ => 0,
                        })
                        .collect()
                });
                let [above, here, below] = [&rows[0][..], &rows[1][..], &rows[2][..]];
                let mut got = Vec::new();
                let tail = kernel.suppress_row([above, here, below], &mut |x| got.push(x));
                let plain = |x: usize| {
                    let s = here[x];
                    let earlier = [above[x - 1], above[x], above[x + 1], here[x - 1]];
                    let later = [here[x + 1], below[x - 1], below[x], below[x + 1]];
                    s > 0 && earlier.iter().all(|&n| s > n) && later.iter().all(|&n| s >= n)
                };
                got.extend(tail.filter(|&x| plain(x)));
                let want: Vec<usize> = (1..width.saturating_sub(1)).filter(|&x| plain(x)).collect();
                assert_eq!(got, want, "{kernel:?} width {width}");
            }
        }
    }

    #[test]
    fn every_kernel_gives_the_reference_scores() {
        // Random strided images of a few grey levels (ties, saturation at 0 and 255) and of all 256,
        // every threshold class, segments of LANES pixels and longer (the overlapping last segment).
        let mut rng = crate::synthetic::SplitMix64::new(17);
        let kernels = kernels();
        for (w, h, stride) in [(38, 9, 38), (39, 12, 41), (70, 10, 70), (131, 16, 140)] {
            for (levels, threshold) in [(2u64, 1u8), (3, 40), (256, 1), (256, 20), (256, 254), (5, 100)] {
                let data: Vec<u8> = (0..stride * h)
                    .map(|_| (rng.below(levels) * 255 / (levels - 1)) as u8)
                    .collect();
                let img = GrayView::new(&data, w, h, stride).unwrap();
                for kernel in &kernels {
                    for y in 3..h - 3 {
                        let mut out = vec![7u8; w - 6];
                        kernel.score_row(&img, y, 3..w - 3, threshold, &mut out);
                        for (i, &got) in out.iter().enumerate() {
                            let s = super::super::cpu::fast_score(&img, 3 + i, y);
                            let want = if s > threshold as i32 { s as u8 } else { 0 };
                            assert_eq!(got, want, "{kernel:?} ({}, {y}) of {w}x{h}, t {threshold}", 3 + i);
                        }
                    }
                }
            }
        }
    }
}
