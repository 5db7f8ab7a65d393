//! Two photos → matches: detect, describe and match on the fastest backend here.
//!
//! ```sh
//! cargo run --release --example match_pair -- a.jpg b.jpg
//! cargo run --release --example match_pair       # the repository's photo against a shifted crop
//! ```

use std::error::Error;

use clatch::{Backend, Extractor, ExtractorConfig, GrayView, MatchConfig, Matcher};
use image::GrayImage;

fn load(path: &str) -> Result<GrayImage, Box<dyn Error>> {
    let decoded = image::open(path).map_err(|e| format!("{path}: {e}"))?;
    Ok(clatch::decode::gray_from_dynamic(&decoded))
}

/// The two images: the paths given, or the repository's photo and a copy shifted by (24, 16) pixels.
fn images() -> Result<(GrayImage, GrayImage), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [a, b] => Ok((load(a)?, load(b)?)),
        [] => {
            let photo = image::load_from_memory(include_bytes!("../assets/astronaut.png"))?;
            let photo = clatch::decode::gray_from_dynamic(&photo);
            let (w, h) = (photo.width() - 24, photo.height() - 16);
            let a = image::imageops::crop_imm(&photo, 0, 0, w, h).to_image();
            let b = image::imageops::crop_imm(&photo, 24, 16, w, h).to_image();
            Ok((a, b))
        }
        _ => Err("usage: match_pair [IMAGE_A IMAGE_B]".into()),
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let (a, b) = images()?;
    // The GPU when the `cuda` feature is on and a device is present, else every CPU core.
    let backend = Backend::auto();
    let extractor = Extractor::new(backend, ExtractorConfig::default())?;
    let matcher = Matcher::new(backend, MatchConfig::default())?;

    let features_a = extractor.detect_and_describe(&GrayView::try_from(&a)?)?;
    let features_b = extractor.detect_and_describe(&GrayView::try_from(&b)?)?;
    // Ratio test 0.8 and cross-check: each match is a mutual nearest neighbour.
    let matches = matcher.match_descriptors(&features_a.descriptors, &features_b.descriptors)?;

    println!(
        "{backend}: {} and {} keypoints, {} matches",
        features_a.len(),
        features_b.len(),
        matches.len()
    );
    for m in matches.iter().take(5) {
        let (p, q) = (
            features_a.keypoints[m.query as usize],
            features_b.keypoints[m.train as usize],
        );
        println!(
            "  ({:6.1}, {:6.1}) -> ({:6.1}, {:6.1})  {} bits apart",
            p.x, p.y, q.x, q.y, m.distance
        );
    }
    Ok(())
}
