//! `clatch extract IMG -o PREFIX`: keypoints as CSV and JSON, descriptors as `.npy`.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};

use clatch::{DescriptorSet, Extractor, KeyPoint};

use crate::error::CliError;
use crate::input::{check_detectable, load_gray};
use crate::pipeline::{self, EXTRACT_STAGES};
use crate::progress::Progress;
use crate::report::{ms, print_set_up_steps};
use crate::{ExtractArgs, npy, settings_on};
use clatch::output::{Staged, check_distinct, check_writable, ends_with_separator};

/// `PREFIX` followed by `suffix` (no separator added).
pub fn with_suffix(prefix: &Path, suffix: &str) -> PathBuf {
    let mut s = OsString::from(prefix.as_os_str());
    s.push(suffix);
    PathBuf::from(s)
}

/// Keypoints as CSV with the header `x,y,size,angle,response,octave`.
pub fn write_keypoints_csv(mut w: impl Write, keypoints: &[KeyPoint]) -> std::io::Result<()> {
    writeln!(w, "x,y,size,angle,response,octave")?;
    for kp in keypoints {
        writeln!(
            w,
            "{},{},{},{},{},{}",
            kp.x, kp.y, kp.size, kp.angle, kp.response, kp.octave
        )?;
    }
    w.flush()
}

/// Keypoints as a JSON array of objects with the fields of [`KeyPoint`], one object per line.
pub fn write_keypoints_json(mut w: impl Write, keypoints: &[KeyPoint]) -> std::io::Result<()> {
    // Keypoint fields are finite (the library validates them), so `{}` always prints a JSON number.
    write!(w, "[")?;
    for (i, kp) in keypoints.iter().enumerate() {
        let sep = if i == 0 { "" } else { "," };
        write!(
            w,
            "{sep}\n  {{\"x\": {}, \"y\": {}, \"size\": {}, \"angle\": {}, \"response\": {}, \"octave\": {}}}",
            kp.x, kp.y, kp.size, kp.angle, kp.response, kp.octave
        )?;
    }
    writeln!(w, "{}]", if keypoints.is_empty() { "" } else { "\n" })?;
    w.flush()
}

/// Descriptors as an `N x bytes` `uint8` `.npy` array in OpenCV LATCH's byte layout.
pub fn write_descriptors_npy(w: impl Write, descriptors: &DescriptorSet) -> std::io::Result<()> {
    let bytes = descriptors.to_opencv_bytes();
    npy::write_u8(w, &bytes, descriptors.len(), descriptors.width().bytes())
}

/// The three output paths of `PREFIX`: keypoints CSV, keypoints JSON, descriptors `.npy`. A prefix
/// that names a folder (`out/`, `.`, an existing folder) is refused: the files would be hidden
/// `out/.keypoints.csv`.
pub fn output_paths(prefix: &Path) -> Result<[PathBuf; 3], CliError> {
    let names_folder = prefix.file_name().is_none()
        || ends_with_separator(prefix)
        || prefix.is_dir()
        || prefix.file_name().is_some_and(|n| n == "." || n == "..");
    if names_folder {
        return Err(CliError::OutputPath {
            path: prefix.to_path_buf(),
            reason: "the output prefix names a folder; give a file name prefix such as DIR/photo"
                .into(),
        });
    }
    Ok([".keypoints.csv", ".keypoints.json", ".descriptors.npy"].map(|s| with_suffix(prefix, s)))
}

/// Runs `clatch extract`.
pub fn main(args: &ExtractArgs) -> Result<(), CliError> {
    // The backend's set-up (on the GPU: the device's context and kernels) runs on a thread of its
    // own while the outputs are checked and the images decoded.
    let start = args.backend.start()?;
    let settings = settings_on(start.backend(), &args.detect, args.subpixel.library(), None)?;
    // OpenCV-compatible LATCH describes full-resolution keypoints: single scale unless --pyramid
    // is asked for, which extract_opencv then refuses.
    let config = if args.opencv.opencv_latch {
        let mut config = args.detect.config_full_resolution()?;
        config.detector.subpixel = settings.extractor.detector.subpixel;
        config
    } else {
        settings.extractor
    };
    let extractor = Extractor::starting(&start, config)?;
    let image = match args.images.as_slice() {
        [one] => one,
        _ => return crate::extract_many::main(args, &extractor, start),
    };
    let [csv, json, npy_path] = output_paths(&args.output)?;
    check_distinct(
        &[("image", image)],
        &[
            ("keypoints CSV", &csv),
            ("keypoints JSON", &json),
            ("descriptors", &npy_path),
        ],
    )?;
    for path in [&csv, &json, &npy_path] {
        check_writable(path)?;
    }
    let progress = Progress::new(1 + EXTRACT_STAGES + 1);

    progress.stage("reading image");
    let img = load_gray(image, &args.input.limits())?;
    check_detectable(image, img.width(), img.height())?;
    // Waited for here, so that the stages below time their own work only.
    let set_up = start.wait()?;
    progress.done();

    let latch = args.opencv.latch()?;
    let extracted = match &latch {
        None => pipeline::extract(&extractor, &img, image, &progress)?,
        Some(latch) => pipeline::extract_opencv(&extractor, latch, &img, image, &progress)?,
    };
    let features = &extracted.features;
    crate::input::warn_if_no_keypoints(
        image,
        img.dimensions(),
        features.keypoints.len(),
        extractor.config(),
    );

    progress.stage("writing files");
    // All three are written in full before any replaces an older file.
    let mut staged = Staged::new();
    staged.write(&csv, |w| write_keypoints_csv(w, &features.keypoints))?;
    staged.write(&json, |w| write_keypoints_json(w, &features.keypoints))?;
    staged.write(&npy_path, |w| {
        write_descriptors_npy(w, &features.descriptors)
    })?;
    staged.commit()?;
    progress.done();
    progress.finish();

    let (w, h) = img.dimensions();
    let n = features.keypoints.len();
    println!("clatch extract");
    println!("  image       {} ({w}x{h})", image.display());
    println!("  {:<12}{}", "backend", extractor.backend());
    if let Some(l) = &latch {
        println!(
            "  {:<12}OpenCV LATCH (bytes {}, rotation {}, half_ssd_size {}, sigma {})",
            "descriptor",
            l.bytes(),
            l.rotation_invariance(),
            l.half_ssd_size(),
            l.sigma()
        );
    }
    println!(
        "  {:<12}{:>12} (the backend's set-up, alongside reading the image)",
        "start",
        ms(set_up)
    );
    print_set_up_steps(extractor.backend());
    println!("  {:<12}{n}", "keypoints");
    match extracted.describe {
        Some(describe) => {
            println!("  {:<12}{:>12}", "detect", ms(extracted.detect));
            println!("  {:<12}{:>12}", "describe", ms(describe));
        }
        None => println!("  {:<12}{:>12}", "detect+desc", ms(extracted.detect)),
    }
    println!("  wrote       {}", csv.display());
    println!("  wrote       {}", json.display());
    println!(
        "  wrote       {} (uint8, shape ({n}, {}), OpenCV LATCH byte layout)",
        npy_path.display(),
        features.descriptors.width().bytes()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clatch::{Descriptor, DescriptorWidth};

    fn keypoints() -> Vec<KeyPoint> {
        vec![
            KeyPoint::new(10.0, 20.0).with_angle(12.5),
            KeyPoint {
                response: 33.0,
                octave: 0,
                ..KeyPoint::new(1.5, 2.0)
            },
        ]
    }

    #[test]
    fn a_prefix_naming_a_folder_is_refused() {
        for prefix in ["out/", ".", "..", "/"] {
            let e = output_paths(Path::new(prefix)).unwrap_err();
            assert!(matches!(e, CliError::OutputPath { .. }), "{prefix}: {e}");
        }
        let e = output_paths(&std::env::temp_dir()).unwrap_err();
        assert!(e.to_string().contains("prefix names a folder"), "{e}");
        let [csv, ..] = output_paths(Path::new("out/photo")).unwrap();
        assert_eq!(csv, PathBuf::from("out/photo.keypoints.csv"));
    }

    #[test]
    fn suffix_is_appended() {
        assert_eq!(
            with_suffix(Path::new("out/photo"), ".keypoints.csv"),
            PathBuf::from("out/photo.keypoints.csv")
        );
    }

    #[test]
    fn csv_and_json() {
        let mut csv = Vec::new();
        write_keypoints_csv(&mut csv, &keypoints()).unwrap();
        assert_eq!(
            String::from_utf8(csv).unwrap(),
            "x,y,size,angle,response,octave\n10,20,64,12.5,0,0\n1.5,2,64,0,33,0\n"
        );
        let mut json = Vec::new();
        write_keypoints_json(&mut json, &keypoints()).unwrap();
        assert_eq!(
            String::from_utf8(json).unwrap(),
            "[\n  {\"x\": 10, \"y\": 20, \"size\": 64, \"angle\": 12.5, \"response\": 0, \"octave\": 0},\n  \
             {\"x\": 1.5, \"y\": 2, \"size\": 64, \"angle\": 0, \"response\": 33, \"octave\": 0}\n]\n"
        );
        let mut empty = Vec::new();
        write_keypoints_json(&mut empty, &[]).unwrap();
        assert_eq!(empty, b"[]\n");
    }

    #[test]
    fn npy_holds_opencv_bytes() {
        let mut d = Descriptor::default();
        d.0[0] = 1; // triplet 0: the most significant bit of byte 0 in OpenCV's layout
        let width = DescriptorWidth::from_bits(16).unwrap();
        let set = DescriptorSet::from_descriptors(width, &[d, Descriptor::default()]);
        let mut out = Vec::new();
        write_descriptors_npy(&mut out, &set).unwrap();
        let header = npy::header_u8(2, 2);
        assert_eq!(&out[..header.len()], &header[..]);
        assert_eq!(&out[header.len()..], &[0x80, 0, 0, 0]);
    }
}
