//! The image pairs of `clatch-eval`: OpenCV's graf sample, synthetic warps (sequences on disk are in
//! [`crate::sequences`]); and the manifest (`pairs.csv`) that hands the very same files to
//! `scripts/eval_opencv.py`.

use std::path::{Path, PathBuf};

use clatch::GrayView;
use clatch::decode::DecodeLimits;
use clatch::homography::{Homography, warp};
use clatch_cli::photo::demo_homography;
use image::GrayImage;
use serde::Serialize;

use crate::degrade::{BLUR_SIGMAS, NOISE_SIGMAS, add_noise, gaussian_blur, noise_seed};
use crate::error::{EvalError, ImageContext, IoContext, write_file};
use crate::results::{Shortest, write_rows};

/// One pair: image A, image B and the homography mapping A's pixels to B's.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalPair {
    /// Unique name (no commas), e.g. `graf 1-3`, `astronaut rot 30`.
    pub name: String,
    /// Which family the pair belongs to, e.g. `oxford-graf`, `synthetic-rotation`.
    pub group: String,
    /// The varied parameter of synthetic pairs (degrees or scale factor).
    pub param: Option<f64>,
    /// Image A (queries).
    pub image_a: PathBuf,
    /// Image B (gallery).
    pub image_b: PathBuf,
    /// Ground truth, A to B (Oxford text or OpenCV XML).
    pub homography: PathBuf,
}

/// Group names, shared with the script and the charts.
pub const GROUP_OPENCV_SAMPLE: &str = "opencv-sample";
/// Synthetic rotations at scale 1.
pub const GROUP_ROTATION: &str = "synthetic-rotation";
/// Synthetic scalings without rotation.
pub const GROUP_SCALE: &str = "synthetic-scale";
/// Synthetic perspective warps.
pub const GROUP_PERSPECTIVE: &str = "synthetic-perspective";
/// B is A plus Gaussian noise (no warp); the parameter is sigma in gray levels.
pub const GROUP_NOISE: &str = "synthetic-noise";
/// B is A blurred by a Gaussian (no warp); the parameter is sigma in pixels.
pub const GROUP_BLUR: &str = "synthetic-blur";

/// Synthetic rotations, degrees (scale 1).
pub fn rotations() -> Vec<f64> {
    (0..=12).map(|i| 15.0 * i as f64).collect()
}

/// Synthetic scale factors (no rotation): 0.5 to 2.
pub const SCALES: [f64; 10] = [0.5, 0.6, 0.7, 0.8, 0.9, 1.15, 1.3, 1.5, 1.75, 2.0];

fn missing(path: &Path, what: &str) -> EvalError {
    EvalError::Input {
        path: path.to_path_buf(),
        reason: format!("{what} not found"),
    }
}

/// OpenCV's sample pair in `dir`: `graf1.png`, `graf3.png`, `H1to3p.xml`.
pub fn opencv_sample_pair(dir: &Path) -> Result<EvalPair, EvalError> {
    let file = |name: &str| {
        let path = dir.join(name);
        if path.is_file() {
            Ok(path)
        } else {
            Err(missing(&path, "OpenCV sample file"))
        }
    };
    Ok(EvalPair {
        name: "opencv graf1-graf3".into(),
        group: GROUP_OPENCV_SAMPLE.into(),
        param: None,
        image_a: file("graf1.png")?,
        image_b: file("graf3.png")?,
        homography: file("H1to3p.xml")?,
    })
}

/// A photo to warp: a name for the pairs and the gray image.
pub struct SyntheticSource {
    /// Short name, used in pair names and file names.
    pub name: String,
    /// The photo.
    pub image: GrayImage,
}

/// Reads a homography file: nine numbers (the Oxford and HPatches format) or OpenCV FileStorage XML.
pub fn read_homography(path: &Path) -> Result<Homography, EvalError> {
    let text = std::fs::read_to_string(path).reading(path)?;
    text.parse().map_err(
        |e: clatch::homography::ParseHomographyError| EvalError::Homography {
            path: path.to_path_buf(),
            reason: e.to_string(),
        },
    )
}

/// Decodes an image as 8-bit gray.
pub fn read_gray(path: &Path) -> Result<GrayImage, EvalError> {
    Ok(clatch::decode::open_gray(path, &DecodeLimits::default())?)
}

/// Parses `NAME=PATH` or `PATH` (the name is then the file stem) and loads the image.
pub fn synthetic_source(arg: &str) -> Result<SyntheticSource, EvalError> {
    let (name, path) = match arg.split_once('=') {
        Some((name, path)) => (name.to_string(), PathBuf::from(path)),
        None => {
            let path = PathBuf::from(arg);
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
            (stem.unwrap_or_default(), path)
        }
    };
    let ok = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '_';
    if name.is_empty() || !name.chars().all(ok) {
        return Err(EvalError::Input {
            path,
            reason: format!(
                "synthetic source name `{name}` must be letters, digits, `-` or `_` \
                 (give one as NAME=PATH)"
            ),
        });
    }
    Ok(SyntheticSource {
        image: read_gray(&path)?,
        name,
    })
}

/// The known warps of a `width` x `height` image: (suffix, group, parameter, homography), all about
/// the image centre.
pub fn synthetic_warps(width: u32, height: u32) -> Vec<(String, &'static str, f64, Homography)> {
    let (w, h) = (width as usize, height as usize);
    let mut warps = Vec::new();
    for degrees in rotations() {
        let hom = Homography::rotation_scale(degrees, 1.0).about_centre(w, h);
        warps.push((format!("rot {degrees}"), GROUP_ROTATION, degrees, hom));
    }
    for scale in SCALES {
        let hom = Homography::rotation_scale(0.0, scale).about_centre(w, h);
        warps.push((format!("scale {scale:.2}"), GROUP_SCALE, scale, hom));
    }
    // The demo's view (30 degrees, 0.9, slight tilt) and a strong tilt: w from 0.75 to 1.25 across
    // the image's width.
    warps.push((
        "persp demo".into(),
        GROUP_PERSPECTIVE,
        1.0,
        demo_homography(w, h),
    ));
    let strong = Homography::perspective(0.5 / width as f64, 0.0);
    warps.push((
        "persp strong".into(),
        GROUP_PERSPECTIVE,
        2.0,
        strong.about_centre(w, h),
    ));
    warps
}

fn save_png(img: &GrayImage, path: &Path) -> Result<(), EvalError> {
    img.save_with_format(path, image::ImageFormat::Png)
        .map_err(|source| EvalError::Encode {
            path: path.to_path_buf(),
            source,
        })
}

/// The photometric views of an image: (suffix, group, parameter, B), each with A's geometry.
pub fn degraded_views(img: &GrayImage) -> Vec<(String, &'static str, f64, GrayImage)> {
    let mut views = Vec::new();
    for sigma in NOISE_SIGMAS {
        let noisy = add_noise(img, sigma, noise_seed(sigma));
        views.push((format!("noise {sigma}"), GROUP_NOISE, sigma, noisy));
    }
    for sigma in BLUR_SIGMAS {
        let blurred = gaussian_blur(img, sigma);
        views.push((format!("blur {sigma}"), GROUP_BLUR, sigma, blurred));
    }
    views
}

/// Writes `source` and its synthetic views into `dir` (PNG images, Oxford-format homographies) and
/// returns their pairs: the warps, then the noisy and blurred copies.
pub fn write_synthetic(source: &SyntheticSource, dir: &Path) -> Result<Vec<EvalPair>, EvalError> {
    std::fs::create_dir_all(dir).writing(dir)?;
    let (width, height) = source.image.dimensions();
    let image_a = dir.join(format!("{}.png", source.name));
    save_png(&source.image, &image_a)?;
    let view = GrayView::try_from(&source.image).in_image(&image_a)?;
    let mut views = Vec::new();
    for (suffix, group, param, hom) in synthetic_warps(width, height) {
        let pixels = warp(&view, &hom, width as usize, height as usize)?;
        let warped = GrayImage::from_raw(width, height, pixels)
            .expect("a warp has the asked width x height pixels");
        views.push((suffix, group, param, hom, warped));
    }
    for (suffix, group, param, degraded) in degraded_views(&source.image) {
        views.push((suffix, group, param, Homography::identity(), degraded));
    }
    let mut pairs = Vec::new();
    for (suffix, group, param, hom, image) in views {
        let file = format!("{}_{}", source.name, suffix.replace(' ', "_"));
        let image_b = dir.join(format!("{file}.png"));
        save_png(&image, &image_b)?;
        let homography = dir.join(format!("{file}.H"));
        write_file(&homography, hom.to_string().as_bytes())?;
        pairs.push(EvalPair {
            name: format!("{} {suffix}", source.name),
            group: group.into(),
            param: Some(param),
            image_a: image_a.clone(),
            image_b,
            homography,
        });
    }
    Ok(pairs)
}

/// One line of the manifest.
#[derive(Serialize)]
struct ManifestRow<'a> {
    pair: &'a str,
    group: &'a str,
    param: Shortest,
    image_a: PathBuf,
    image_b: PathBuf,
    homography: PathBuf,
}

/// Writes the manifest to `path`: `pair,group,param,image_a,image_b,homography`, one pair a line,
/// absolute paths.
pub fn write_manifest(pairs: &[EvalPair], path: &Path) -> Result<(), EvalError> {
    let absolute = |p: &Path| std::path::absolute(p).reading(p);
    let rows = pairs
        .iter()
        .map(|p| {
            Ok(ManifestRow {
                pair: &p.name,
                group: &p.group,
                param: Shortest(p.param),
                image_a: absolute(&p.image_a)?,
                image_b: absolute(&p.image_b)?,
                homography: absolute(&p.homography)?,
            })
        })
        .collect::<Result<Vec<_>, EvalError>>()?;
    write_rows(path, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("clatch-pairs-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn warps_keep_the_centre_and_do_what_they_say() {
        let warps = synthetic_warps(101, 81);
        assert_eq!(warps.len(), 13 + SCALES.len() + 2);
        for (suffix, _, _, h) in &warps {
            let (x, y) = h.apply(50.0, 40.0).unwrap();
            assert!(
                (x - 50.0).abs() < 1e-9 && (y - 40.0).abs() < 1e-9,
                "{suffix}"
            );
        }
        let (name, group, param, rot90) = &warps[6];
        assert_eq!(
            (name.as_str(), *group, *param),
            ("rot 90", GROUP_ROTATION, 90.0)
        );
        // 10 px right of the centre goes 10 px down.
        let (x, y) = rot90.apply(60.0, 40.0).unwrap();
        assert!((x - 50.0).abs() < 1e-9 && (y - 50.0).abs() < 1e-9);
        let (name, _, _, half) = &warps[13];
        assert_eq!(name, "scale 0.50");
        assert_eq!(
            half.apply(60.0, 40.0).map(|(x, _)| (x * 1e9).round() / 1e9),
            Some(55.0)
        );
    }

    /// Image A of the synthetic pairs (the same file for all).
    fn rot_a(pairs: &[EvalPair]) -> PathBuf {
        pairs[0].image_a.clone()
    }

    #[test]
    fn synthetic_files_and_manifest() {
        let dir = temp_dir("synthetic");
        let source = SyntheticSource {
            name: "ramp".into(),
            image: GrayImage::from_fn(70, 66, |x, y| image::Luma([(3 * x + y) as u8])),
        };
        let pairs = write_synthetic(&source, &dir).unwrap();
        let warps = synthetic_warps(70, 66).len();
        assert_eq!(pairs.len(), warps + NOISE_SIGMAS.len() + BLUR_SIGMAS.len());
        // The photometric pairs: A itself against a noisy or blurred copy, through the identity.
        let noise = &pairs[warps + 1];
        assert_eq!(
            (noise.name.as_str(), noise.group.as_str(), noise.param),
            ("ramp noise 10", GROUP_NOISE, Some(10.0))
        );
        let blur = pairs.last().unwrap();
        assert_eq!(
            (blur.name.as_str(), blur.group.as_str(), blur.param),
            ("ramp blur 3", GROUP_BLUR, Some(3.0))
        );
        for (pair, expected) in [
            (noise, add_noise(&source.image, 10.0, noise_seed(10.0))),
            (blur, gaussian_blur(&source.image, 3.0)),
        ] {
            assert_eq!(pair.image_a, rot_a(&pairs));
            assert_eq!(read_gray(&pair.image_b).unwrap(), expected);
            assert_ne!(expected, source.image);
            assert_eq!(
                read_homography(&pair.homography).unwrap(),
                Homography::identity()
            );
        }
        let rot = &pairs[2];
        assert_eq!(rot.name, "ramp rot 30");
        assert_eq!(read_gray(&rot.image_a).unwrap(), source.image);
        assert_eq!(read_gray(&rot.image_b).unwrap().dimensions(), (70, 66));
        let h = read_homography(&rot.homography).unwrap();
        assert_eq!(h, synthetic_warps(70, 66)[2].3);
        // The demo's view, exactly: the homography file holds every digit.
        let demo = pairs.iter().find(|p| p.name == "ramp persp demo").unwrap();
        assert_eq!(
            read_homography(&demo.homography).unwrap(),
            demo_homography(70, 66)
        );

        // The manifest: proper CSV, so a name with a comma or a quote reads back whole.
        let quoted = EvalPair {
            name: "a,\"b\"".into(),
            ..pairs[0].clone()
        };
        let manifest_path = dir.join("pairs.csv");
        write_manifest(&[pairs[0].clone(), quoted], &manifest_path).unwrap();
        let text = std::fs::read_to_string(&manifest_path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "pair,group,param,image_a,image_b,homography");
        assert!(
            lines[1].starts_with("ramp rot 0,synthetic-rotation,0,/"),
            "{}",
            lines[1]
        );
        let mut reader = csv::Reader::from_path(&manifest_path).unwrap();
        let names: Vec<String> = reader
            .records()
            .map(|r| r.unwrap()[0].to_string())
            .collect();
        assert_eq!(names, ["ramp rot 0", "a,\"b\""]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn missing_inputs_are_typed_errors() {
        let dir = temp_dir("sample");
        assert!(matches!(
            opencv_sample_pair(&dir),
            Err(EvalError::Input { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();

        assert!(matches!(
            synthetic_source("bad name=x.png"),
            Err(EvalError::Input { .. })
        ));
        assert!(matches!(
            synthetic_source("/nonexistent/clatch.png"),
            Err(EvalError::Decode(clatch::decode::DecodeError::Io { .. }))
        ));
        assert!(matches!(
            read_homography(Path::new("/nonexistent/H1to2p")),
            Err(EvalError::File {
                access: crate::error::Access::Read,
                ..
            })
        ));
    }
}
