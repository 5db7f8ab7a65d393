//! Hostile files, generated here: lying headers, truncated JPEGs, FIFOs, bad palettes, 16-bit data.

use super::*;

/// A path `name` in a folder of its own, removed with the folder when the test ends.
struct TempPath {
    dir: PathBuf,
    path: PathBuf,
}

impl std::ops::Deref for TempPath {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for TempPath {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for TempPath {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

fn temp(name: &str) -> TempPath {
    let dir = std::env::temp_dir().join(format!("clatch-decode-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    TempPath {
        path: dir.join(name),
        dir,
    }
}

fn png_bytes(img: &DynamicImage) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png).unwrap();
    out.into_inner()
}

/// A real PNG whose IHDR is patched to say `width` x `height` (CRC fixed, so only the size lies).
fn lying_png(width: u32, height: u32) -> Vec<u8> {
    let mut png = png_bytes(&DynamicImage::ImageLuma8(GrayImage::new(4, 4)));
    png[16..20].copy_from_slice(&width.to_be_bytes());
    png[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

fn textured(width: u32, height: u32) -> GrayImage {
    GrayImage::from_fn(width, height, |x, y| {
        image::Luma([((x * 31 + y * 17 + (x * y) % 7) % 256) as u8])
    })
}

fn jpeg_bytes(img: &GrayImage) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
        .encode_image(img)
        .unwrap();
    out
}

#[test]
fn lying_png_header_is_refused_before_decoding() {
    let path = temp("lying.png");
    std::fs::write(&path, lying_png(200_000, 200_000)).unwrap();
    let e = open_gray(&path, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::TooLarge {
                width: 200_000,
                height: 200_000,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("lying.png"), "{e}");
    assert!(matches!(
        probe(&path, &DecodeLimits::default()),
        Err(DecodeError::TooLarge { .. })
    ));
}

#[test]
fn lying_ppm_and_jpeg_headers_are_refused() {
    let ppm = temp("lying.ppm");
    let mut data = b"P6\n4000000000 2\n255\n".to_vec();
    data.resize(320, 7);
    std::fs::write(&ppm, &data).unwrap();
    let e = open_gray(&ppm, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::TooLarge {
                width: 4_000_000_000,
                height: 2,
                ..
            }
        ),
        "{e}"
    );

    // A JPEG whose frame header is patched to 65500x65500.
    let mut jpeg = jpeg_bytes(&textured(64, 64));
    let sof = jpeg
        .windows(2)
        .position(|w| w == [0xFF, 0xC0])
        .expect("a baseline frame header");
    jpeg[sof + 5..sof + 7].copy_from_slice(&65500u16.to_be_bytes());
    jpeg[sof + 7..sof + 9].copy_from_slice(&65500u16.to_be_bytes());
    let path = temp("lying.jpg");
    std::fs::write(&path, &jpeg).unwrap();
    let e = open_gray(&path, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::TooLarge {
                width: 65500,
                height: 65500,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn the_pixel_limit_is_configurable() {
    let path = temp("medium.png");
    std::fs::write(
        &path,
        png_bytes(&DynamicImage::ImageLuma8(textured(300, 200))),
    )
    .unwrap();
    assert!(open_gray(&path, &DecodeLimits { max_pixels: 60_000 }).is_ok());
    let e = open_gray(&path, &DecodeLimits { max_pixels: 59_999 }).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::TooLarge {
                max_pixels: 59_999,
                ..
            }
        ),
        "{e}"
    );
    let info = probe(&path, &DecodeLimits::default()).unwrap();
    assert_eq!(
        (info.width, info.height, info.format),
        (300, 200, ImageFormat::Png)
    );
}

#[test]
fn truncated_jpegs_are_refused_and_whole_ones_read() {
    let img = textured(160, 120);
    let jpeg = jpeg_bytes(&img);
    let whole = temp("whole.jpg");
    std::fs::write(&whole, &jpeg).unwrap();
    let decoded = open_gray(&whole, &DecodeLimits::default()).unwrap();
    assert_eq!(decoded.dimensions(), (160, 120));
    for cut in [1000.min(jpeg.len() - 1), jpeg.len() / 2, jpeg.len() - 2] {
        let path = temp("cut.jpg");
        std::fs::write(&path, &jpeg[..cut]).unwrap();
        let e = open_gray(&path, &DecodeLimits::default()).unwrap_err();
        assert!(
            matches!(e, DecodeError::TruncatedJpeg { bytes, .. } if bytes == cut as u64),
            "cut at {cut}: {e}"
        );
        assert!(matches!(
            probe(&path, &DecodeLimits::default()),
            Err(DecodeError::TruncatedJpeg { .. })
        ));
    }
}

#[cfg(unix)]
#[test]
fn fifos_and_folders_are_refused_without_blocking() {
    let fifo = temp("pipe.png");
    std::fs::remove_file(&fifo).ok();
    let made = std::process::Command::new("mkfifo")
        .arg(&*fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let e = open_gray(&fifo, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(e, DecodeError::NotAFile { kind: "a FIFO", .. }),
        "{e}"
    );
    let dir = temp("folder.png");
    std::fs::create_dir_all(&dir).unwrap();
    let e = open_gray(&dir, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::NotAFile {
                kind: "a folder",
                ..
            }
        ),
        "{e}"
    );
    let e = open_gray(Path::new("/dev/zero"), &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::NotAFile {
                kind: "a device",
                ..
            }
        ),
        "{e}"
    );
}

#[path = "../../tests/common/palette_png.rs"]
mod palette_png_writer;

/// A 16x16 8-bit palette PNG with `entries` colours `(10 i, 0, 200)` whose pixels are the indices
/// `index(x, y)`.
fn palette_png(entries: usize, index: impl Fn(u32, u32) -> u8) -> Vec<u8> {
    let palette: Vec<[u8; 3]> = (0..entries).map(|i| [i as u8 * 10, 0, 200]).collect();
    palette_png_writer::palette_png(16, 16, &palette, index)
}

#[test]
fn palette_indices_past_the_palette_are_refused() {
    let good = temp("palette-good.png");
    std::fs::write(&good, palette_png(4, |x, _| (x % 4) as u8)).unwrap();
    let gray = open_gray(&good, &DecodeLimits::default()).unwrap();
    // Index 3 is (30, 0, 200): the same gray as through the image crate's own decoding.
    assert_eq!(gray.get_pixel(3, 0).0[0], super::super::luma(30, 0, 200));
    let plain = image::open(&good).unwrap();
    assert_eq!(gray, super::super::gray_from_dynamic(&plain));

    let bad = temp("palette-bad.png");
    std::fs::write(
        &bad,
        palette_png(4, |x, y| if (x, y) == (9, 9) { 200 } else { 1 }),
    )
    .unwrap();
    let e = open_gray(&bad, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(e, DecodeError::PaletteIndex { entries: 4, .. }),
        "{e}"
    );
}

#[test]
fn sixteen_bit_data_is_scaled_full_range() {
    // 12-bit data (0..4095) in a 16-bit PNG: the high byte alone would be 0..15.
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(64, 8, |x, _| {
        image::Luma([(x * 65) as u16])
    });
    let path = temp("twelve-bit.png");
    std::fs::write(&path, png_bytes(&DynamicImage::ImageLuma16(img))).unwrap();
    let gray = open_gray(&path, &DecodeLimits::default()).unwrap();
    assert_eq!(gray.get_pixel(0, 0).0[0], 0);
    assert_eq!(gray.get_pixel(63, 0).0[0], 255);
    // x = 32: (32 * 65) * 255 / (63 * 65) = 129.52, rounded to 130.
    assert_eq!(gray.get_pixel(32, 3).0[0], 130);
}

fn rgb_jpeg_bytes(width: u32, height: u32) -> Vec<u8> {
    let img = image::RgbImage::from_fn(width, height, |x, y| {
        image::Rgb([
            (x * 7 + y * 3) as u8,
            ((x ^ y) * 5) as u8,
            (x * y / 7) as u8,
        ])
    });
    let mut out = Cursor::new(Vec::new());
    DynamicImage::ImageRgb8(img)
        .write_to(&mut out, ImageFormat::Jpeg)
        .unwrap();
    out.into_inner()
}

/// The offset of the first SOF0 marker's height field.
fn sof_size_offset(jpeg: &[u8]) -> usize {
    jpeg.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap() + 5
}

#[test]
fn strict_jpeg_decoding_gives_the_image_crates_pixels_for_valid_files() {
    for bytes in [jpeg_bytes(&textured(97, 75)), rgb_jpeg_bytes(130, 66)] {
        let path = temp("valid.jpg");
        std::fs::write(&path, &bytes).unwrap();
        let ours = open_gray(&path, &DecodeLimits::default()).unwrap();
        let theirs = super::super::gray_from_dynamic(&image::load_from_memory(&bytes).unwrap());
        assert_eq!(ours, theirs);
    }
}

#[test]
fn corrupt_jpegs_that_end_with_their_marker_are_refused() {
    let whole = jpeg_bytes(&textured(320, 240));
    // Cut in the entropy-coded data and marked as ended.
    let mut cut = whole[..whole.len() * 2 / 5].to_vec();
    cut.extend_from_slice(&[0xFF, 0xD9]);
    // The header's size patched to 10000 x 10000 (the data holds 320 x 240).
    let mut patched = whole.clone();
    let at = sof_size_offset(&patched);
    patched[at..at + 4].copy_from_slice(&[0x27, 0x10, 0x27, 0x10]);
    for (name, bytes) in [("cut.jpg", cut), ("patched.jpg", patched)] {
        let path = temp(name);
        std::fs::write(&path, &bytes).unwrap();
        let e = open_gray(&path, &DecodeLimits::default()).unwrap_err();
        assert!(matches!(e, DecodeError::CorruptImage { .. }), "{name}: {e}");
        assert!(e.to_string().contains(name), "{e}");
    }
}

#[test]
fn pnm_samples_above_maxval_and_empty_files_are_refused() {
    let path = temp("hot.pgm");
    let mut pgm = b"P5\n64 64\n100\n".to_vec();
    pgm.resize(pgm.len() + 64 * 64, 50);
    std::fs::write(&path, &pgm).unwrap();
    // Scaled by MAXVAL: 50 of 100 is 128 of 255.
    assert_eq!(
        open_gray(&path, &DecodeLimits::default())
            .unwrap()
            .get_pixel(1, 1)
            .0[0],
        128
    );
    *pgm.last_mut().unwrap() = 200;
    std::fs::write(&path, &pgm).unwrap();
    let e = open_gray(&path, &DecodeLimits::default()).unwrap_err();
    assert!(e.to_string().contains("above the file's MAXVAL 100"), "{e}");
    // A bitmap's 0/1 samples are expanded by the decoder: accepted.
    let mut pbm = b"P4\n64 64\n".to_vec();
    pbm.resize(pbm.len() + 8 * 64, 0x0F);
    std::fs::write(&path, &pbm).unwrap();
    open_gray(&path, &DecodeLimits::default()).unwrap();
    std::fs::write(&path, b"").unwrap();
    let e = open_gray(&path, &DecodeLimits::default()).unwrap_err();
    assert!(matches!(e, DecodeError::EmptyFile { .. }), "{e}");
    assert!(e.to_string().contains("the file is empty"), "{e}");
}

/// A libjpeg file (OpenCV 5.0.0's `imwrite`: 4:2:0, a restart marker every 2 MCUs, 160 x 120).
const RESTART_420: &[u8] = include_bytes!("testdata/restart_420.jpg");

#[test]
fn libjpeg_files_with_restart_markers_pass_whole_and_fail_cut() {
    super::super::jpeg_scan::check_scans(RESTART_420).unwrap();
    let path = temp("restart.jpg");
    std::fs::write(&path, RESTART_420).unwrap();
    let ours = open_gray(&path, &DecodeLimits::default()).unwrap();
    let theirs = super::super::gray_from_dynamic(&image::load_from_memory(RESTART_420).unwrap());
    assert_eq!(ours, theirs);
    for keep in [RESTART_420.len() / 3, RESTART_420.len() * 3 / 4] {
        let mut cut = RESTART_420[..keep].to_vec();
        cut.extend_from_slice(&[0xFF, 0xD9]);
        let e = super::super::jpeg_scan::check_scans(&cut).unwrap_err();
        assert!(e.contains("of its 80 MCUs"), "{e}");
    }
}
