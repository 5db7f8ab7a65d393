//! The first pass of [`super::cpu::downscale`]: a source row interpolated along `x` at every output
//! column, `p[low] (256 - fx) + p[high] fx` (at most `255 · 256`: exact in `u16`).
//!
//! The columns' taps are the same for every row, so they are turned once per level into blocks of 8
//! output columns whose pixels all lie within 16 bytes of the block's first `low` (8 outputs
//! advance at most `7 · 2 + 1` source pixels for a factor of at most 2): with AVX2 (detected at run
//! time) one 16-byte load per block and two byte shuffles bring each output's `p[low]` and `p[high]`
//! into 16-bit lanes, and two 16-bit multiplies and an add give the sums, exact because no product
//! or sum exceeds `255 · 256 < 2^16`. Blocks that would read past the row's end, and every block
//! without AVX2, are computed one output at a time, the same integers.

use super::cpu::Tap;

/// Output columns per block.
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
const BLOCK: usize = 8;

/// One block's bytes: where it reads and, per output, the shuffle indices and weights.
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
#[derive(Clone, Copy, Debug)]
struct Block {
    /// The first output's `low`: the block reads the 16 bytes from here.
    base: usize,
    /// Shuffle control: `p[low]` of output `i` into 16-bit lane `i` (byte `2i` from byte
    /// `low - base`, byte `2i + 1` zeroed by the control's high bit).
    low: [i8; 2 * BLOCK],
    /// The same for `p[high]`.
    high: [i8; 2 * BLOCK],
    /// `256 - fx` and `fx` per output.
    weights: [[u16; BLOCK]; 2],
}

/// The taps of one level, in blocks where the CPU runs AVX2 (see the module).
pub(super) struct ColumnPlan<'a> {
    taps: &'a [Tap],
    /// Blocks `0..blocks.len()` cover outputs `0..BLOCK · blocks.len()` (all reading inside the row);
    /// the outputs after them are computed one by one. Empty without AVX2.
    #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
    blocks: Vec<Block>,
}

impl<'a> ColumnPlan<'a> {
    /// The plan of `taps` over rows of `source` pixels.
    #[cfg_attr(not(all(target_arch = "x86_64", feature = "cpu")), allow(unused_variables))]
    pub(super) fn new(taps: &'a [Tap], source: usize) -> Self {
        Self {
            taps,
            #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
            blocks: if std::arch::is_x86_feature_detected!("avx2") {
                blocks(taps, source)
            } else {
                Vec::new()
            },
        }
    }

    /// `line[X] = pixels[low] (256 - fx) + pixels[high] fx` for every output column `X`.
    pub(super) fn interpolate(&self, pixels: &[u8], line: &mut [u16]) {
        #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
        let done = {
            // SAFETY: blocks are made only when the CPU reports AVX2 (`new`).
            unsafe { x86::blocks(&self.blocks, pixels, line) };
            BLOCK * self.blocks.len()
        };
        #[cfg(not(all(target_arch = "x86_64", feature = "cpu")))]
        let done = 0;
        for (value, tap) in line[done..].iter_mut().zip(&self.taps[done..]) {
            let fx = tap.weight as u32;
            *value = (pixels[tap.low] as u32 * (256 - fx) + pixels[tap.high] as u32 * fx) as u16;
        }
    }
}

/// The blocks of `taps` over rows of `source` pixels, as long as they read inside the row.
#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
fn blocks(taps: &[Tap], source: usize) -> Vec<Block> {
    let mut blocks = Vec::with_capacity(taps.len() / BLOCK);
    for chunk in taps.chunks_exact(BLOCK) {
        let base = chunk[0].low;
        // Taps are monotone: the last output's `high` is the block's farthest byte.
        let span = chunk[BLOCK - 1].high - base;
        if span >= 16 || base + 16 > source {
            break;
        }
        let mut block = Block {
            base,
            low: [-128; 2 * BLOCK],
            high: [-128; 2 * BLOCK],
            weights: [[0; BLOCK]; 2],
        };
        for (i, tap) in chunk.iter().enumerate() {
            block.low[2 * i] = (tap.low - base) as i8;
            block.high[2 * i] = (tap.high - base) as i8;
            block.weights[0][i] = (256 - tap.weight) as u16;
            block.weights[1][i] = tap.weight as u16;
        }
        blocks.push(block);
    }
    blocks
}

#[cfg(all(target_arch = "x86_64", feature = "cpu"))]
mod x86 {
    use std::arch::x86_64::*;

    use super::{BLOCK, Block};

    /// The outputs of `blocks` (the first `BLOCK · blocks.len()` of `line`).
    ///
    /// # Safety
    /// AVX2 must be present. The loads are bounds-checked slices (each block's 16 bytes lie inside
    /// `pixels` by [`super::ColumnPlan::new`], and `get` checks it again).
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn blocks(blocks: &[Block], pixels: &[u8], line: &mut [u16]) {
        for (block, out) in blocks.iter().zip(line.chunks_exact_mut(BLOCK)) {
            let bytes: &[u8; 16] = pixels
                .get(block.base..block.base + 16)
                .and_then(|b| b.try_into().ok())
                .expect("the block lies inside the row");
            let out: &mut [u16; BLOCK] = out.try_into().expect("BLOCK outputs");
            // SAFETY: AVX2 (and so SSSE3) is present (the caller's contract); every pointer is that
            // of a reference to exactly 16 bytes.
            unsafe {
                let v = _mm_loadu_si128(bytes.as_ptr() as *const __m128i);
                let low = _mm_shuffle_epi8(v, _mm_loadu_si128(block.low.as_ptr() as *const __m128i));
                let high = _mm_shuffle_epi8(v, _mm_loadu_si128(block.high.as_ptr() as *const __m128i));
                let w0 = _mm_loadu_si128(block.weights[0].as_ptr() as *const __m128i);
                let w1 = _mm_loadu_si128(block.weights[1].as_ptr() as *const __m128i);
                let sum = _mm_add_epi16(_mm_mullo_epi16(low, w0), _mm_mullo_epi16(high, w1));
                _mm_storeu_si128(out.as_mut_ptr() as *mut __m128i, sum);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pyramid::downscaled;

    #[test]
    fn blocks_equal_the_taps_one_by_one() {
        // Every factor class (just above 1, 1.2, 1.5, just below 2, 2), widths around the block size.
        let mut rng = crate::synthetic::SplitMix64::new(31);
        for step in [65_537i64, 78_643, 98_304, 131_071, 131_072] {
            for source in (2..40).chain([97, 255, 1000]) {
                let w = downscaled(source, step);
                let taps = crate::pyramid::cpu::taps(w, source, step);
                let pixels: Vec<u8> = (0..source).map(|_| rng.next_u64() as u8).collect();
                let plan = ColumnPlan::new(&taps, source);
                let mut line = vec![0u16; w];
                plan.interpolate(&pixels, &mut line);
                for (x, (tap, &got)) in taps.iter().zip(&line).enumerate() {
                    let fx = tap.weight as u32;
                    let want = pixels[tap.low] as u32 * (256 - fx) + pixels[tap.high] as u32 * fx;
                    assert_eq!(got as u32, want, "step {step} source {source} x {x}");
                }
                #[cfg(all(target_arch = "x86_64", feature = "cpu"))]
                if source >= 40 && std::arch::is_x86_feature_detected!("avx2") {
                    assert!(!plan.blocks.is_empty(), "step {step} source {source}");
                }
            }
        }
    }
}
