//! Rendering the planes of a scene into a camera: each pixel's ray meets the nearest plane, whose
//! texture is sampled bilinearly, 3 × 3 rays per pixel averaged (anti-aliasing); rays that meet no
//! plane see a smooth sky.

use image::RgbImage;

use crate::geometry::truth::{Plane, TrueCamera};

/// A plane of the scene with its texture: texture pixel `(i, j)` covers plane coordinates
/// `[i, i + 1) · metres_per_pixel × [j, j + 1) · metres_per_pixel`.
pub struct TexturedPlane<'a> {
    pub plane: Plane,
    pub texture: &'a RgbImage,
    pub metres_per_pixel: f64,
}

fn bilinear(texture: &RgbImage, x: f64, y: f64) -> [f64; 3] {
    // Texture pixel centres at integer + 0.5.
    let (x, y) = (x - 0.5, y - 0.5);
    let (w, h) = (texture.width() as i64, texture.height() as i64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |i: i64, j: i64| {
        let p = texture
            .get_pixel(i.clamp(0, w - 1) as u32, j.clamp(0, h - 1) as u32)
            .0;
        p.map(f64::from)
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let (a, b, c, d) = (
        at(x0, y0),
        at(x0 + 1, y0),
        at(x0, y0 + 1),
        at(x0 + 1, y0 + 1),
    );
    [0, 1, 2].map(|k| {
        (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
    })
}

/// The image `camera` sees of `planes`.
pub fn render(camera: &TrueCamera, planes: &[TexturedPlane]) -> RgbImage {
    const SAMPLES: u32 = 3;
    let from = camera.centre();
    let mut image = RgbImage::new(camera.width, camera.height);
    for (i, j, pixel) in image.enumerate_pixels_mut() {
        let mut sum = [0.0; 3];
        for sy in 0..SAMPLES {
            for sx in 0..SAMPLES {
                // COLMAP pixel coordinates: pixel (i, j) covers [i, i + 1) × [j, j + 1).
                let u = f64::from(i) + (f64::from(sx) + 0.5) / f64::from(SAMPLES);
                let v = f64::from(j) + (f64::from(sy) + 0.5) / f64::from(SAMPLES);
                let Some(direction) = camera.ray([u, v]) else {
                    continue;
                };
                let hit = planes
                    .iter()
                    .filter_map(|p| p.plane.intersect(from, direction).map(|(s, ab)| (s, ab, p)))
                    .min_by(|a, b| a.0.total_cmp(&b.0));
                let colour = match hit {
                    Some((_, [a, b], p)) => {
                        bilinear(p.texture, a / p.metres_per_pixel, b / p.metres_per_pixel)
                    }
                    None => {
                        // A pale sky, lighter towards the horizon.
                        let t = v / f64::from(camera.height);
                        [150.0 + 60.0 * t, 185.0 + 40.0 * t, 230.0 + 10.0 * t]
                    }
                };
                for k in 0..3 {
                    sum[k] += colour[k];
                }
            }
        }
        let n = f64::from(SAMPLES * SAMPLES);
        *pixel = image::Rgb(sum.map(|s| (s / n).round().clamp(0.0, 255.0) as u8));
    }
    image
}
