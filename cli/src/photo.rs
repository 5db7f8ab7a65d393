//! The photo carried in the binary and the demo's known second view of it; the evaluation harness
//! warps the same photo (its `astronaut` pairs, among them the demo's view as `persp demo`).

use clatch::homography::Homography;
use image::GrayImage;

/// `assets/astronaut.png`: 512x512 gray.
pub const ASTRONAUT_PNG: &[u8] = include_bytes!("../../assets/astronaut.png");

/// Where the embedded photo comes from.
pub const SOURCE: &str = "photo of NASA astronaut Eileen Collins, NASA Great Images database, \
                          public domain (scikit-image's `astronaut`)";

/// Decodes the embedded photo (an error only in a broken build).
pub fn embedded_photo() -> Result<GrayImage, image::ImageError> {
    let decoded = image::load_from_memory_with_format(ASTRONAUT_PNG, image::ImageFormat::Png)?;
    Ok(clatch::decode::gray_from_dynamic(&decoded))
}

/// The demo's fixed second view of a `width` x `height` image: rotation by 30 degrees and scaling by
/// 0.9 about the centre, with a slight perspective tilt; the centre stays put.
pub fn demo_homography(width: usize, height: usize) -> Homography {
    // Perspective in centred coordinates: w varies by about ±5 % across a 512-pixel image.
    let tilt = Homography::perspective(1.2e-4, -0.8e-4);
    tilt.after(&Homography::rotation_scale(30.0, 0.9))
        .about_centre(width, height)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_photo_decodes() {
        let img = embedded_photo().unwrap();
        assert_eq!(img.dimensions(), (512, 512));
    }

    #[test]
    fn the_demo_view_keeps_the_centre_and_rotates() {
        let h = demo_homography(512, 512);
        let close =
            |(x, y): (f64, f64), (u, v): (f64, f64)| (x - u).abs() < 1e-9 && (y - v).abs() < 1e-9;
        assert!(close(h.apply(255.5, 255.5).unwrap(), (255.5, 255.5)));
        // A step to the right turns by about 30 degrees and shrinks by about 0.9.
        let (u, v) = h.apply(265.5, 255.5).unwrap();
        let (dx, dy) = (u - 255.5, v - 255.5);
        assert!((dy.atan2(dx).to_degrees() - 30.0).abs() < 1.0);
        assert!((dx.hypot(dy) - 9.0).abs() < 0.1);
    }
}
