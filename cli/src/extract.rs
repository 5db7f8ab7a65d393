//! `clatch extract IMG -o PREFIX`: keypoints as CSV and JSON, descriptors as `.npy`.

use std::ffi::OsString;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use clatch::{DescriptorSet, Extractor, KeyPoint};

use crate::error::CliError;
use crate::input::load_gray;
use crate::pipeline::{self, EXTRACT_STAGES};
use crate::progress::Progress;
use crate::report::ms;
use crate::{ExtractArgs, npy, settings};

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

fn write_file(
    path: &Path,
    write: impl FnOnce(BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), CliError> {
    let file = std::fs::File::create(path).map_err(CliError::write(path))?;
    write(BufWriter::new(file)).map_err(CliError::write(path))
}

/// Runs `clatch extract`.
pub fn main(args: &ExtractArgs) -> Result<(), CliError> {
    let settings = settings(&args.backend, &args.detect, None)?;
    let extractor = Extractor::new(settings.backend, settings.extractor)?;
    let progress = Progress::new(1 + EXTRACT_STAGES + 1);

    progress.stage("reading image");
    let img = load_gray(&args.image)?;
    progress.done();

    let latch = args.opencv.latch()?;
    let extracted = match &latch {
        None => pipeline::extract(&extractor, &img, &args.image, &progress)?,
        Some(latch) => pipeline::extract_opencv(&extractor, latch, &img, &args.image, &progress)?,
    };
    let features = &extracted.features;

    progress.stage("writing files");
    let csv = with_suffix(&args.output, ".keypoints.csv");
    let json = with_suffix(&args.output, ".keypoints.json");
    let npy_path = with_suffix(&args.output, ".descriptors.npy");
    write_file(&csv, |w| write_keypoints_csv(w, &features.keypoints))?;
    write_file(&json, |w| write_keypoints_json(w, &features.keypoints))?;
    write_file(&npy_path, |w| {
        write_descriptors_npy(w, &features.descriptors)
    })?;
    progress.done();
    progress.finish();

    let (w, h) = img.dimensions();
    let n = features.keypoints.len();
    println!("clatch extract");
    println!("  image       {} ({w}x{h})", args.image.display());
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
    println!("  {:<12}{n}", "keypoints");
    println!("  {:<12}{:>12}", "detect", ms(extracted.detect));
    println!("  {:<12}{:>12}", "describe", ms(extracted.describe));
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
