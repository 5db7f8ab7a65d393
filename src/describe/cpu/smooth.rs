//! Smoothing before description ([`Smoothing`]): the reference, `kernels/describe.cu`'s
//! `clatch_smooth_binomial*` reproduce it bit for bit.

use crate::describe::Smoothing;
use crate::gray_view::GrayView;
use crate::parallel::*;

/// `img` smoothed by `smoothing`, row-major with stride = width (for [`Smoothing::None`], a copy).
///
/// With the binomial taps `k` of [`Smoothing::taps`] (`2r + 1` of them, summing to `2^(2r)`), pixel
/// `(x, y)` of the result is
/// `(Σ_{i,j < 2r+1} k[i] k[j] I(clamp(x + j - r, 0, W - 1), clamp(y + i - r, 0, H - 1)) + 2^(4r - 1)) >> 4r`:
/// the exact sum (at most `2^(4r) · 255 < 2^16`), rounded once, half up. Past an edge the edge pixel
/// is repeated. Computed separably (column sums of `2r + 1` clamped rows, then row sums of `2r + 1`
/// clamped columns), which adds the same integers in another order.
pub fn smooth(img: &GrayView, smoothing: Smoothing) -> Vec<u8> {
    match smoothing {
        Smoothing::None => (0..img.height()).flat_map(|y| img.row(y)).copied().collect(),
        Smoothing::Binomial3 => separable(img, [1, 2, 1]),
        Smoothing::Binomial5 => separable(img, [1, 4, 6, 4, 1]),
    }
}

/// [`smooth`] with the `N = 2r + 1` taps `taps` (summing to `2^(2r)`), one output row per task.
fn separable<const N: usize>(img: &GrayView, taps: [u16; N]) -> Vec<u8> {
    let (w, h) = (img.width(), img.height());
    let r = N / 2;
    let shift = 2 * (N as u32 - 1);
    let half = 1u16 << (shift - 1);
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w).enumerate().for_each_init(
        || (vec![0u16; w + 2 * r], vec![0u16; w]),
        |(columns, sums), (y, line)| {
            // Column sums of rows clamp(y - r) ..= clamp(y + r): at most 2^(2r) · 255.
            let inner = &mut columns[r..r + w];
            inner.fill(0);
            for (i, &k) in taps.iter().enumerate() {
                let row = img.row((y + i).saturating_sub(r).min(h - 1));
                for (s, &p) in inner.iter_mut().zip(row) {
                    *s += k * p as u16;
                }
            }
            // Columns past the edges are the edge columns (clamped x).
            let (first, last) = (columns[r], columns[r + w - 1]);
            columns[..r].fill(first);
            columns[r + w..].fill(last);
            // Row sums of the column sums: sums[x] covers columns x - r ..= x + r, at most
            // 2^(4r) · 255 = 65280 for r = 2, so `+ half` (128) still fits 16 bits.
            sums.fill(0);
            for (j, &k) in taps.iter().enumerate() {
                for (s, &c) in sums.iter_mut().zip(&columns[j..j + w]) {
                    *s += k * c;
                }
            }
            for (o, &s) in line.iter_mut().zip(sums.iter()) {
                *o = ((s + half) >> shift) as u8;
            }
        },
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMOOTHINGS: [Smoothing; 2] = [Smoothing::Binomial3, Smoothing::Binomial5];

    fn view(pixels: &[u8], w: usize, h: usize) -> GrayView<'_> {
        GrayView::new(pixels, w, h, w).unwrap()
    }

    /// The formula of [`smooth`]'s documentation, pixel by pixel, as a 2-D sum.
    fn direct(img: &GrayView, smoothing: Smoothing, x: usize, y: usize) -> u8 {
        let k = smoothing.taps();
        let r = smoothing.radius() as i64;
        let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
        let mut sum = 0u64;
        for (i, &ki) in k.iter().enumerate() {
            for (j, &kj) in k.iter().enumerate() {
                let px = clamp(x as i64 + j as i64 - r, img.width());
                let py = clamp(y as i64 + i as i64 - r, img.height());
                sum += ki as u64 * kj as u64 * img.at(px, py) as u64;
            }
        }
        ((sum + (1 << (4 * r - 1))) >> (4 * r)) as u8
    }

    #[test]
    fn taps_are_binomial_and_sum_to_a_power_of_four() {
        assert_eq!(Smoothing::None.radius(), 0);
        assert_eq!(Smoothing::Binomial3.radius(), 1);
        assert_eq!(Smoothing::Binomial5.radius(), 2);
        for s in SMOOTHINGS {
            let sum: u32 = s.taps().iter().map(|&k| k as u32).sum();
            assert_eq!(sum, 1 << (2 * s.radius()), "{s:?}");
        }
    }

    #[test]
    fn none_is_a_copy_of_a_strided_view() {
        let pixels: Vec<u8> = (0..7 * 4).map(|i| (i * 9) as u8).collect();
        let img = GrayView::new(&pixels, 5, 4, 7).unwrap();
        let copy = smooth(&img, Smoothing::None);
        assert_eq!(copy.len(), 20);
        assert_eq!(&copy[5..10], &pixels[7..12]);
    }

    #[test]
    fn a_constant_image_stays_constant() {
        for s in SMOOTHINGS {
            for value in [0u8, 1, 127, 200, 255] {
                for (w, h) in [(1, 1), (1, 6), (6, 1), (2, 3), (9, 7), (40, 33)] {
                    let pixels = vec![value; w * h];
                    assert_eq!(
                        smooth(&view(&pixels, w, h), s),
                        pixels,
                        "{s:?} {value} {w}x{h}"
                    );
                }
            }
        }
    }

    #[test]
    fn an_impulse_gives_the_kernel() {
        // 255 at the centre of a 9x9 zero image: out = (255 k_i k_j + 2^(4r-1)) >> 4r. Binomial5:
        // 255 k / 256 rounds to k for every product k <= 36 (36: 9180 + 128 = 9308, >> 8 = 36).
        // Binomial3: 255 k / 16 rounds to 16 k (k = 1: 263 >> 4 = 16; k = 4: 1028 >> 4 = 64).
        let mut pixels = vec![0u8; 81];
        pixels[4 * 9 + 4] = 255;
        let img = view(&pixels, 9, 9);
        let b5: [[u8; 5]; 5] = [
            [1, 4, 6, 4, 1],
            [4, 16, 24, 16, 4],
            [6, 24, 36, 24, 6],
            [4, 16, 24, 16, 4],
            [1, 4, 6, 4, 1],
        ];
        let b3: [[u8; 3]; 3] = [[16, 32, 16], [32, 64, 32], [16, 32, 16]];
        for (s, r) in [(Smoothing::Binomial3, 1usize), (Smoothing::Binomial5, 2)] {
            let out = smooth(&img, s);
            for y in 0..9 {
                for x in 0..9 {
                    let (dx, dy) = (x as i64 - 4 + r as i64, y as i64 - 4 + r as i64);
                    let inside = (0..=2 * r as i64).contains(&dx) && (0..=2 * r as i64).contains(&dy);
                    let expected = match (inside, s) {
                        (false, _) => 0,
                        (true, Smoothing::Binomial3) => b3[dy as usize][dx as usize],
                        (true, _) => b5[dy as usize][dx as usize],
                    };
                    assert_eq!(out[y * 9 + x], expected, "{s:?} at ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn borders_repeat_the_edge_pixel() {
        // 255 in the top-left corner of a 4x4 zero image, [1 2 1]: at (0, 0) the taps at -1 and 0
        // both read the corner on each axis, weight (1 + 2)² = 9: (2295 + 8) >> 4 = 143. At (1, 0):
        // x weight 1 (tap -1), y weight 3: (765 + 8) >> 4 = 48; at (1, 1): 255 + 8 >> 4 = 16.
        let mut pixels = vec![0u8; 16];
        pixels[0] = 255;
        let out = smooth(&view(&pixels, 4, 4), Smoothing::Binomial3);
        assert_eq!(
            out,
            [
                143, 48, 0, 0, //
                48, 16, 0, 0, //
                0, 0, 0, 0, //
                0, 0, 0, 0,
            ]
        );
        // [1 4 6 4 1] at the corner: weight (1 + 4 + 6)² = 121 at (0, 0): (30855 + 128) >> 8 = 121;
        // (1, 0): x taps -2 and -1 read it (1 + 4), y 11: 55 · 255 = 14025, + 128 >> 8 = 55.
        let out = smooth(&view(&pixels, 4, 4), Smoothing::Binomial5);
        assert_eq!(&out[..3], &[121, 55, 11]);
    }

    #[test]
    fn a_ramp_keeps_its_interior_and_rounds_half_up_at_the_edges() {
        // Columns 0, 10, ..., 50 on every row: a symmetric kernel keeps a linear ramp exactly inside;
        // at x = 0 [1 2 1] reads 0, 0, 10: 10 / 4 = 2.5 -> 3; at x = 5: 40, 50, 50 -> 47.5 -> 48.
        let pixels: Vec<u8> = (0..6 * 3).map(|i| (10 * (i % 6)) as u8).collect();
        let out = smooth(&view(&pixels, 6, 3), Smoothing::Binomial3);
        for row in out.chunks(6) {
            assert_eq!(row, [3, 10, 20, 30, 40, 48]);
        }
        // [1 4 6 4 1] at x = 0: 0 (11) + 10·4 + 20 = 60 / 16 = 3.75 -> 4; at x = 1: 10·6 + 20·4 + 30
        // = 170 / 16 = 10.625 -> 11.
        let out = smooth(&view(&pixels, 6, 3), Smoothing::Binomial5);
        assert_eq!(&out[..6], [4, 11, 20, 30, 39, 46]);
    }

    #[test]
    fn equals_the_two_dimensional_formula_on_random_strided_images() {
        let mut rng = crate::synthetic::SplitMix64::new(21);
        for (w, h) in [(1, 1), (2, 2), (1, 17), (13, 1), (3, 5), (37, 29), (120, 64)] {
            let stride = w + 3;
            let pixels: Vec<u8> = (0..stride * h).map(|_| rng.next_u64() as u8).collect();
            let img = GrayView::new(&pixels, w, h, stride).unwrap();
            for s in SMOOTHINGS {
                let out = smooth(&img, s);
                for y in 0..h {
                    for x in 0..w {
                        assert_eq!(out[y * w + x], direct(&img, s, x, y), "{s:?} {w}x{h} ({x}, {y})");
                    }
                }
            }
        }
    }
}
