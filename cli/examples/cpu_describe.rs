//! Times the CPU describe on a given image and keypoint list, for side-by-side runs with other
//! implementations (`tools/cpu_vs_opencv.py` drives it) and for instruction counts under callgrind.
//!
//! ```text
//! cargo run --release --example cpu_describe -- detect IMAGE OUT.txt [MAX_KEYPOINTS [THRESHOLD]]
//!     detects keypoints (default detector) and writes them, one `x y size angle` line each
//! cargo run --release --example cpu_describe -- time IMAGE KEYPOINTS.txt THREADS REPEATS
//!     describes the list REPEATS times on a pool of THREADS threads; prints the number of
//!     descriptors and the median microseconds per descriptor of the repeats
//! cargo run --release --example cpu_describe -- bits IMAGE KEYPOINTS.txt
//!     prints `index words` per described keypoint, the 64-bit words in hex (to compare builds)
//! ```

use std::time::Instant;

use clatch::{Backend, Extractor, ExtractorConfig, GrayView, KeyPoint};

type Failure = Box<dyn std::error::Error>;

fn load(path: &str) -> Result<image::GrayImage, Failure> {
    Ok(clatch::decode::gray_from_dynamic(&image::open(path)?))
}

fn read_keypoints(path: &str) -> Result<Vec<KeyPoint>, Failure> {
    let text = std::fs::read_to_string(path)?;
    text.lines()
        .filter(|line| !line.trim().is_empty())
        .map(|line| {
            let v: Vec<f32> = line
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()?;
            let [x, y, size, angle] = v[..] else {
                return Err(format!("expected `x y size angle`, got {line:?}").into());
            };
            let mut kp = KeyPoint::new(x, y).with_angle(angle);
            kp.size = size;
            Ok(kp)
        })
        .collect()
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    }
}

fn main() -> Result<(), Failure> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: cpu_describe detect IMAGE OUT [MAX [THRESHOLD]] | time IMAGE KEYPOINTS THREADS REPEATS \
                 | bits IMAGE KEYPOINTS";
    let mode = args.first().ok_or(usage)?;
    let image = load(args.get(1).ok_or(usage)?)?;
    let (w, h) = image.dimensions();
    let view = GrayView::new(image.as_raw(), w as usize, h as usize, w as usize)?;
    match mode.as_str() {
        "detect" => {
            let mut config = ExtractorConfig::default();
            if let Some(max) = args.get(3) {
                config.detector.max_keypoints = max.parse()?;
            }
            if let Some(threshold) = args.get(4) {
                config.detector.threshold = threshold.parse()?;
            }
            let keypoints = Extractor::new(Backend::Cpu, config)?.detect(&view)?;
            let lines: Vec<String> = keypoints
                .iter()
                .map(|k| format!("{} {} {} {}\n", k.x, k.y, k.size, k.angle))
                .collect();
            std::fs::write(args.get(2).ok_or(usage)?, lines.concat())?;
            println!("keypoints {}", keypoints.len());
        }
        "time" => {
            let keypoints = read_keypoints(args.get(2).ok_or(usage)?)?;
            let threads: usize = args.get(3).ok_or(usage)?.parse()?;
            let repeats: usize = args.get(4).ok_or(usage)?.parse()?;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?;
            let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
            let mut per_descriptor = Vec::new();
            let mut described = 0;
            for _ in 0..repeats {
                let start = Instant::now();
                let result = pool.install(|| extractor.describe(&view, &keypoints))?;
                let seconds = start.elapsed().as_secs_f64();
                described = result.descriptors.len();
                per_descriptor.push(seconds * 1e6 / described.max(1) as f64);
            }
            println!(
                "descriptors {described} threads {threads} median_us {:.3}",
                median(per_descriptor)
            );
        }
        "bits" => {
            let keypoints = read_keypoints(args.get(2).ok_or(usage)?)?;
            let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
            let result = extractor.describe(&view, &keypoints)?;
            for (row, &i) in result.keypoint_index.iter().enumerate() {
                let words = result
                    .descriptors
                    .get(row)
                    .expect("a row per described keypoint");
                let hex: String = words.iter().map(|w| format!("{w:016x}")).collect();
                println!("{i} {hex}");
            }
        }
        _ => return Err(usage.into()),
    }
    Ok(())
}
