//! `OpencvLatch` against OpenCV itself: `cv2.xfeatures2d.LATCH_create(...).compute` (opencv-contrib-python,
//! run through `tests/opencv/latch_reference.py`) on the same images and keypoints, 0 differing bits
//! required, and the same keypoints kept (except those OpenCV would read outside the image for, which
//! we skip on purpose).
//!
//! Without python3 + cv2 every test is reported as ignored with `skipped: opencv-contrib-python not
//! installed`, never as passed; with `CLATCH_REQUIRE_OPENCV` set (as in CI) a missing cv2 fails instead.
//! `CLATCH_OPENCV_EXTRA_IMAGES=a.png:b.ppm` adds a run on those images (e.g. real photographs); without
//! it that test is ignored. `CLATCH_PYTHON` picks the interpreter.

mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use clatch::synthetic::SplitMix64;
use clatch::{Backend, Extractor, ExtractorConfig, KeyPoint, OpencvLatch, SkipReason};
use common::{Gray, astronaut, rectangles};
use libtest_mimic::{Arguments, Failed, Trial};

const EXTRA_IMAGES: &str = "CLATCH_OPENCV_EXTRA_IMAGES";
/// Set (by CI) to make a missing cv2 a failure instead of ignored tests.
const REQUIRE: &str = "CLATCH_REQUIRE_OPENCV";

fn main() {
    let args = Arguments::from_args();
    let mut trials = vec![
        Trial::test(
            "opencv_astronaut_every_configuration",
            astronaut_every_configuration,
        ),
        Trial::test("opencv_random_images_subpixel_positions", random_images),
        Trial::test("opencv_angles", angles),
        Trial::test("opencv_sigmas", sigmas),
        Trial::test("opencv_half_ssd_sizes", half_ssd_sizes),
        Trial::test("opencv_borders_and_half_pixels", borders),
    ];
    match python_with_cv2() {
        Ok(version) => println!("cv2 {version}"),
        Err(reason) if std::env::var_os(REQUIRE).is_some() => {
            eprintln!("{REQUIRE} is set but opencv-contrib-python is missing: {reason}");
            std::process::exit(1);
        }
        Err(reason) => {
            println!("skipped: opencv-contrib-python not installed ({reason})");
            trials = trials
                .into_iter()
                .map(|t| t.with_ignored_flag(true))
                .collect();
        }
    }
    let extra = Trial::test("opencv_extra_images", extra_images);
    trials.push(if std::env::var_os(EXTRA_IMAGES).is_some() {
        extra
    } else {
        extra.with_ignored_flag(true)
    });
    libtest_mimic::run(&args, trials).exit()
}

fn python() -> String {
    std::env::var("CLATCH_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// The cv2 version, if python3 can import cv2 with the contrib module.
fn python_with_cv2() -> Result<String, String> {
    let output = Command::new(python())
        .args([
            "-c",
            "import cv2; cv2.xfeatures2d.LATCH_create; print(cv2.__version__)",
        ])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python()))?;
    if !output.status.success() {
        return Err(String::from_utf8_lossy(&output.stderr)
            .lines()
            .last()
            .unwrap_or("import failed")
            .to_string());
    }
    Ok(String::from_utf8_lossy(&output.stdout).trim().to_string())
}

/// One describe call to compare.
struct Job<'a> {
    image: &'a Gray,
    keypoints: &'a [KeyPoint],
    latch: OpencvLatch,
}

/// What a comparison covered.
#[derive(Default, Debug)]
struct Tally {
    descriptors: usize,
    bits: usize,
    /// Keypoints OpenCV kept but we skip because OpenCV reads outside the image for them.
    unsafe_skipped: usize,
    /// Keypoints both drop at the border.
    border_dropped: usize,
}

impl Tally {
    fn add(&mut self, other: Tally) {
        self.descriptors += other.descriptors;
        self.bits += other.bits;
        self.unsafe_skipped += other.unsafe_skipped;
        self.border_dropped += other.border_dropped;
    }

    fn report(&self, what: &str) {
        println!(
            "{what}: {} descriptors, {} bits compared, 0 differ; {} dropped at the border by both, {} \
             kept by OpenCV but skipped as out-of-bounds reads",
            self.descriptors, self.bits, self.border_dropped, self.unsafe_skipped
        );
    }
}

/// A fresh, empty folder for one run of the Python script.
fn scratch_dir() -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "clatch-opencv-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create a temporary folder");
    dir
}

fn write_pgm(path: &Path, image: &Gray) -> std::io::Result<()> {
    let mut bytes = format!("P5\n{} {}\n255\n", image.width, image.height).into_bytes();
    bytes.extend_from_slice(&image.pixels);
    std::fs::write(path, bytes)
}

/// cv2's result of one job: the input index of every kept keypoint and its descriptor row.
type Cv2Rows = Vec<(usize, Vec<u8>)>;

/// Runs every job through cv2 in one Python process.
fn run_cv2(jobs: &[Job]) -> Result<Vec<Cv2Rows>, Failed> {
    let dir = scratch_dir();
    let mut images: HashMap<*const Gray, String> = HashMap::new();
    let mut lines = String::new();
    for (j, job) in jobs.iter().enumerate() {
        let next = images.len();
        let image = images
            .entry(job.image as *const Gray)
            .or_insert_with(|| format!("image{next}.pgm"))
            .clone();
        if !dir.join(&image).exists() {
            write_pgm(&dir.join(&image), job.image)?;
        }
        let floats: Vec<u8> = job
            .keypoints
            .iter()
            .flat_map(|kp| [kp.x, kp.y, kp.angle])
            .flat_map(f32::to_le_bytes)
            .collect();
        std::fs::write(dir.join(format!("kp{j}.f32")), floats)?;
        let l = &job.latch;
        lines.push_str(&format!(
            "{image} kp{j}.f32 out{j} {} {} {} {:?}\n",
            l.bytes(),
            u8::from(l.rotation_invariance()),
            l.half_ssd_size(),
            l.sigma()
        ));
    }
    std::fs::write(dir.join("jobs.txt"), lines)?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/opencv/latch_reference.py");
    let output = Command::new(python())
        .arg(&script)
        .arg(dir.join("jobs.txt"))
        .output()?;
    if !output.status.success() {
        return Err(format!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&output.stderr)
        )
        .into());
    }
    let mut results = Vec::new();
    for (j, job) in jobs.iter().enumerate() {
        let idx = std::fs::read(dir.join(format!("out{j}.idx")))?;
        let desc = std::fs::read(dir.join(format!("out{j}.desc")))?;
        let bytes = job.latch.bytes();
        let indices: Vec<usize> = idx
            .chunks_exact(4)
            .map(|c| i32::from_le_bytes(c.try_into().unwrap()) as usize)
            .collect();
        if desc.len() != indices.len() * bytes {
            return Err(format!(
                "job {j}: {} descriptor bytes for {} keypoints",
                desc.len(),
                indices.len()
            )
            .into());
        }
        results.push(
            indices
                .into_iter()
                .zip(desc.chunks_exact(bytes).map(<[u8]>::to_vec))
                .collect(),
        );
    }
    std::fs::remove_dir_all(&dir)?;
    Ok(results)
}

/// Compares our CPU result with cv2's for every job.
fn compare(jobs: &[Job]) -> Result<Tally, Failed> {
    let expected = run_cv2(jobs)?;
    let mut tally = Tally::default();
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    for (job, cv2) in jobs.iter().zip(expected) {
        let ours = extractor.describe_opencv(&job.latch, &job.image.view(), job.keypoints)?;
        let rows = ours.descriptors.to_opencv_bytes();
        let bytes = job.latch.bytes();
        let ours_rows: HashMap<usize, &[u8]> = ours
            .keypoint_index
            .iter()
            .copied()
            .zip(rows.chunks_exact(bytes))
            .collect();
        let skipped: HashMap<usize, SkipReason> = ours
            .skipped
            .iter()
            .map(|s| (s.keypoint, s.reason))
            .collect();
        let config = format!("{:?}", job.latch);
        let kept_by_cv2: std::collections::HashSet<usize> = cv2.iter().map(|(i, _)| *i).collect();
        for (i, row) in &cv2 {
            let kp = job.keypoints[*i];
            match (ours_rows.get(i), skipped.get(i)) {
                (Some(mine), _) => {
                    let differing: u32 = mine
                        .iter()
                        .zip(row)
                        .map(|(a, b)| (a ^ b).count_ones())
                        .sum();
                    if differing != 0 {
                        return Err(format!(
                            "{config}: keypoint {i} {kp:?}: {differing} bits differ\n ours {mine:02x?}\n cv2  {row:02x?}"
                        )
                        .into());
                    }
                    tally.descriptors += 1;
                    tally.bits += 8 * bytes;
                }
                (None, Some(SkipReason::OpencvReadsOutsideImage)) => tally.unsafe_skipped += 1,
                (None, reason) => {
                    return Err(format!(
                        "{config}: cv2 describes keypoint {i} {kp:?}, we skip it ({reason:?})"
                    )
                    .into());
                }
            }
        }
        for &i in &ours.keypoint_index {
            if !kept_by_cv2.contains(&i) {
                return Err(format!(
                    "{config}: we describe keypoint {i} {:?}, cv2 drops it",
                    job.keypoints[i]
                )
                .into());
            }
        }
        for s in &ours.skipped {
            if s.reason == SkipReason::OpencvBorder {
                tally.border_dropped += 1;
            }
            if s.reason == SkipReason::OpencvReadsOutsideImage && !kept_by_cv2.contains(&s.keypoint)
            {
                return Err(format!(
                    "{config}: keypoint {} was skipped as an out-of-bounds read but cv2 drops it",
                    s.keypoint
                )
                .into());
            }
        }
    }
    Ok(tally)
}

fn latch(bytes: usize, rotation: bool, half: usize, sigma: f64) -> OpencvLatch {
    OpencvLatch::new(bytes, rotation, half, sigma).expect("valid settings")
}

fn random_keypoints(image: &Gray, count: usize, seed: u64) -> Vec<KeyPoint> {
    common::random_subpixel_keypoints(image.width, image.height, count, seed)
}

/// Our FAST keypoints (angles from the detector).
fn fast_keypoints(image: &Gray) -> Vec<KeyPoint> {
    Extractor::new(Backend::Cpu, ExtractorConfig::default())
        .and_then(|e| e.detect(&image.view()))
        .expect("detection on a valid image")
}

fn astronaut_every_configuration() -> Result<(), Failed> {
    let image = astronaut();
    let mut keypoints = fast_keypoints(&image);
    keypoints.truncate(1500);
    keypoints.extend(random_keypoints(&image, 1500, 1));
    let mut jobs = Vec::new();
    for bytes in clatch::describe::opencv::OPENCV_BYTES {
        for rotation in [true, false] {
            for sigma in [0.0, 2.0] {
                jobs.push(Job {
                    image: &image,
                    keypoints: &keypoints,
                    latch: latch(bytes, rotation, 3, sigma),
                });
            }
        }
    }
    compare(&jobs)?.report("astronaut, 7 widths x rotation on/off x sigma 0/2");
    Ok(())
}

fn random_images() -> Result<(), Failed> {
    let noise = Gray::new(
        clatch::synthetic::noise(640, 480, 3).expect("synthetic image"),
        640,
        480,
    );
    let blocks = rectangles(800, 600, 4);
    let keypoints_noise = random_keypoints(&noise, 6000, 5);
    let mut keypoints_blocks = fast_keypoints(&blocks);
    keypoints_blocks.truncate(3000);
    keypoints_blocks.extend(random_keypoints(&blocks, 3000, 6));
    let mut jobs = Vec::new();
    for (image, keypoints) in [(&noise, &keypoints_noise), (&blocks, &keypoints_blocks)] {
        for (rotation, sigma) in [(true, 2.0), (false, 0.0), (true, 0.0), (false, 2.0)] {
            jobs.push(Job {
                image,
                keypoints,
                latch: latch(64, rotation, 3, sigma),
            });
        }
    }
    compare(&jobs)?.report("noise 640x480 and rectangles 800x600, 64 bytes");
    Ok(())
}

/// True when the two candidate rules for OpenCV's `float cos_theta = cos(angle)`, the `double` `cos`
/// rounded to `f32` (what OpenCV does) and the platform's `f32` `cosf` (what it would do with a float
/// overload), place some patch centre differently at this angle: the angles that tell them apart.
/// Computed here independently of the library, so a wrong rule in the library fails on them.
fn rules_differ(angle: f32) -> bool {
    let r = angle * (std::f64::consts::PI / 180.0) as f32;
    let double = ((r as f64).cos() as f32, (r as f64).sin() as f32);
    let float = (r.cos(), r.sin());
    let place = |(c, s): (f32, f32), x: f32, y: f32| {
        (
            ((x * c - y * s) as i32).clamp(-24, 24),
            ((x * s + y * c) as i32).clamp(-24, 24),
        )
    };
    double != float
        && clatch::describe::opencv::OPENCV_CENTRES.iter().any(|t| {
            [0, 2, 4].into_iter().any(|i| {
                let (x, y) = (t[i] as f32, t[i + 1] as f32);
                place(double, x, y) != place(float, x, y)
            })
        })
}

fn angles() -> Result<(), Failed> {
    let image = Gray::new(
        clatch::synthetic::noise(300, 300, 8).expect("synthetic image"),
        300,
        300,
    );
    // Every 0.01 degree in [-360, 360], then angles where a float cosf/sinf would give other bits.
    let mut angles: Vec<f32> = (-36_000..=36_000).map(|i| i as f32 / 100.0).collect();
    let mut telling = 0;
    let mut bits = 0.001f32.to_bits();
    while f32::from_bits(bits) <= 720.0 && telling < 300 {
        for angle in [f32::from_bits(bits), -f32::from_bits(bits)] {
            if rules_differ(angle) {
                angles.push(angle);
                telling += 1;
            }
        }
        bits += 11;
    }
    let mut rng = SplitMix64::new(9);
    let keypoints: Vec<KeyPoint> = angles
        .iter()
        .map(|&a| {
            KeyPoint::new(
                100.0 + rng.below(100 * 16) as f32 / 16.0,
                100.0 + rng.below(100 * 16) as f32 / 16.0,
            )
            .with_angle(a)
        })
        .collect();
    let jobs = [Job {
        image: &image,
        keypoints: &keypoints,
        latch: latch(64, true, 3, 0.0),
    }];
    compare(&jobs)?.report(&format!(
        "{} angles (every 0.01 degree in [-360, 360], and {telling} where a float cosf would give other bits)",
        angles.len()
    ));
    Ok(())
}

fn sigmas() -> Result<(), Failed> {
    let image = astronaut();
    let keypoints = random_keypoints(&image, 800, 10);
    let sigma_list = [
        0.1, 0.3, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 5.0, 7.5, 10.0,
        100.0, 1e6, -1.0, -2.0,
    ];
    let mut jobs: Vec<Job> = sigma_list
        .iter()
        .map(|&sigma| Job {
            image: &image,
            keypoints: &keypoints,
            latch: latch(64, true, 3, sigma),
        })
        .collect();
    // Sigmas whose kernel weight sits just either side of a rounding step (k · 256 near x.5).
    let mut rng = SplitMix64::new(11);
    let random_sigmas: Vec<f64> = (0..30)
        .map(|_| 0.2 + rng.below(1_000_000) as f64 / 100_000.0)
        .collect();
    for &sigma in &random_sigmas {
        jobs.push(Job {
            image: &image,
            keypoints: &keypoints,
            latch: latch(64, true, 3, sigma),
        });
    }
    compare(&jobs)?.report(&format!(
        "{} sigmas (fixed list and 30 random in [0.2, 10.2])",
        jobs.len()
    ));
    Ok(())
}

fn half_ssd_sizes() -> Result<(), Failed> {
    let image = rectangles(400, 300, 12);
    let keypoints = random_keypoints(&image, 1000, 13);
    let jobs: Vec<Job> = [0, 1, 2, 4, 5, 8, 12, 24]
        .into_iter()
        .flat_map(|half| {
            [true, false].map(|rotation| Job {
                image: &image,
                keypoints: &keypoints,
                latch: latch(32, rotation, half, 2.0),
            })
        })
        .collect();
    compare(&jobs)?.report("half_ssd_size 0, 1, 2, 4, 5, 8, 12, 24");
    Ok(())
}

fn borders() -> Result<(), Failed> {
    // Every position on a quarter-pixel grid across the border zones, both edges, both axes, on images
    // with even and odd sizes (the out-of-bounds case needs W - 28 even).
    let mut total = Tally::default();
    for (w, h, seed) in [(200usize, 150usize, 14u64), (201, 151, 15)] {
        let image = Gray::new(
            clatch::synthetic::noise(w, h, seed).expect("synthetic image"),
            w,
            h,
        );
        let mut keypoints = Vec::new();
        for half in [0usize, 3, 6] {
            let b = 24.0 + half as f32;
            let zone = |len: usize| -> Vec<f32> {
                let far = len as f32 - 1.0 - b;
                (-12..=12)
                    .flat_map(|q| [b + q as f32 / 4.0, far + q as f32 / 4.0])
                    .chain([b - 0.5, b + 0.5, far - 0.5, far + 0.5, far + 1.5])
                    .filter(|&v| v >= 0.0)
                    .collect()
            };
            let (xs, ys) = (zone(w), zone(h));
            for (k, &x) in xs.iter().enumerate() {
                keypoints.push(KeyPoint::new(x, h as f32 / 2.0 + 0.5).with_angle(k as f32 * 7.3));
                keypoints.push(KeyPoint::new(x, ys[k % ys.len()]).with_angle(-1.0));
            }
            for (k, &y) in ys.iter().enumerate() {
                keypoints.push(KeyPoint::new(w as f32 / 2.0 - 0.5, y).with_angle(k as f32 * 3.1));
            }
        }
        let store: Vec<(OpencvLatch, Vec<KeyPoint>)> = [0usize, 3, 6]
            .into_iter()
            .flat_map(|half| {
                [(true, 2.0), (false, 0.0)].map(|(r, s)| (latch(8, r, half, s), keypoints.clone()))
            })
            .collect();
        let jobs: Vec<Job> = store
            .iter()
            .map(|(l, kps)| Job {
                image: &image,
                keypoints: kps,
                latch: l.clone(),
            })
            .collect();
        total.add(compare(&jobs)?);
    }
    if total.unsafe_skipped == 0 {
        return Err("no keypoint exercised OpenCV's out-of-bounds half-pixel case".into());
    }
    total.report("border zones, quarter-pixel grid, half_ssd_size 0/3/6");
    Ok(())
}

fn extra_images() -> Result<(), Failed> {
    python_with_cv2().map_err(|e| format!("skipped: opencv-contrib-python not installed ({e})"))?;
    let paths = std::env::var(EXTRA_IMAGES).unwrap_or_default();
    let mut total = Tally::default();
    for path in paths.split(':').filter(|p| !p.is_empty()) {
        let decoded = image::open(path).map_err(|e| format!("{path}: {e}"))?;
        let gray = clatch::decode::gray_from_dynamic(&decoded);
        let (w, h) = (gray.width() as usize, gray.height() as usize);
        let image = Gray::new(gray.into_raw(), w, h);
        let mut keypoints = fast_keypoints(&image);
        keypoints.truncate(5000);
        keypoints.extend(random_keypoints(&image, 2000, 16));
        let jobs: Vec<Job> = [(64, true, 2.0), (32, true, 0.0), (64, false, 2.0)]
            .into_iter()
            .map(|(bytes, rotation, sigma)| Job {
                image: &image,
                keypoints: &keypoints,
                latch: latch(bytes, rotation, 3, sigma),
            })
            .collect();
        let tally = compare(&jobs)?;
        tally.report(&format!("{path} ({w}x{h})"));
        total.add(tally);
    }
    total.report("extra images, in all");
    Ok(())
}
