//! A generated corpus of malformed image files through the decoder the command-line tool uses
//! (`clatch::decode::open_gray`): truncated, bit-flipped and header-lying PNG (gray, RGB, palette,
//! 16-bit), JPEG and PNM files. Every file must give an image or a typed error: no panic, no abort
//! (an abort would end this test process), and the process's peak memory stays bounded although
//! headers claim up to 2^32 x 2^32 pixels.

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use clatch::decode::{DecodeLimits, open_gray};
use clatch::synthetic::SplitMix64;
use image::{DynamicImage, ImageFormat};

/// Valid files to start from, with their extension.
fn originals() -> Vec<(&'static str, Vec<u8>)> {
    let pixels = clatch::synthetic::rectangles(97, 83, 5).expect("synthetic image");
    let gray = image::GrayImage::from_raw(97, 83, pixels).expect("whole image");
    let rgb = DynamicImage::ImageLuma8(gray.clone()).to_rgb8();
    let wide = DynamicImage::ImageLuma8(gray.clone()).to_luma16();
    let encode = |img: DynamicImage, format| {
        let mut out = Cursor::new(Vec::new());
        img.write_to(&mut out, format).expect("encodes");
        out.into_inner()
    };
    let mut pgm = b"P5\n97 83\n255\n".to_vec();
    pgm.extend_from_slice(gray.as_raw());
    vec![
        (
            "png",
            encode(DynamicImage::ImageLuma8(gray.clone()), ImageFormat::Png),
        ),
        (
            "png",
            encode(DynamicImage::ImageRgb8(rgb.clone()), ImageFormat::Png),
        ),
        (
            "png",
            encode(DynamicImage::ImageLuma16(wide), ImageFormat::Png),
        ),
        ("png", palette_png(&gray)),
        (
            "jpg",
            encode(DynamicImage::ImageRgb8(rgb.clone()), ImageFormat::Jpeg),
        ),
        (
            "jpg",
            encode(DynamicImage::ImageLuma8(gray), ImageFormat::Jpeg),
        ),
        (
            "ppm",
            encode(DynamicImage::ImageRgb8(rgb), ImageFormat::Pnm),
        ),
        ("pgm", pgm),
    ]
}

#[path = "common/palette_png.rs"]
mod palette_png_writer;

/// An 8-bit palette PNG of `gray` with 16 gray entries (the top 4 bits of each pixel).
fn palette_png(gray: &image::GrayImage) -> Vec<u8> {
    let palette: Vec<[u8; 3]> = (0..16u8).map(|i| [i * 17; 3]).collect();
    palette_png_writer::palette_png(gray.width(), gray.height(), &palette, |x, y| {
        gray.get_pixel(x, y).0[0] >> 4
    })
}

/// The header lies about the size: PNG IHDR (CRC fixed, so only the size is wrong), JPEG SOF, PNM text.
fn lie_about_size(ext: &str, file: &[u8], w: u32, h: u32) -> Vec<u8> {
    let mut out = file.to_vec();
    match ext {
        "png" => {
            out[16..20].copy_from_slice(&w.to_be_bytes());
            out[20..24].copy_from_slice(&h.to_be_bytes());
            let crc = crc32fast::hash(&out[12..29]);
            out[29..33].copy_from_slice(&crc.to_be_bytes());
        }
        "jpg" => {
            // Baseline or progressive start of frame: FF C0 / FF C2, length, precision, height, width.
            if let Some(i) = out
                .windows(2)
                .position(|m| m[0] == 0xFF && (m[1] == 0xC0 || m[1] == 0xC2))
            {
                out[i + 5..i + 7].copy_from_slice(&(h.min(65_535) as u16).to_be_bytes());
                out[i + 7..i + 9].copy_from_slice(&(w.min(65_535) as u16).to_be_bytes());
            }
        }
        _ => {
            let text = String::from_utf8_lossy(&out[..2]).to_string();
            let body_start = out
                .iter()
                .enumerate()
                .filter(|(_, b)| **b == b'\n')
                .nth(2)
                .map_or(0, |(i, _)| i + 1);
            let mut lied = format!("{text}\n{w} {h}\n255\n").into_bytes();
            lied.extend_from_slice(&out[body_start..]);
            out = lied;
        }
    }
    out
}

/// Peak resident memory of this process, in bytes (Linux; `None` elsewhere).
fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[test]
fn malformed_files_give_an_image_or_a_typed_error() {
    let dir = std::env::temp_dir().join(format!("clatch-hostile-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // 4 megapixels: what the decoder may allocate for one image is bounded by it.
    let limits = DecodeLimits::default().with_max_pixels(4_000_000);
    let mut rng = SplitMix64::new(0xf11e5);
    let (mut decoded, mut refused, mut panics) = (0usize, 0usize, Vec::new());
    let mut run = |name: &str, ext: &str, bytes: &[u8], dir: &Path| {
        let path = dir.join(format!("case.{ext}"));
        std::fs::write(&path, bytes).unwrap();
        match catch_unwind(AssertUnwindSafe(|| open_gray(&path, &limits))) {
            Ok(Ok(img)) => {
                assert!(u64::from(img.width()) * u64::from(img.height()) <= limits.max_pixels);
                decoded += 1;
            }
            Ok(Err(e)) => {
                assert!(!e.to_string().is_empty());
                refused += 1;
            }
            Err(_) => panics.push(name.to_string()),
        }
    };
    for (n, (ext, file)) in originals().iter().enumerate() {
        run(&format!("original {n}.{ext}"), ext, file, &dir);
        for cut in (0..file.len()).step_by((file.len() / 60).max(1)) {
            run(&format!("{n}.{ext} cut at {cut}"), ext, &file[..cut], &dir);
        }
        for trial in 0..2000 {
            let mut bytes = file.clone();
            for _ in 0..1 + rng.below(8) {
                let at = rng.below(bytes.len() as u64) as usize;
                bytes[at] ^= 1 << rng.below(8);
            }
            run(&format!("{n}.{ext} flip {trial}"), ext, &bytes, &dir);
        }
        for (w, h) in [
            (200_000, 200_000),
            (65_500, 65_500),
            (30_000, 16_000),
            (u32::MAX, u32::MAX),
            (0, 0),
            (1, u32::MAX),
            (2_000, 2_000),
        ] {
            run(
                &format!("{n}.{ext} claims {w}x{h}"),
                ext,
                &lie_about_size(ext, file, w, h),
                &dir,
            );
        }
        // Under another file type's name: the content decides, not the extension.
        run(&format!("{n}.{ext} named .png"), "png", file, &dir);
    }
    std::fs::remove_dir_all(&dir).ok();
    let peak = peak_rss();
    println!(
        "{} files: {decoded} decoded, {refused} refused, {} panics; peak memory {} MiB",
        decoded + refused + panics.len(),
        panics.len(),
        peak.map_or("unknown".into(), |b| (b >> 20).to_string())
    );
    assert!(panics.is_empty(), "panics: {panics:#?}");
    assert!(refused > 0 && decoded > 0);
    // A header that claims 2^64 pixels must not have been believed: the whole corpus, test harness
    // included, stays well under what one such allocation would take.
    if let Some(peak) = peak {
        assert!(peak < 1 << 30, "peak memory {} MiB", peak >> 20);
    }
}
