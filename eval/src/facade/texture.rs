//! The facade's texture: one crop of a photo (a window, an arch) tiled `columns × rows` times with
//! bands of wall between the tiles, each tile a little different (its crop shifted by a few pixels,
//! its brightness, a grain of noise) under a gentle illumination gradient, so the repetition is as
//! exact as on a real building and no more.

use clatch::synthetic::SplitMix64;
use image::RgbImage;

/// How the tiles vary.
#[derive(Clone, Copy, Debug)]
pub struct TileVariation {
    /// Largest shift of a tile's crop in the photo, pixels (each axis).
    pub jitter_px: u32,
    /// Largest relative change of a tile's brightness.
    pub gain: f32,
    /// Standard deviation of the per-pixel grain, gray levels (uniform noise of that deviation).
    pub grain: f32,
    /// Width of the wall band between tiles, texture pixels.
    pub gap_px: u32,
}

/// A uniform number in `[-1, 1)`.
pub fn symmetric(rng: &mut SplitMix64) -> f32 {
    ((rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
}

/// The mean colour of the crop's outermost ring of pixels: the wall between the tiles.
fn wall_colour(photo: &RgbImage, (x, y, w, h): (u32, u32, u32, u32)) -> [f32; 3] {
    let mut sum = [0.0f64; 3];
    let mut n = 0.0;
    for j in y..y + h {
        for i in x..x + w {
            if i == x || j == y || i == x + w - 1 || j == y + h - 1 {
                let p = photo.get_pixel(i, j).0;
                for c in 0..3 {
                    sum[c] += f64::from(p[c]);
                }
                n += 1.0;
            }
        }
    }
    sum.map(|s| (s / n) as f32)
}

/// The texture of `columns × rows` tiles of the crop `(x, y, w, h)` of `photo`. The crop with its
/// jitter must lie inside the photo (checked by the caller).
pub fn tiled_facade(
    photo: &RgbImage,
    crop: (u32, u32, u32, u32),
    columns: u32,
    rows: u32,
    variation: TileVariation,
    rng: &mut SplitMix64,
) -> RgbImage {
    let (x0, y0, w, h) = crop;
    let gap = variation.gap_px;
    let (width, height) = (columns * (w + gap) + gap, rows * (h + gap) + gap);
    let wall = wall_colour(photo, crop);
    let mut texture = RgbImage::new(width, height);
    let shade = |x: u32, y: u32| {
        // Light falls from the upper left: 10 % brighter there than at the lower right.
        1.05 - 0.1 * (0.6 * x as f32 / width as f32 + 0.4 * y as f32 / height as f32)
    };
    let grain = |rng: &mut SplitMix64| symmetric(rng) * variation.grain * 3f32.sqrt();
    for y in 0..height {
        for x in 0..width {
            let s = shade(x, y);
            let value = wall.map(|c| c * s);
            let g = grain(rng);
            texture.put_pixel(
                x,
                y,
                image::Rgb(value.map(|v| (v + g).clamp(0.0, 255.0) as u8)),
            );
        }
    }
    let jitter = variation.jitter_px as i64;
    for row in 0..rows {
        for column in 0..columns {
            let dx = (symmetric(rng) * (jitter as f32 + 0.999)) as i64;
            let dy = (symmetric(rng) * (jitter as f32 + 0.999)) as i64;
            let gain = 1.0 + symmetric(rng) * variation.gain;
            let (tx, ty) = (gap + column * (w + gap), gap + row * (h + gap));
            for j in 0..h {
                for i in 0..w {
                    let sx = (i64::from(x0 + i) + dx) as u32;
                    let sy = (i64::from(y0 + j) + dy) as u32;
                    let p = photo.get_pixel(sx, sy).0;
                    let s = shade(tx + i, ty + j) * gain;
                    let g = grain(rng);
                    let value = p.map(|c| (f32::from(c) * s + g).clamp(0.0, 255.0) as u8);
                    texture.put_pixel(tx + i, ty + j, image::Rgb(value));
                }
            }
        }
    }
    texture
}
