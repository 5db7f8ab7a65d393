//! `clatch extract IMG... -o DIR`: several images, their files in one folder. Images are decoded on
//! worker threads ahead of the extractor, which takes them as a stream (on the GPU several in flight
//! on several streams); the progress bar counts images with their rate.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clatch::{Extractor, GrayView};

use crate::ExtractArgs;
use crate::error::CliError;
use crate::extract::{write_descriptors_npy, write_keypoints_csv, write_keypoints_json};
use crate::input::{check_detectable, load_gray};
use crate::progress::Progress;
use crate::report::{self, ms, per_second, print_set_up_steps};
use clatch::output::{Staged, check_distinct, check_writable};
use clatch::prefetch::extract_decoded;

/// A decoded image waiting for extraction.
struct Decoded {
    img: image::GrayImage,
    index: usize,
}

impl clatch::AsGrayView for Decoded {
    fn gray_view(&self) -> clatch::Result<GrayView<'_>> {
        GrayView::try_from(&self.img)
    }
}

/// The three output files of `image` in `dir`: `STEM.keypoints.csv`, `STEM.keypoints.json`,
/// `STEM.descriptors.npy`.
fn outputs_in(dir: &Path, image: &Path) -> Result<[PathBuf; 3], CliError> {
    let stem = image.file_stem().ok_or_else(|| CliError::OutputPath {
        path: image.to_path_buf(),
        reason: "the image path has no file name to name its outputs by".into(),
    })?;
    let prefix = dir.join(stem);
    Ok([".keypoints.csv", ".keypoints.json", ".descriptors.npy"]
        .map(|suffix| crate::extract::with_suffix(&prefix, suffix)))
}

/// Runs `clatch extract` on several images with `extractor`, whose backend `start` is setting up
/// meanwhile; `-o` names the output folder.
pub fn main(
    args: &ExtractArgs,
    extractor: &Extractor,
    start: clatch::BackendStart,
) -> Result<(), CliError> {
    if args.opencv.opencv_latch {
        return Err(CliError::OptionConflict {
            options: "--opencv-latch with several images".into(),
            reason: "OpenCV-compatible LATCH describes one image per call; run one call per image"
                .into(),
        });
    }
    let dir = &args.output;
    if dir.exists() && !dir.is_dir() {
        return Err(CliError::OutputPath {
            path: dir.clone(),
            reason: "with several images, -o names a folder for their files".into(),
        });
    }
    // Every output checked before any work: distinct from each other and from the inputs.
    let outputs = args
        .images
        .iter()
        .map(|image| outputs_in(dir, image))
        .collect::<Result<Vec<_>, _>>()?;
    let inputs: Vec<(&'static str, &Path)> =
        args.images.iter().map(|p| ("image", p.as_path())).collect();
    let roles = ["keypoints CSV", "keypoints JSON", "descriptors"];
    let all_outputs: Vec<(&'static str, &Path)> = outputs
        .iter()
        .flat_map(|files| {
            roles
                .iter()
                .copied()
                .zip(files.iter().map(PathBuf::as_path))
        })
        .collect();
    // Two inputs of one name (a/x.png, b/x.png) would write one set of files: named, both of them.
    for (i, a) in args.images.iter().enumerate() {
        if let Some(b) = args.images[..i]
            .iter()
            .find(|b| outputs_in(dir, b).ok() == outputs_in(dir, a).ok())
        {
            return Err(CliError::OutputPath {
                path: outputs[i][0].clone(),
                reason: format!(
                    "the images {} and {} would both write their files as {}.*; give them \
                     different file names or extract them into different folders",
                    b.display(),
                    a.display(),
                    a.file_stem().unwrap_or_default().to_string_lossy()
                ),
            });
        }
    }
    check_distinct(&inputs, &all_outputs)?;
    std::fs::create_dir_all(dir).map_err(CliError::write(dir))?;
    for (_, path) in &all_outputs {
        check_writable(path)?;
    }

    let limits = args.input.limits();
    // Every header before any work: a bad image is found before the first file is written.
    let mut failed: Vec<(usize, CliError)> = Vec::new();
    for (i, path) in args.images.iter().enumerate() {
        let checked = clatch::decode::probe(path, &limits)
            .map_err(CliError::from)
            .and_then(|info| check_detectable(path, info.width, info.height));
        if let Err(e) = checked {
            if args.fail_fast {
                return Err(e);
            }
            failed.push((i, e));
        }
    }

    let progress = Progress::counter(args.images.len() as u64, "extracting images");
    let began = Instant::now();
    let mut keypoints = 0usize;
    let mut written = vec![false; args.images.len()];
    // --fail-fast: every image's files renamed into place together at the end, or none.
    let mut all_or_none = Staged::new();
    let mut decoding = clatch::prefetch::Prefetched::default();
    loop {
        let todo: Vec<usize> = (0..args.images.len())
            .filter(|&i| !written[i] && !failed.iter().any(|(f, _)| *f == i))
            .collect();
        if todo.is_empty() {
            break;
        }
        let run = extract_decoded(
            extractor,
            todo.len(),
            |k| {
                let index = todo[k];
                let path = &args.images[index];
                let img = load_gray(path, &limits)
                    .and_then(|img| check_detectable(path, img.width(), img.height()).map(|()| img))
                    .map_err(|error| Failure {
                        image: Some(index),
                        error: Box::new(error),
                    })?;
                Ok::<_, Failure>(Decoded { img, index })
            },
            |_, decoded, features| {
                crate::input::warn_if_no_keypoints(
                    &args.images[decoded.index],
                    decoded.img.dimensions(),
                    features.keypoints.len(),
                    extractor.config(),
                );
                let [csv, json, npy] = &outputs[decoded.index];
                let mut one = Staged::new();
                let staged = if args.fail_fast {
                    &mut all_or_none
                } else {
                    &mut one
                };
                staged.write(csv, |w| write_keypoints_csv(w, &features.keypoints))?;
                staged.write(json, |w| write_keypoints_json(w, &features.keypoints))?;
                staged.write(npy, |w| write_descriptors_npy(w, &features.descriptors))?;
                // Each image's three files go into place together: never half of one image's result.
                one.commit()?;
                written[decoded.index] = true;
                keypoints += features.keypoints.len();
                progress.done();
                Ok(())
            },
        );
        match run {
            Ok(stats) => {
                decoding.produce += stats.produce;
                decoding.waited += stats.waited;
                decoding.threads = decoding.threads.max(stats.threads);
            }
            Err(Failure {
                image: Some(index),
                error,
            }) if !args.fail_fast => {
                progress.done();
                failed.push((index, *error));
            }
            Err(Failure { error, .. }) => return Err(*error),
        }
    }
    all_or_none.commit()?;
    let wall = began.elapsed();
    // Done by now: the first image's extraction waited for it.
    let set_up = start.wait()?;
    progress.finish();

    let n = written.iter().filter(|&&w| w).count();
    println!("clatch extract");
    println!("  images      {n} of {}", args.images.len());
    println!("  {:<12}{}", "backend", extractor.backend());
    println!(
        "  {:<12}{} (the backend's set-up, alongside decoding; extract includes any wait for it)",
        "start",
        ms(set_up)
    );
    print_set_up_steps(extractor.backend());
    println!(
        "  {:<12}{keypoints} ({:.0} per image)",
        "keypoints",
        keypoints as f64 / n.max(1) as f64
    );
    println!(
        "  {:<12}{} ({}, files written included)",
        "extract",
        ms(wall),
        per_second(n, wall, "images")
    );
    println!("  {:<12}{}", "decode", report::decoding(&decoding));
    println!("  wrote       {} x 3 files in {}", n, dir.display());
    if failed.is_empty() {
        return Ok(());
    }
    failed.sort_by_key(|(i, _)| *i);
    for (_, e) in &failed {
        eprintln!("clatch: failed: {e}");
    }
    Err(CliError::ImagesFailed {
        failed: failed.len(),
        total: args.images.len(),
        first: args.images[failed[0].0].clone(),
    })
}

/// An error of the extraction loop, with the image it belongs to when it is one image's (that image
/// is listed as failed and the others go on, unless --fail-fast).
struct Failure {
    image: Option<usize>,
    error: Box<CliError>,
}

impl From<clatch::Error> for Failure {
    fn from(e: clatch::Error) -> Self {
        Self {
            image: None,
            error: Box::new(e.into()),
        }
    }
}

impl From<clatch::output::OutputError> for Failure {
    fn from(e: clatch::output::OutputError) -> Self {
        Self {
            image: None,
            error: Box::new(e.into()),
        }
    }
}
