//! Reading input images as 8-bit gray, with errors that name the file.

use std::io::BufReader;
use std::path::Path;

use clatch::WINDOW;
use image::{DynamicImage, GrayImage, ImageDecoder, ImageReader};

use crate::error::CliError;

/// Decodes any image the `image` crate reads here (PNG, JPEG, PGM/PPM/PBM/PAM), converts it to gray
/// with [`clatch::decode::gray_from_dynamic`] and checks that it holds one descriptor window.
pub fn load_gray(path: &Path) -> Result<GrayImage, CliError> {
    load_gray_with_exif(path).map(|(gray, _)| gray)
}

/// [`load_gray`], with the file's raw EXIF block when it has one.
pub fn load_gray_with_exif(path: &Path) -> Result<(GrayImage, Option<Vec<u8>>), CliError> {
    let read_err = |source| CliError::Read {
        path: path.to_path_buf(),
        source,
    };
    let decode_err = |source| CliError::Decode {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(read_err)?;
    let reader = ImageReader::new(BufReader::new(file))
        .with_guessed_format()
        .map_err(read_err)?;
    let mut decoder = reader.into_decoder().map_err(decode_err)?;
    // EXIF is optional: a block that cannot be read is simply absent.
    let exif = decoder.exif_metadata().ok().flatten();
    let decoded = DynamicImage::from_decoder(decoder).map_err(decode_err)?;
    let gray = clatch::decode::gray_from_dynamic(&decoded);
    check_size(&gray).map_err(CliError::in_image(path))?;
    Ok((gray, exif))
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

    fn temp_path(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("clatch-input-test-{}-{name}", std::process::id()))
    }

    #[test]
    fn missing_file_is_a_read_error() {
        let e = load_gray(Path::new("/nonexistent/clatch/none.png")).unwrap_err();
        assert!(matches!(e, CliError::Read { .. }), "{e}");
        assert!(e.to_string().contains("none.png"));
    }

    #[test]
    fn garbage_is_a_decode_error() {
        let path = temp_path("garbage.png");
        std::fs::write(&path, b"this is not an image at all").unwrap();
        let e = load_gray(&path).unwrap_err();
        std::fs::remove_file(&path).ok();
        assert!(matches!(e, CliError::Decode { .. }), "{e}");
    }

    #[test]
    fn small_image_is_refused_and_pgm_is_read() {
        let path = temp_path("small.pgm");
        let mut pgm = b"P5\n32 32\n255\n".to_vec();
        pgm.resize(pgm.len() + 32 * 32, 77);
        std::fs::write(&path, &pgm).unwrap();
        let e = load_gray(&path).unwrap_err();
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
        let img = load_gray(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(img.dimensions(), (64, 70));
        assert_eq!(img.get_pixel(5, 5).0[0], 77);
    }
}
