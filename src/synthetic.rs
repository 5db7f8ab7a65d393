//! Deterministic synthetic images for tests, benches and examples (no files, no randomness crate).
//!
//! ```
//! let pixels = clatch::synthetic::rectangles(320, 240, 7)?;
//! let image = clatch::GrayView::new(&pixels, 320, 240, 320)?;
//! assert!(clatch::synthetic::noise(40_000, 1, 0).is_err()); // wider than clatch::MAX_IMAGE_SIDE
//! # Ok::<(), clatch::Error>(())
//! ```

use crate::error::Result;
use crate::gray_view::check_max_side;

/// A small, fast, reproducible generator (SplitMix64).
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A number in `0..n`; 0 when `n` is 0.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64().checked_rem(n).unwrap_or(0)
    }
}

/// Uniform random pixels, row-major `width * height`. Sides above [`crate::MAX_IMAGE_SIDE`] are
/// [`Error::ImageTooLarge`](crate::Error::ImageTooLarge).
pub fn noise(width: usize, height: usize, seed: u64) -> Result<Vec<u8>> {
    check_max_side(width, height)?;
    let mut rng = SplitMix64::new(seed);
    Ok((0..width * height).map(|_| rng.next_u64() as u8).collect())
}

/// Overlapping axis-aligned rectangles of random gray levels on a mid-gray background, with a little
/// noise: many FAST corners of varied strength, and textured enough for descriptors to differ. Sides
/// above [`crate::MAX_IMAGE_SIDE`] are [`Error::ImageTooLarge`](crate::Error::ImageTooLarge).
pub fn rectangles(width: usize, height: usize, seed: u64) -> Result<Vec<u8>> {
    check_max_side(width, height)?;
    let mut rng = SplitMix64::new(seed);
    let mut img = vec![128u8; width * height];
    let count = (width * height / 900).max(4);
    for _ in 0..count {
        let w = 4 + rng.below((width / 6).max(1) as u64) as usize;
        let h = 4 + rng.below((height / 6).max(1) as u64) as usize;
        let x0 = rng.below(width as u64) as usize;
        let y0 = rng.below(height as u64) as usize;
        let level = rng.next_u64() as u8;
        for y in y0..(y0 + h).min(height) {
            img[y * width + x0..y * width + (x0 + w).min(width)].fill(level);
        }
    }
    for p in img.iter_mut() {
        *p = p
            .saturating_add((rng.next_u64() % 5) as u8)
            .saturating_sub(2);
    }
    Ok(img)
}
