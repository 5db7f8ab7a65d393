//! Frames on several CUDA streams: image `i` is detected and described on one stream while images
//! `i - 2` and `i - 1` are matched on another, so the device works on both at once.
//!
//! ```sh
//! cargo run --release --features cuda --example gpu_streams
//! ```
//!
//! It compiles in every build (the stream types exist without the `cuda` feature too); without the
//! feature or a device it says why and stops.

use clatch::cuda::GpuStream;
use clatch::{Backend, Extractor, ExtractorConfig, GrayView, MatchConfig, Matcher};

fn main() -> clatch::Result<()> {
    let gpu = Backend::Cuda { device: 0 };
    if let Err(why) = gpu.ensure_available() {
        println!("{why}");
        return Ok(());
    }
    let (w, h) = (1920, 1080);
    let frames = (0..8)
        .map(|i| clatch::synthetic::rectangles(w, h, i))
        .collect::<clatch::Result<Vec<Vec<u8>>>>()?;
    let extractor = Extractor::new(gpu, ExtractorConfig::default())?;
    let matcher = Matcher::new(gpu, MatchConfig::default())?;
    let streams = [GpuStream::new(0)?, GpuStream::new(0)?];

    let mut features = vec![extractor.detect_and_describe(&GrayView::new(&frames[0], w, h, w)?)?];
    for i in 1..=frames.len() {
        // Queue the next frame's extraction, then the matching of the two before it; neither blocks.
        let next = match frames.get(i) {
            Some(f) => Some(
                extractor.detect_and_describe_async(&streams[0], &GrayView::new(f, w, h, w)?)?,
            ),
            None => None,
        };
        let pair = match i {
            2.. => Some(matcher.match_descriptors_async(
                &streams[1],
                &features[i - 2].descriptors,
                &features[i - 1].descriptors,
            )?),
            _ => None,
        };
        if let Some(next) = next {
            features.push(next.wait()?);
        }
        if let Some(pair) = pair {
            println!(
                "frames {} and {}: {} matches",
                i - 2,
                i - 1,
                pair.wait()?.len()
            );
        }
    }
    Ok(())
}
