//! Times the CPU default extraction (`ExtractorConfig::default()`: detection on the 8-level pyramid,
//! selection, orientation, sub-pixel positions and description) on one image, for side-by-side runs
//! with OpenCV's ORB (`tools/cpu_vs_orb.py` drives it) and for profiles.
//!
//! ```text
//! cargo run --release --example cpu_extract -- prepare IMAGE OUT.png [WIDTHxHEIGHT]
//!     writes IMAGE in gray as clatch reads it, resized (bilinear) when a size is given: the file
//!     both sides of a comparison then read
//! cargo run --release --example cpu_extract -- time IMAGE THREADS REPEATS
//!     extracts REPEATS times on a pool of THREADS threads (one warm-up call first); prints the
//!     image size, the number of keypoints and the median milliseconds per call (the upper median
//!     of an even count)
//! cargo run --release --example cpu_extract -- features IMAGE
//!     prints one line per keypoint, `x y size angle response octave` then the descriptor's 64-bit
//!     words in hex (to compare builds)
//! ```

use std::time::Instant;

use clatch::{Backend, Extractor, ExtractorConfig, GrayView};

type Failure = Box<dyn std::error::Error>;

fn main() -> Result<(), Failure> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: cpu_extract prepare IMAGE OUT.png [WIDTHxHEIGHT] | time IMAGE THREADS REPEATS | features IMAGE";
    let mode = args.first().ok_or(usage)?;
    let image = clatch::decode::gray_from_dynamic(&image::open(args.get(1).ok_or(usage)?)?);
    let (w, h) = (image.width() as usize, image.height() as usize);
    let view = GrayView::new(image.as_raw(), w, h, w)?;
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    match mode.as_str() {
        "prepare" => {
            let out = args.get(2).ok_or(usage)?;
            let resized = match args.get(3) {
                Some(size) => {
                    let (w, h) = size.split_once('x').ok_or(usage)?;
                    let (w, h) = (w.parse()?, h.parse()?);
                    image::imageops::resize(&image, w, h, image::imageops::FilterType::Triangle)
                }
                None => image,
            };
            resized.save(out)?;
            println!("width {} height {}", resized.width(), resized.height());
        }
        "time" => {
            let threads: usize = args.get(2).ok_or(usage)?.parse()?;
            let repeats: usize = args.get(3).ok_or(usage)?.parse()?;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?;
            let mut keypoints = pool.install(|| extractor.detect_and_describe(&view))?.len();
            let mut times = Vec::with_capacity(repeats);
            for _ in 0..repeats {
                let start = Instant::now();
                let features = pool.install(|| extractor.detect_and_describe(&view))?;
                times.push(start.elapsed().as_secs_f64() * 1e3);
                keypoints = features.len();
            }
            // The median (the upper one of an even count).
            times.sort_by(f64::total_cmp);
            let median = times.get(repeats / 2).ok_or("REPEATS must be at least 1")?;
            println!(
                "width {w} height {h} keypoints {keypoints} threads {threads} median_ms {median:.3}"
            );
        }
        "features" => {
            let features = extractor.detect_and_describe(&view)?;
            for (k, words) in features.keypoints.iter().zip(features.descriptors.rows()) {
                let hex: String = words.iter().map(|w| format!("{w:016x}")).collect();
                let (x, y, size, angle) = (k.x, k.y, k.size, k.angle);
                println!("{x} {y} {size} {angle} {} {} {hex}", k.response, k.octave);
            }
        }
        _ => return Err(usage.into()),
    }
    Ok(())
}
