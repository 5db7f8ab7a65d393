//! Opening image files with their size checked from the header before anything large is allocated.

use std::fs::File;
use std::io::{BufRead, BufReader, Cursor, Read, Seek};
use std::path::{Path, PathBuf};

use image::{DynamicImage, GrayImage, ImageDecoder, ImageFormat, ImageReader};
use thiserror::Error;

use super::jpeg_end::{JpegEnd, find_end};
use super::palette;
use crate::gray_view::MAX_IMAGE_SIDE;
use crate::output::file_kind;

/// How large an image file may be decoded.
///
/// The size is read from the file's header and checked before any pixel buffer is allocated; the
/// decoder's own allocations are capped at [`DecodeLimits::max_alloc`].
///
/// `#[non_exhaustive]`, so that limits can be added: start from [`DecodeLimits::default`].
///
/// ```
/// use clatch::decode::DecodeLimits;
///
/// let limits = DecodeLimits::default().with_max_pixels(50_000_000);
/// assert_eq!(limits.max_alloc(), 400_000_000);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct DecodeLimits {
    /// Most pixels (width × height) an image may have. Default [`DecodeLimits::DEFAULT_MAX_PIXELS`].
    /// Each side is also capped at [`crate::MAX_IMAGE_SIDE`], the most clatch can process.
    pub max_pixels: u64,
}

impl DecodeLimits {
    /// 100 megapixels: a 12 000 × 8 000 photo; its decoded RGB takes 300 MB.
    pub const DEFAULT_MAX_PIXELS: u64 = 100_000_000;

    with_methods! {
        /// The same limits with at most this many pixels an image ([`DecodeLimits::max_pixels`]).
        with_max_pixels => max_pixels: u64;
    }

    /// Bytes the decoder may allocate: 8 per pixel, the largest decoded pixel (16-bit RGBA).
    pub fn max_alloc(&self) -> u64 {
        self.max_pixels.saturating_mul(8)
    }
}

impl Default for DecodeLimits {
    fn default() -> Self {
        Self {
            max_pixels: Self::DEFAULT_MAX_PIXELS,
        }
    }
}

/// Why an image file was not decoded. Every variant names the file.
// Field names are described by each variant's message.
#[allow(missing_docs)]
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The path is a folder, a FIFO, a device or a socket: reading it could block or never end.
    #[error("{path}: not a regular file ({kind}); images are read from regular files only", path = .path.display())]
    NotAFile { path: PathBuf, kind: &'static str },

    /// The file could not be opened or read.
    #[error("cannot read {path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },

    /// The header declares more pixels, or a longer side, than allowed.
    #[error(
        "{path}: the header says {width}x{height} ({pixels} pixels), more than allowed \
         ({max_pixels} pixels, sides up to {max_side})",
        path = .path.display(), pixels = u64::from(*.width) * u64::from(*.height)
    )]
    TooLarge {
        path: PathBuf,
        width: u32,
        height: u32,
        max_pixels: u64,
        max_side: u32,
    },

    /// A palette PNG file larger than the decoder may allocate (it is read whole to check its indices).
    #[error("{path}: {bytes} bytes is more than the {max} a palette image of the allowed size may take", path = .path.display())]
    FileTooLarge { path: PathBuf, bytes: u64, max: u64 },

    /// A JPEG file that stops before its end-of-image marker.
    #[error("{path}: the JPEG data is truncated (the file ends after {bytes} bytes, before the end-of-image marker)", path = .path.display())]
    TruncatedJpeg { path: PathBuf, bytes: u64 },

    /// A palette PNG with pixels whose index is past the end of its palette.
    #[error("{path}: palette PNG with pixels whose colour index is past the end of its {entries}-colour palette", path = .path.display())]
    PaletteIndex { path: PathBuf, entries: usize },

    /// The file is corrupt although its decoder could have filled the gaps: a JPEG whose entropy-coded
    /// data stops early or holds a marker where none belongs (what `djpeg` reports as corrupt), a
    /// PNM sample above the file's MAXVAL.
    #[error("{path}: corrupt image: {reason}", path = .path.display())]
    CorruptImage { path: PathBuf, reason: String },

    /// The file is empty.
    #[error("{path}: the file is empty, not an image", path = .path.display())]
    EmptyFile { path: PathBuf },

    /// The decoder refused the file (unknown format, corrupt or truncated data, ...).
    #[error("cannot decode image {path}: {source}", path = .path.display())]
    Image {
        path: PathBuf,
        source: image::ImageError,
    },
}

/// A gray image and the raw EXIF block of its file, when it has one.
type GrayWithExif = (GrayImage, Option<Vec<u8>>);

/// What a file's header says, checked against the limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct ImageInfo {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The format, from the file's content (not its name).
    pub format: ImageFormat,
}

/// Reads `path`'s header: its size (checked against `limits`) and format, without decoding pixels.
/// JPEG files are also followed to their end marker, so a truncated one is refused here.
pub fn probe(path: &Path, limits: &DecodeLimits) -> Result<ImageInfo, DecodeError> {
    let mut reader = reader(path)?;
    let format = format_of(&reader, path)?;
    // A PNG's metadata (iCCP, zTXt) is inflated while its header is read: capped already.
    reader.limits(image_limits(path, limits)?);
    let decoder = reader.into_decoder().map_err(image_error(path))?;
    let (width, height) = decoder.dimensions();
    check_size(path, width, height, limits)?;
    if format == ImageFormat::Jpeg {
        check_jpeg_end(path)?;
    }
    Ok(ImageInfo {
        width,
        height,
        format,
    })
}

/// Decodes `path` (PNG, JPEG or PNM, by content) to 8-bit gray with [`super::gray_from_dynamic`].
///
/// Before decoding: the path must be a regular file, the header's size within `limits`, a JPEG
/// complete to its end marker. A palette PNG with indices past its palette is refused.
///
/// ```
/// use clatch::decode::{DecodeError, DecodeLimits, open_gray};
///
/// let path = std::env::temp_dir().join(format!("clatch-doc-open-{}.png", std::process::id()));
/// image::GrayImage::from_pixel(120, 100, image::Luma([9])).save(&path)?;
/// let gray = open_gray(&path, &DecodeLimits::default())?;
/// assert_eq!(gray.dimensions(), (120, 100));
/// let small = DecodeLimits::default().with_max_pixels(10_000);
/// assert!(matches!(open_gray(&path, &small), Err(DecodeError::TooLarge { .. })));
/// # std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn open_gray(path: &Path, limits: &DecodeLimits) -> Result<GrayImage, DecodeError> {
    open_gray_with_exif(path, limits).map(|(gray, _)| gray)
}

/// [`open_gray`], with the file's raw EXIF block when it has a readable one.
pub fn open_gray_with_exif(
    path: &Path,
    limits: &DecodeLimits,
) -> Result<(GrayImage, Option<Vec<u8>>), DecodeError> {
    let reader = reader(path)?;
    match format_of(&reader, path)? {
        ImageFormat::Jpeg => {
            check_jpeg_end(path)?;
            let (img, exif) = decode_jpeg_strictly(path, limits)?;
            return Ok((super::gray_from_dynamic(&img), exif));
        }
        ImageFormat::Png => {
            if let Some(decoded) = open_palette_png(path, limits)? {
                return Ok(decoded);
            }
        }
        _ => {}
    }
    if reader.format() == Some(ImageFormat::Pnm) {
        check_pnm_samples(path)?;
    }
    let (img, exif) = decode(reader, path, limits)?;
    Ok((super::gray_from_dynamic(&img), exif))
}

/// Decodes a JPEG with the `image` crate's decoder (zune-jpeg) and its options, but in strict mode:
/// entropy-coded data that ends early, or a marker inside it, is [`DecodeError::CorruptImage`]
/// instead of gray fill. Valid files decode to the same pixels as `image` gives.
fn decode_jpeg_strictly(
    path: &Path,
    limits: &DecodeLimits,
) -> Result<(DynamicImage, Option<Vec<u8>>), DecodeError> {
    use zune_jpeg::zune_core::bytestream::ZCursor;
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;

    check_file_len(path, limits)?;
    let bytes = std::fs::read(path).map_err(io_error(path))?;
    let corrupt = |e: zune_jpeg::errors::DecodeErrors| DecodeError::CorruptImage {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(&bytes[..]), options);
    decoder.decode_headers().map_err(corrupt)?;
    let (width, height) = decoder.dimensions().unwrap_or_default();
    let (width, height) = (width as u32, height as u32);
    check_size(path, width, height, limits)?;
    super::jpeg_scan::check_scans(&bytes).map_err(|reason| DecodeError::CorruptImage {
        path: path.to_path_buf(),
        reason,
    })?;
    // The `image` crate's colour choice: these four as they are, anything else (CMYK, YCCK) to RGB.
    let out = match decoder.input_colorspace() {
        Some(c @ (ColorSpace::RGB | ColorSpace::RGBA | ColorSpace::Luma | ColorSpace::LumaA)) => c,
        _ => ColorSpace::RGB,
    };
    decoder.set_options(decoder.options().jpeg_set_out_colorspace(out));
    let exif = decoder.exif().cloned();
    let pixels = decoder.decode().map_err(corrupt)?;
    let wrong = || DecodeError::CorruptImage {
        path: path.to_path_buf(),
        reason: "the decoded pixels do not fill the header's size".into(),
    };
    let img = match out {
        ColorSpace::Luma => {
            DynamicImage::ImageLuma8(GrayImage::from_raw(width, height, pixels).ok_or_else(wrong)?)
        }
        ColorSpace::LumaA => DynamicImage::ImageLumaA8(
            image::GrayAlphaImage::from_raw(width, height, pixels).ok_or_else(wrong)?,
        ),
        ColorSpace::RGBA => DynamicImage::ImageRgba8(
            image::RgbaImage::from_raw(width, height, pixels).ok_or_else(wrong)?,
        ),
        _ => DynamicImage::ImageRgb8(
            image::RgbImage::from_raw(width, height, pixels).ok_or_else(wrong)?,
        ),
    };
    Ok((img, exif))
}

/// The path's metadata, refusing anything but a regular file (symbolic links are followed).
/// The file's length, refused when larger than the decoder may allocate (a file read whole first).
fn check_file_len(path: &Path, limits: &DecodeLimits) -> Result<u64, DecodeError> {
    let len = regular_file(path)?.len();
    if len > limits.max_alloc() {
        return Err(DecodeError::FileTooLarge {
            path: path.to_path_buf(),
            bytes: len,
            max: limits.max_alloc(),
        });
    }
    Ok(len)
}

fn regular_file(path: &Path) -> Result<std::fs::Metadata, DecodeError> {
    let meta = std::fs::metadata(path).map_err(io_error(path))?;
    if meta.is_file() {
        return Ok(meta);
    }
    Err(DecodeError::NotAFile {
        path: path.to_path_buf(),
        kind: file_kind(&meta),
    })
}

fn reader(path: &Path) -> Result<ImageReader<BufReader<File>>, DecodeError> {
    if regular_file(path)?.len() == 0 {
        return Err(DecodeError::EmptyFile {
            path: path.to_path_buf(),
        });
    }
    let file = File::open(path).map_err(io_error(path))?;
    ImageReader::new(BufReader::new(file))
        .with_guessed_format()
        .map_err(io_error(path))
}

fn format_of<R: BufRead + Seek>(
    reader: &ImageReader<R>,
    path: &Path,
) -> Result<ImageFormat, DecodeError> {
    reader.format().ok_or_else(|| DecodeError::Image {
        path: path.to_path_buf(),
        source: image::ImageError::Unsupported(
            image::error::UnsupportedError::from_format_and_kind(
                image::error::ImageFormatHint::Unknown,
                image::error::UnsupportedErrorKind::Format(image::error::ImageFormatHint::Unknown),
            ),
        ),
    })
}

fn check_size(
    path: &Path,
    width: u32,
    height: u32,
    limits: &DecodeLimits,
) -> Result<(), DecodeError> {
    let max_side = MAX_IMAGE_SIDE as u32;
    let pixels = u64::from(width) * u64::from(height);
    if pixels > limits.max_pixels || width > max_side || height > max_side {
        return Err(DecodeError::TooLarge {
            path: path.to_path_buf(),
            width,
            height,
            max_pixels: limits.max_pixels,
            max_side,
        });
    }
    Ok(())
}

fn check_jpeg_end(path: &Path) -> Result<(), DecodeError> {
    let file = File::open(path).map_err(io_error(path))?;
    match find_end(BufReader::new(file)).map_err(io_error(path))? {
        JpegEnd::Complete => Ok(()),
        JpegEnd::Truncated { bytes } => Err(DecodeError::TruncatedJpeg {
            path: path.to_path_buf(),
            bytes,
        }),
    }
}

/// Size check from the header, allocation limit, then the pixels and the EXIF block.
fn decode<R: BufRead + Seek>(
    mut reader: ImageReader<R>,
    path: &Path,
    limits: &DecodeLimits,
) -> Result<(DynamicImage, Option<Vec<u8>>), DecodeError> {
    reader.limits(image_limits(path, limits)?);
    let mut decoder = reader.into_decoder().map_err(image_error(path))?;
    let (width, height) = decoder.dimensions();
    check_size(path, width, height, limits)?;
    // EXIF is optional: a block that cannot be read is simply absent.
    let exif = decoder.exif_metadata().ok().flatten();
    let img = DynamicImage::from_decoder(decoder).map_err(image_error(path))?;
    Ok((img, exif))
}

/// A palette PNG that could hold indices past its palette: decoded with the sentinel palette and
/// checked. `None` for every other PNG.
fn open_palette_png(
    path: &Path,
    limits: &DecodeLimits,
) -> Result<Option<GrayWithExif>, DecodeError> {
    let mut start = [0u8; 33];
    let mut file = File::open(path).map_err(io_error(path))?;
    let read = read_up_to(&mut file, &mut start).map_err(io_error(path))?;
    let Some(header) = palette::Header::parse(&start[..read]) else {
        return Ok(None);
    };
    if header.colour_type != 3 {
        return Ok(None);
    }
    check_size(path, header.width, header.height, limits)?;
    // A palette file is at most a byte per pixel once inflated; a larger one is refused unread.
    let len = check_file_len(path, limits)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.rewind().map_err(io_error(path))?;
    file.read_to_end(&mut bytes).map_err(io_error(path))?;
    let Some(rewritten) = palette::with_sentinel(&bytes) else {
        return Ok(None);
    };
    drop(bytes);
    let reader = ImageReader::with_format(Cursor::new(rewritten.png), ImageFormat::Png);
    let (img, exif) = decode(reader, path, limits)?;
    let rgb = img.to_rgb8();
    if rgb.pixels().any(|p| p.0 == rewritten.sentinel) {
        return Err(DecodeError::PaletteIndex {
            path: path.to_path_buf(),
            entries: rewritten.entries,
        });
    }
    Ok(Some((super::gray_from_rgb(&rgb), exif)))
}

/// Metadata a PNG may inflate beyond its pixels (ICC profile, compressed text): real ICC profiles
/// are under 1 MiB; 16 MiB leaves room for any, never the hundreds of MiB of a decompression bomb.
pub const MAX_METADATA_BYTES: u64 = 16 << 20;

/// The `image` crate's limits for `path`: its allocations capped at [`DecodeLimits::max_alloc`], and
/// for a PNG at what its own size needs (8 bytes a pixel, from its IHDR) plus
/// [`MAX_METADATA_BYTES`], so that a small image cannot inflate a huge ICC profile or text chunk.
fn image_limits(path: &Path, limits: &DecodeLimits) -> Result<image::Limits, DecodeError> {
    let mut max_alloc = limits.max_alloc();
    let mut start = [0u8; 33];
    let mut file = File::open(path).map_err(io_error(path))?;
    let read = read_up_to(&mut file, &mut start).map_err(io_error(path))?;
    if let Some(header) = palette::Header::parse(&start[..read]) {
        let pixels = u64::from(header.width) * u64::from(header.height);
        max_alloc = max_alloc.min(pixels.saturating_mul(8).saturating_add(MAX_METADATA_BYTES));
    }
    let mut image_limits = image::Limits::default();
    image_limits.max_alloc = Some(max_alloc);
    Ok(image_limits)
}

/// Refuses a PNM file with a sample above its MAXVAL (the decoder scales samples by MAXVAL and
/// would pass a larger one on as a brighter value). Bitmaps, whose samples are bits, have none.
/// The samples are read as the file holds them, after its header: binary (one byte each up to
/// MAXVAL 255, two big-endian bytes above) or decimal text.
fn check_pnm_samples(path: &Path) -> Result<(), DecodeError> {
    use image::codecs::pnm::{PnmDecoder, PnmSubtype, SampleEncoding};
    let file = File::open(path).map_err(io_error(path))?;
    let decoder = PnmDecoder::new(BufReader::new(file)).map_err(image_error(path))?;
    let (mut rest, header) = decoder.into_inner();
    let maxval = header.maximal_sample();
    let encoding = match header.subtype() {
        PnmSubtype::Bitmap(_) => return Ok(()),
        PnmSubtype::Graymap(e) | PnmSubtype::Pixmap(e) => e,
        PnmSubtype::ArbitraryMap => SampleEncoding::Binary,
    };
    let mut data = Vec::new();
    rest.read_to_end(&mut data).map_err(io_error(path))?;
    let largest = match encoding {
        SampleEncoding::Binary if maxval > 255 => data
            .chunks_exact(2)
            .map(|c| u32::from(u16::from_be_bytes([c[0], c[1]])))
            .max(),
        SampleEncoding::Binary => data.iter().map(|&b| u32::from(b)).max(),
        SampleEncoding::Ascii => String::from_utf8_lossy(&data)
            .split_ascii_whitespace()
            .filter_map(|t| t.parse::<u32>().ok())
            .max(),
    };
    match largest {
        Some(v) if v > maxval => Err(DecodeError::CorruptImage {
            path: path.to_path_buf(),
            reason: format!("a sample is {v}, above the file's MAXVAL {maxval}"),
        }),
        _ => Ok(()),
    }
}

/// Reads until `buf` is full or the data ends; returns the bytes read.
fn read_up_to(reader: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> DecodeError + '_ {
    move |source| DecodeError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn image_error(path: &Path) -> impl FnOnce(image::ImageError) -> DecodeError + '_ {
    move |source| DecodeError::Image {
        path: path.to_path_buf(),
        source,
    }
}

#[cfg(test)]
#[path = "open_tests.rs"]
mod tests;
