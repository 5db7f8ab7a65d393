//! Reading input images as 8-bit gray, with errors that name the file: the size is checked from the
//! header against `--max-pixels` before decoding ([`clatch::decode::open_gray`]).

use std::path::Path;

use clatch::WINDOW;
use clatch::decode::DecodeLimits;
use image::GrayImage;

use crate::error::CliError;

/// Decodes any image the `image` crate reads here (PNG, JPEG, PGM/PPM/PBM/PAM) within `limits`,
/// converts it to gray with [`clatch::decode::gray_from_dynamic`] and checks that it holds one
/// descriptor window.
pub fn load_gray(path: &Path, limits: &DecodeLimits) -> Result<GrayImage, CliError> {
    let gray = clatch::decode::open_gray(path, limits)?;
    check_size(&gray).map_err(CliError::in_image(path))?;
    Ok(gray)
}

/// Refuses an image in which the detector cannot score a single pixel
/// ([`clatch::colmap::check_detectable`], the rule `clatch colmap` applies to a folder).
pub fn check_detectable(path: &Path, width: u32, height: u32) -> Result<(), CliError> {
    Ok(clatch::colmap::check_detectable(path, width, height)?)
}

/// Warns on stderr when `path` gave no keypoint, saying why: the image is too small for keypoints
/// whose windows must fit inside it (the margin of `config`'s keypoint size), or no corner passes
/// the threshold.
pub fn warn_if_no_keypoints(
    path: &Path,
    (width, height): (u32, u32),
    keypoints: usize,
    config: &clatch::ExtractorConfig,
) {
    if keypoints > 0 {
        return;
    }
    let detector = &config.detector;
    let margin = detector.margin();
    let min = 2 * margin + 1;
    let path = path.display();
    if (width.min(height) as usize) < min {
        eprintln!(
            "clatch: warning: {path}: no keypoints: it is {width}x{height}, and keypoints are detected \
             at least {margin} pixels from every border (their {}-pixel windows must fit, rotated), \
             so a side needs {min} pixels; use a smaller --keypoint-size (--single-scale uses 64)",
            detector.keypoint_size
        );
    } else {
        eprintln!(
            "clatch: warning: {path}: no keypoints: no corner passes --threshold {}",
            detector.threshold
        );
    }
}

/// The library's error for an image that cannot hold one 64x64 descriptor window (or that is larger
/// than supported).
pub fn check_size(img: &GrayImage) -> Result<(), clatch::Error> {
    let (width, height) = (img.width() as usize, img.height() as usize);
    if width < WINDOW || height < WINDOW {
        return Err(clatch::Error::ImageTooSmall {
            width,
            height,
            min: WINDOW,
        });
    }
    clatch::GrayView::try_from(img).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> DecodeLimits {
        DecodeLimits::default()
    }

    fn temp_path(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("clatch-input-test-{}-{name}", std::process::id()))
    }

    #[test]
    fn missing_file_is_a_read_error() {
        let e = load_gray(Path::new("/nonexistent/clatch/none.png"), &limits()).unwrap_err();
        assert!(
            matches!(e, CliError::Decode(clatch::decode::DecodeError::Io { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("none.png"));
    }

    #[test]
    fn garbage_is_a_decode_error() {
        let path = temp_path("garbage.png");
        std::fs::write(&path, b"this is not an image at all").unwrap();
        let e = load_gray(&path, &limits()).unwrap_err();
        std::fs::remove_file(&path).ok();
        assert!(matches!(e, CliError::Decode(_)), "{e}");
    }

    #[test]
    fn small_image_is_refused_and_pgm_is_read() {
        let path = temp_path("small.pgm");
        let mut pgm = b"P5\n32 32\n255\n".to_vec();
        pgm.resize(pgm.len() + 32 * 32, 77);
        std::fs::write(&path, &pgm).unwrap();
        let e = load_gray(&path, &limits()).unwrap_err();
        assert!(
            matches!(
                e,
                CliError::ClatchImage {
                    source: clatch::Error::ImageTooSmall { .. },
                    ..
                }
            ),
            "{e}"
        );

        let mut pgm = b"P5\n64 70\n255\n".to_vec();
        pgm.resize(pgm.len() + 64 * 70, 77);
        std::fs::write(&path, &pgm).unwrap();
        let img = load_gray(&path, &limits()).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(img.dimensions(), (64, 70));
        assert_eq!(img.get_pixel(5, 5).0[0], 77);
    }
}
