//! Pictures of matches: two gray images side by side, keypoint circles, lines between matches.

use std::io::{Seek, Write};
use std::path::Path;

use clatch::{KeyPoint, Match};
use image::codecs::pnm::{PnmEncoder, PnmSubtype, SampleEncoding};
use image::{ExtendedColorType, GrayImage, ImageEncoder, ImageFormat, Rgb, RgbImage};

use crate::error::CliError;
use clatch::output::Staged;

/// Lines and circles of matches that agree with the ground truth.
pub const INLIER: Rgb<u8> = Rgb([0, 230, 0]);
/// Lines and circles of matches that disagree with the ground truth.
pub const OUTLIER: Rgb<u8> = Rgb([255, 40, 40]);
/// Lines and circles of matches when there is no ground truth.
pub const UNCHECKED: Rgb<u8> = Rgb([255, 210, 0]);
/// Circles of keypoints without a match.
pub const UNMATCHED: Rgb<u8> = Rgb([70, 140, 255]);

/// Radius of a matched keypoint's circle.
const MATCH_RADIUS: i64 = 4;
/// Radius of an unmatched keypoint's circle.
const KEYPOINT_RADIUS: i64 = 2;

/// How a match is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatchClass {
    /// Agrees with the ground truth.
    Inlier,
    /// Disagrees with the ground truth.
    Outlier,
    /// No ground truth.
    Unchecked,
}

impl MatchClass {
    fn colour(self) -> Rgb<u8> {
        match self {
            MatchClass::Inlier => INLIER,
            MatchClass::Outlier => OUTLIER,
            MatchClass::Unchecked => UNCHECKED,
        }
    }
}

/// Sets one pixel, ignoring coordinates outside the image.
fn plot(img: &mut RgbImage, x: i64, y: i64, colour: Rgb<u8>) {
    if x >= 0 && y >= 0 && x < img.width() as i64 && y < img.height() as i64 {
        img.put_pixel(x as u32, y as u32, colour);
    }
}

/// A straight line from `(x0, y0)` to `(x1, y1)`, both ends included (Bresenham); pixels outside the
/// image are skipped.
pub fn line(img: &mut RgbImage, (x0, y0): (i64, i64), (x1, y1): (i64, i64), colour: Rgb<u8>) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        plot(img, x, y, colour);
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// A circle outline of radius `r` around `(cx, cy)` (midpoint algorithm).
pub fn circle(img: &mut RgbImage, (cx, cy): (i64, i64), r: i64, colour: Rgb<u8>) {
    let (mut x, mut y, mut err) = (r, 0i64, 1 - r);
    while x >= y {
        for (px, py) in [
            (x, y),
            (y, x),
            (-y, x),
            (-x, y),
            (-x, -y),
            (-y, -x),
            (y, -x),
            (x, -y),
        ] {
            plot(img, cx + px, cy + py, colour);
        }
        y += 1;
        if err < 0 {
            err += 2 * y + 1;
        } else {
            x -= 1;
            err += 2 * (y - x) + 1;
        }
    }
}

/// `a` and `b` side by side on one RGB canvas (`b` starts at column `a.width()`), black below the
/// shorter one.
pub fn side_by_side(a: &GrayImage, b: &GrayImage) -> RgbImage {
    let mut canvas = RgbImage::new(a.width() + b.width(), a.height().max(b.height()));
    for (offset, img) in [(0, a), (a.width(), b)] {
        for (x, y, p) in img.enumerate_pixels() {
            let v = p.0[0];
            canvas.put_pixel(offset + x, y, Rgb([v, v, v]));
        }
    }
    canvas
}

fn pixel(kp: &KeyPoint, offset: u32) -> (i64, i64) {
    (kp.x.round() as i64 + offset as i64, kp.y.round() as i64)
}

/// Which of `n` matches get a line when at most `max` may: all of them if `n <= max`, else `max`
/// of them spread evenly over the list.
pub fn line_subset(n: usize, max: usize) -> Vec<bool> {
    if n <= max {
        return vec![true; n];
    }
    let mut keep = vec![false; n];
    for j in 0..max {
        keep[j * n / max] = true;
    }
    keep
}

/// The picture of `matches` (query keypoints in `a`, train keypoints in `b`); `classes[i]` says how
/// `matches[i]` is drawn. Every matched keypoint gets a circle in its match's colour, unmatched
/// keypoints small blue circles; at most `max_lines` matches, spread evenly over the list, get a line
/// (a picture with hundreds of lines is unreadable). Outliers are drawn before inliers so that the
/// inliers stay visible.
pub fn draw_matches(
    a: &GrayImage,
    b: &GrayImage,
    keypoints_a: &[KeyPoint],
    keypoints_b: &[KeyPoint],
    matches: &[Match],
    classes: &[MatchClass],
    max_lines: usize,
) -> RgbImage {
    let mut canvas = side_by_side(a, b);
    let offset_b = a.width();
    let mut matched_a = vec![false; keypoints_a.len()];
    let mut matched_b = vec![false; keypoints_b.len()];
    for m in matches {
        matched_a[m.query as usize] = true;
        matched_b[m.train as usize] = true;
    }
    for (kps, matched, offset) in [
        (keypoints_a, &matched_a, 0),
        (keypoints_b, &matched_b, offset_b),
    ] {
        for (kp, _) in kps.iter().zip(matched.iter()).filter(|(_, m)| !**m) {
            circle(&mut canvas, pixel(kp, offset), KEYPOINT_RADIUS, UNMATCHED);
        }
    }
    let with_line = line_subset(matches.len(), max_lines);
    for pass in [
        MatchClass::Outlier,
        MatchClass::Unchecked,
        MatchClass::Inlier,
    ] {
        let drawn = matches.iter().zip(classes).zip(&with_line);
        for ((m, _), &draw_line) in drawn.filter(|((_, c), _)| **c == pass) {
            let pa = pixel(&keypoints_a[m.query as usize], 0);
            let pb = pixel(&keypoints_b[m.train as usize], offset_b);
            let colour = pass.colour();
            if draw_line {
                line(&mut canvas, pa, pb, colour);
            }
            circle(&mut canvas, pa, MATCH_RADIUS, colour);
            circle(&mut canvas, pb, MATCH_RADIUS, colour);
        }
    }
    canvas
}

/// The formats a picture is written in, chosen by the path's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PictureFormat {
    /// `.png`.
    Png,
    /// `.jpg`, `.jpeg`.
    Jpeg,
    /// `.ppm`, `.pnm`: binary PPM (P6), as every PPM reader expects.
    Ppm,
    /// `.pgm`: binary PGM (P5), the picture in gray ([`clatch::decode::luma`]).
    Pgm,
}

/// The format `path`'s extension names, checked before any work.
pub fn picture_format(path: &Path) -> Result<PictureFormat, CliError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("png") => Ok(PictureFormat::Png),
        Some("jpg" | "jpeg") => Ok(PictureFormat::Jpeg),
        Some("ppm" | "pnm") => Ok(PictureFormat::Ppm),
        Some("pgm") => Ok(PictureFormat::Pgm),
        _ => Err(CliError::PictureFormat {
            path: path.to_path_buf(),
            reason: "use .png, .jpg, .ppm or .pgm".into(),
        }),
    }
}

/// Checks, before any work, that `path`'s extension names a format this build can write and that the
/// path can be a file.
pub fn check_picture_path(path: &Path) -> Result<(), CliError> {
    picture_format(path)?;
    Ok(clatch::output::check_writable(path)?)
}

/// Encodes `picture` as `format`.
pub fn encode_picture(
    picture: &RgbImage,
    format: PictureFormat,
    out: &mut (impl Write + Seek),
) -> image::ImageResult<()> {
    let (w, h) = picture.dimensions();
    match format {
        PictureFormat::Png => picture.write_to(out, ImageFormat::Png),
        PictureFormat::Jpeg => picture.write_to(out, ImageFormat::Jpeg),
        PictureFormat::Ppm => PnmEncoder::new(out)
            .with_subtype(PnmSubtype::Pixmap(SampleEncoding::Binary))
            .write_image(picture.as_raw(), w, h, ExtendedColorType::Rgb8),
        PictureFormat::Pgm => {
            let gray = clatch::decode::gray_from_rgb(picture);
            PnmEncoder::new(out)
                .with_subtype(PnmSubtype::Graymap(SampleEncoding::Binary))
                .write_image(gray.as_raw(), w, h, ExtendedColorType::L8)
        }
    }
}

/// Encodes a picture, in the format its extension names, into a temporary file of `staged`.
pub fn stage_picture(staged: &mut Staged, picture: &RgbImage, path: &Path) -> Result<(), CliError> {
    let format = picture_format(path)?;
    staged.write(path, |out| {
        encode_picture(picture, format, out).map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// Saves a picture, in the format its extension names, through a temporary file renamed into place.
pub fn save_picture(picture: &RgbImage, path: &Path) -> Result<(), CliError> {
    let mut staged = Staged::new();
    stage_picture(&mut staged, picture, path)?;
    Ok(staged.commit()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    const C: Rgb<u8> = Rgb([1, 2, 3]);

    fn painted(img: &RgbImage) -> Vec<(i64, i64)> {
        img.enumerate_pixels()
            .filter(|(_, _, p)| **p == C)
            .map(|(x, y, _)| (x as i64, y as i64))
            .collect()
    }

    #[test]
    fn line_hits_both_endpoints_and_is_connected() {
        for &(a, b) in &[
            ((1, 1), (18, 7)),
            ((18, 7), (1, 1)),
            ((3, 15), (9, 0)),
            ((0, 0), (0, 12)),
            ((5, 5), (5, 5)),
            ((0, 19), (19, 0)),
        ] {
            let mut img = RgbImage::new(20, 20);
            line(&mut img, a, b, C);
            let px = painted(&img);
            assert!(px.contains(&a) && px.contains(&b), "{a:?}-{b:?}");
            let steps = (a.0 - b.0).abs().max((a.1 - b.1).abs());
            assert_eq!(px.len() as i64, steps + 1, "one pixel per step");
            // Every pixel has a painted 8-neighbour (connected), except a 1-pixel line.
            if px.len() > 1 {
                for &(x, y) in &px {
                    assert!(px.iter().any(|&(u, v)| {
                        (u, v) != (x, y) && (u - x).abs() <= 1 && (v - y).abs() <= 1
                    }));
                }
            }
        }
    }

    #[test]
    fn line_clips_outside_the_image() {
        let mut img = RgbImage::new(10, 10);
        line(&mut img, (-5, 5), (20, 5), C);
        assert_eq!(painted(&img).len(), 10);
    }

    #[test]
    fn circle_is_at_radius() {
        let mut img = RgbImage::new(21, 21);
        circle(&mut img, (10, 10), 5, C);
        let px = painted(&img);
        assert!(px.contains(&(15, 10)) && px.contains(&(5, 10)));
        assert!(px.contains(&(10, 15)) && px.contains(&(10, 5)));
        for (x, y) in px {
            let r = (((x - 10).pow(2) + (y - 10).pow(2)) as f64).sqrt();
            assert!((r - 5.0).abs() < 0.75, "({x}, {y}) at {r}");
        }
    }

    #[test]
    fn matches_are_drawn_across_the_two_halves() {
        let a = GrayImage::from_pixel(30, 20, image::Luma([9]));
        let b = GrayImage::from_pixel(25, 30, image::Luma([7]));
        let kps_a = [KeyPoint::new(10.0, 10.0)];
        let kps_b = [KeyPoint::new(12.0, 15.0)];
        let m = [Match {
            query: 0,
            train: 0,
            distance: 3,
        }];
        let img = draw_matches(&a, &b, &kps_a, &kps_b, &m, &[MatchClass::Inlier], 10);
        assert_eq!(img.dimensions(), (55, 30));
        assert_eq!(*img.get_pixel(10, 10), INLIER);
        assert_eq!(*img.get_pixel(42, 15), INLIER);
        assert_eq!(*img.get_pixel(0, 0), Rgb([9, 9, 9]));
        assert_eq!(*img.get_pixel(30, 0), Rgb([7, 7, 7]));
        assert_eq!(*img.get_pixel(0, 25), Rgb([0, 0, 0]));
        // Halfway along the line, (26, 12.5).
        let halfway = |img: &RgbImage| (12..=13).any(|y| *img.get_pixel(26, y) == INLIER);
        assert!(halfway(&img));
        let img = draw_matches(&a, &b, &kps_a, &kps_b, &m, &[MatchClass::Inlier], 0);
        assert_eq!(*img.get_pixel(14, 10), INLIER, "circles stay");
        assert_eq!(
            *img.get_pixel(10, 10),
            Rgb([9, 9, 9]),
            "no line through the centre"
        );
        assert!(!halfway(&img), "no line");
    }

    #[test]
    fn picture_paths() {
        for ok in ["a.png", "./b.JPG", "c.jpeg", "d.ppm"] {
            assert!(check_picture_path(Path::new(ok)).is_ok(), "{ok}");
        }
        // A folder that does not exist is found before any work.
        let e = check_picture_path(Path::new("no-such-dir/b.png")).unwrap_err();
        assert!(
            e.to_string()
                .contains("no-such-dir: the folder does not exist"),
            "{e}"
        );
        for bad in ["a.bmp", "noext", "x.txt", "x.pam", "x.pbm"] {
            let e = check_picture_path(Path::new(bad)).unwrap_err();
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    #[test]
    fn ppm_and_pgm_are_binary_p6_and_p5() {
        let picture = RgbImage::from_fn(5, 3, |x, y| Rgb([x as u8 * 50, y as u8 * 100, 7]));
        let encode = |format| {
            let mut out = std::io::Cursor::new(Vec::new());
            encode_picture(&picture, format, &mut out).unwrap();
            out.into_inner()
        };
        // P6/P5 header (magic, width, height, 255, each followed by one whitespace), then raw bytes.
        let split = |data: &[u8]| {
            let text = String::from_utf8_lossy(&data[..data.len().min(16)]).into_owned();
            let fields: Vec<String> = text.split_whitespace().take(4).map(str::to_owned).collect();
            let header_len = fields.iter().map(|f| f.len() + 1).sum::<usize>();
            (fields, data[header_len..].to_vec())
        };
        let (fields, pixels) = split(&encode(PictureFormat::Ppm));
        assert_eq!(fields, ["P6", "5", "3", "255"]);
        assert_eq!(pixels, picture.as_raw().as_slice());
        let (fields, pixels) = split(&encode(PictureFormat::Pgm));
        assert_eq!(fields, ["P5", "5", "3", "255"]);
        let gray = clatch::decode::gray_from_rgb(&picture);
        assert_eq!(pixels, gray.as_raw().as_slice());
        assert_eq!(
            picture_format(Path::new("x.PPM")).unwrap(),
            PictureFormat::Ppm
        );
        assert_eq!(
            picture_format(Path::new("x.pnm")).unwrap(),
            PictureFormat::Ppm
        );
    }

    #[test]
    fn line_subsets_are_spread_and_exact() {
        assert_eq!(line_subset(3, 5), vec![true; 3]);
        assert_eq!(line_subset(4, 0), vec![false; 4]);
        let keep = line_subset(10, 4);
        assert_eq!(keep.iter().filter(|k| **k).count(), 4);
        assert_eq!(
            keep,
            [
                true, false, true, false, false, true, false, true, false, false
            ]
        );
    }
}
