//! GPU detection against the CPU reference, keypoint for keypoint: position, size, angle, response,
//! octave and order, compared bit for bit, ties included, plus the golden file's `detect` section.
//!
//! Runs only with the `cuda` feature and a device; otherwise every test is reported as ignored with
//! `skipped: no CUDA device`, never as passed.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_detect")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("detect_stage_by_stage", gpu::stage_by_stage),
        Trial::test("detect_reproduces_golden_file", gpu::golden_file),
        Trial::test(
            "detect_astronaut_thresholds_limits_sizes",
            gpu::astronaut_grid,
        ),
        Trial::test("detect_tiny_images", gpu::tiny_images),
        Trial::test("detect_1080p", gpu::hd_images),
        Trial::test("detect_5616x3744", gpu::full_frame),
        Trial::test("detect_plateaus_and_tied_cuts", gpu::plateaus_and_ties),
        Trial::test("detect_flat_image_finds_nothing", gpu::flat_images),
        Trial::test("detect_images_around_twice_the_margin", gpu::margin_edges),
        Trial::test("detect_widest_and_tallest_images", gpu::extreme_shapes),
        Trial::test(
            "subpixel_offsets_every_pixel_and_border_equal_cpu",
            gpu::subpixel_offsets,
        ),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::synthetic::SplitMix64;
    use clatch::{Backend, DetectorConfig, Extractor, ExtractorConfig, GrayView, KeyPoint};
    use libtest_mimic::Failed;

    use super::common::golden::{golden_path, render};
    use super::common::{Gray, astronaut, first_keypoint_difference, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };
    const THRESHOLDS: [u8; 5] = [1, 5, 20, 80, 254];
    const LIMITS: [usize; 5] = [1, 10, 500, 100_000, usize::MAX];
    const SIZES: [f32; 3] = [16.0, 64.0, 200.0];

    /// Single-level detection (`ExtractorConfig::single_scale`): this file checks the detector's own
    /// stages and top-N cut; pyramids, level budgets and sub-pixel positions are `cuda_pyramid`'s.
    fn config(threshold: u8, max_keypoints: usize, keypoint_size: f32) -> DetectorConfig {
        ExtractorConfig::single_scale()
            .detector
            .with_threshold(threshold)
            .with_max_keypoints(max_keypoints)
            .with_keypoint_size(keypoint_size)
    }

    fn detect(backend: Backend, image: &GrayView, config: &DetectorConfig) -> Vec<KeyPoint> {
        let extractor = Extractor::new(
            backend,
            ExtractorConfig::single_scale().with_detector(config.clone()),
        )
        .expect("valid configuration");
        extractor.detect(image).expect("detection runs")
    }

    /// Detects on both backends and demands identical lists; returns the CPU's list.
    fn compare(
        what: &str,
        image: &GrayView,
        config: &DetectorConfig,
    ) -> Result<Vec<KeyPoint>, Failed> {
        let cpu = detect(Backend::Cpu, image, config);
        let gpu = detect(GPU, image, config);
        if let Some(i) = first_keypoint_difference(&cpu, &gpu) {
            return Err(format!(
                "{what} {}x{} {config:?}: cpu {} keypoints, gpu {}; first difference at {i}: cpu {:?}, gpu {:?}",
                image.width(),
                image.height(),
                cpu.len(),
                gpu.len(),
                cpu.get(i),
                gpu.get(i)
            )
            .into());
        }
        Ok(cpu)
    }

    /// Runs `compare` for every (threshold, limit, size) given; returns (comparisons, keypoints).
    fn grid(
        what: &str,
        image: &GrayView,
        thresholds: &[u8],
        limits: &[usize],
        sizes: &[f32],
    ) -> Result<(usize, usize), Failed> {
        let (mut runs, mut keypoints) = (0, 0);
        // CLATCH_TEST_SCALE=sanitizer: every other value of each list, the first and last kept.
        let thresholds = &scale::thin(thresholds.to_vec(), 2)[..];
        let limits = &scale::thin(limits.to_vec(), 2)[..];
        let sizes = &scale::thin(sizes.to_vec(), 2)[..];
        for &t in thresholds {
            for &n in limits {
                for &s in sizes {
                    keypoints += compare(what, image, &config(t, n, s))?.len();
                    runs += 1;
                }
            }
        }
        Ok((runs, keypoints))
    }

    fn noise(width: usize, height: usize, seed: u64) -> Gray {
        Gray::new(
            clatch::synthetic::noise(width, height, seed).expect("synthetic image"),
            width,
            height,
        )
    }

    fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> u8) -> Gray {
        Gray::new(
            (0..width * height)
                .map(|i| f(i % width, i / width))
                .collect(),
            width,
            height,
        )
    }

    /// Black and white squares of side `side`: every crossing scores 255 at many pixels at once.
    fn checkerboard(width: usize, height: usize, side: usize) -> Gray {
        from_fn(width, height, |x, y| {
            if (x / side + y / side).is_multiple_of(2) {
                0
            } else {
                255
            }
        })
    }

    /// A random 16x16 noise tile repeated: every score recurs every 16 pixels along a row and down a
    /// column, so equal scores must be ranked within rows and across rows.
    fn tiled(width: usize, height: usize, seed: u64) -> Gray {
        let tile = clatch::synthetic::noise(16, 16, seed).expect("synthetic image");
        from_fn(width, height, |x, y| tile[(y % 16) * 16 + x % 16])
    }

    /// Identical bright blobs of 1x1 to 3x3 pixels on black, on a jittered grid: each blob is a
    /// plateau of equal FAST scores (suppression must keep its first pixel in raster order), and every
    /// blob of a given shape scores the same.
    fn blobs(width: usize, height: usize, seed: u64) -> Gray {
        let mut rng = SplitMix64::new(seed);
        let mut pixels = vec![0u8; width * height];
        for gy in (4..height.saturating_sub(8)).step_by(9) {
            for gx in (4..width.saturating_sub(8)).step_by(9) {
                let (x0, y0) = (gx + rng.below(3) as usize, gy + rng.below(3) as usize);
                let (w, h) = (1 + rng.below(3) as usize, 1 + rng.below(3) as usize);
                let level = [90u8, 180, 250][rng.below(3) as usize];
                for y in y0..y0 + h {
                    pixels[y * width + x0..y * width + x0 + w].fill(level);
                }
            }
        }
        Gray::new(pixels, width, height)
    }

    /// Each stage's buffers against the CPU's intermediate results (texture reads, suppression,
    /// scan, scatter, orientation), reporting the first differences of each.
    pub fn stage_by_stage() -> Result<(), Failed> {
        use clatch::detect::cpu::{score_map, suppress_non_maxima};
        let mut failures = Vec::new();
        for (what, image, cfg) in [
            ("noise", noise(64, 64, 64064), config(1, usize::MAX, 16.0)),
            ("noise", noise(300, 260, 5), config(20, 100, 64.0)),
            (
                "astronaut",
                astronaut(),
                ExtractorConfig::single_scale().detector,
            ),
        ] {
            let view = image.view();
            let (w, h) = (image.width, image.height);
            let dev = clatch::cuda::hooks::device(0)?;
            let st = clatch::cuda::hooks::debug_detect_stages(&dev, &view, &cfg)?;
            let mut report = Vec::new();
            let bad_texels: Vec<usize> = (0..w * h)
                .filter(|&i| st.texture[i] != image.pixels[i])
                .collect();
            if let Some(&i) = bad_texels.first() {
                report.push(format!(
                    "texture: {} of {} texels differ; first ({}, {}): gpu {} cpu {}",
                    bad_texels.len(),
                    w * h,
                    i % w,
                    i / w,
                    st.texture[i],
                    image.pixels[i]
                ));
            }
            let scores = score_map(&view, cfg.threshold, cfg.margin());
            let kept = suppress_non_maxima(&scores, w, h);
            let mut expected = vec![0u8; w * h];
            for &(x, y, s) in &kept {
                expected[y as usize * w + x as usize] = s;
            }
            let mut bad = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    if st.kept[y * st.pitch + x] != expected[y * w + x] {
                        bad.push((x, y));
                    }
                }
            }
            for &(x, y) in bad.iter().take(4) {
                let around: Vec<Vec<u8>> = (y.saturating_sub(3)..(y + 4).min(h))
                    .map(|yy| {
                        (x.saturating_sub(3)..(x + 4).min(w))
                            .map(|xx| image.pixels[yy * w + xx])
                            .collect()
                    })
                    .collect();
                let gpu_row: Vec<u8> = (x.saturating_sub(3)..(x + 4).min(w))
                    .map(|xx| st.kept[y * st.pitch + xx])
                    .collect();
                report.push(format!(
                    "kept ({x}, {y}): gpu {} cpu kept {} cpu score {}; gpu kept row {gpu_row:?}; pixels {around:?}",
                    st.kept[y * st.pitch + x],
                    expected[y * w + x],
                    scores[y * w + x]
                ));
            }
            if !bad.is_empty() {
                report.push(format!("kept: {} pixels differ", bad.len()));
            }
            let nonzero_pad = (0..h)
                .flat_map(|y| (w..st.pitch).map(move |x| (x, y)))
                .filter(|&(x, y)| st.kept[y * st.pitch + x] != 0)
                .count();
            if nonzero_pad > 0 {
                report.push(format!(
                    "kept: {nonzero_pad} non-zero bytes in the row padding"
                ));
            }
            let mut counts = vec![0u32; 255 * h];
            for &(_, y, s) in &kept {
                counts[(255 - s as usize) * h + y as usize] += 1;
            }
            let mut running = 0u32;
            let offsets: Vec<u32> = counts
                .iter()
                .map(|&c| {
                    running += c;
                    running - c
                })
                .collect();
            if st.total as usize != kept.len() {
                report.push(format!("total: gpu {} cpu {}", st.total, kept.len()));
            }
            if let Some(i) = (0..offsets.len()).find(|&i| st.offsets[i] != offsets[i]) {
                report.push(format!(
                    "offsets: first difference at score {} row {}: gpu {} cpu {}",
                    255 - i / h,
                    i % h,
                    st.offsets[i],
                    offsets[i]
                ));
            }
            let mut sorted = kept.clone();
            sorted.sort_unstable_by(|a, b| b.2.cmp(&a.2).then(a.1.cmp(&b.1)).then(a.0.cmp(&b.0)));
            sorted.truncate(cfg.max_keypoints);
            let scattered: Vec<(u32, u32, u8)> = st
                .scattered
                .iter()
                .map(|k| (k.x as u32, k.y as u32, k.response as u8))
                .collect();
            if scattered != sorted {
                let i = scattered.iter().zip(&sorted).position(|(a, b)| a != b);
                report.push(format!(
                    "scatter: gpu {} records, cpu {}; first difference at {i:?}: gpu {:?} cpu {:?}",
                    scattered.len(),
                    sorted.len(),
                    i.and_then(|i| scattered.get(i)),
                    i.and_then(|i| sorted.get(i))
                ));
            }
            let cpu = detect(Backend::Cpu, &view, &cfg);
            if cpu != st.keypoints {
                let i = cpu.iter().zip(&st.keypoints).position(|(a, b)| a != b);
                report.push(format!(
                    "keypoints: gpu {} cpu {}; first difference at {i:?}",
                    st.keypoints.len(),
                    cpu.len()
                ));
            }
            println!(
                "{what} {w}x{h}: {} survivors, {} keypoints; {}",
                kept.len(),
                cpu.len(),
                if report.is_empty() {
                    "every stage identical".to_string()
                } else {
                    report.join("\n    ")
                }
            );
            if !report.is_empty() {
                failures.push(what);
            }
        }
        if failures.is_empty() {
            Ok(())
        } else {
            Err(format!("stages differ for {failures:?}").into())
        }
    }

    pub fn golden_file() -> Result<(), Failed> {
        let image = astronaut();
        let expected = std::fs::read_to_string(golden_path())?;
        let got = render(&image, GPU);
        let section = |text: &str| -> Vec<String> {
            let mut lines = text.lines().skip_while(|l| !l.starts_with("detect "));
            let header = lines.next().unwrap_or_default().to_string();
            let n: usize = header["detect ".len().min(header.len())..]
                .parse()
                .unwrap_or(0);
            std::iter::once(header)
                .chain(lines.take(n).map(str::to_string))
                .collect()
        };
        let (want, have) = (section(&expected), section(&got));
        if want.len() < 2 {
            return Err("the golden file has no detect section".into());
        }
        if want != have {
            let line = want.iter().zip(&have).position(|(e, g)| e != g);
            return Err(format!(
                "GPU detect section differs from the golden file at line {line:?} ({} vs {} lines)",
                want.len(),
                have.len()
            )
            .into());
        }
        if expected != got {
            let line = expected.lines().zip(got.lines()).position(|(e, g)| e != g);
            return Err(format!("GPU output differs from the golden file at line {line:?}").into());
        }
        println!(
            "golden file reproduced: detect section of {} keypoints, {} lines in all",
            want.len() - 1,
            expected.lines().count()
        );
        Ok(())
    }

    pub fn astronaut_grid() -> Result<(), Failed> {
        let image = astronaut();
        let (runs, keypoints) = grid("astronaut", &image.view(), &THRESHOLDS, &LIMITS, &SIZES)?;
        println!("astronaut: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    pub fn tiny_images() -> Result<(), Failed> {
        let (mut runs, mut keypoints) = (0, 0);
        for (w, h) in [(64usize, 64usize), (100, 97)] {
            let seed = (w * 1000 + h) as u64;
            for (what, image) in [
                ("noise", noise(w, h, seed)),
                ("rectangles", rectangles(w, h, seed)),
                ("blobs", blobs(w, h, seed)),
                ("tiled", tiled(w, h, seed)),
                ("checkerboard", checkerboard(w, h, 5)),
            ] {
                let (r, k) = grid(what, &image.view(), &THRESHOLDS, &LIMITS, &SIZES)?;
                runs += r;
                keypoints += k;
            }
        }
        println!("64x64 and 100x97: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    pub fn hd_images() -> Result<(), Failed> {
        let (w, h) = scale::pick((1920, 1080), (384, 216));
        let (mut runs, mut keypoints) = (0, 0);
        for (what, image) in [
            ("noise", noise(w, h, 7)),
            ("rectangles", rectangles(w, h, 8)),
            ("blobs", blobs(w, h, 9)),
            ("tiled", tiled(w, h, 10)),
            ("checkerboard", checkerboard(w, h, 7)),
        ] {
            let view = image.view();
            let (r, k) = grid(what, &view, &THRESHOLDS, &[1, 500, usize::MAX], &[64.0])?;
            let (r2, k2) = grid(what, &view, &[20], &[10, 100_000], &[16.0, 200.0])?;
            runs += r + r2;
            keypoints += k + k2;
        }
        println!("{w}x{h}: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    pub fn full_frame() -> Result<(), Failed> {
        let (w, h) = scale::pick((5616, 3744), (702, 468));
        let (mut runs, mut keypoints) = (0, 0);
        let rect = rectangles(w, h, 11);
        for (t, n, s) in [
            (20u8, 20_000usize, 64.0f32),
            (20, usize::MAX, 64.0),
            (5, 100_000, 16.0),
            (80, usize::MAX, 200.0),
        ] {
            keypoints += compare("rectangles", &rect.view(), &config(t, n, s))?.len();
            runs += 1;
        }
        let image = noise(w, h, 12);
        for (t, n, s) in [(1u8, usize::MAX, 64.0f32), (20, 500, 16.0)] {
            keypoints += compare("noise", &image.view(), &config(t, n, s))?.len();
            runs += 1;
        }
        let image = tiled(w, h, 13);
        keypoints += compare("tiled", &image.view(), &config(20, 50_000, 64.0))?.len();
        runs += 1;
        println!("{w}x{h}: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    /// Images made of exact duplicates; the top-N cut is placed everywhere a run of equal scores
    /// starts or ends, and inside runs, so a tie is split at the cut.
    pub fn plateaus_and_ties() -> Result<(), Failed> {
        let (mut runs, mut keypoints) = (0, 0);
        for (what, image) in [
            ("blobs", blobs(300, 260, 1)),
            ("tiled", tiled(300, 260, 2)),
            ("checkerboard", checkerboard(300, 260, 6)),
            ("checkerboard", checkerboard(257, 203, 2)),
            ("rectangles", rectangles(300, 260, 3)),
        ] {
            let view = image.view();
            for &(t, s) in &scale::thin([(20u8, 64.0f32), (1, 16.0), (254, 16.0)], 2) {
                let all = compare(what, &view, &config(t, usize::MAX, s))?;
                keypoints += all.len();
                runs += 1;
                let mut cuts: Vec<usize> = (1..all.len())
                    .filter(|&i| all[i].response != all[i - 1].response)
                    .flat_map(|i| [i - 1, i, i + 1])
                    .collect();
                let mut rng = SplitMix64::new(all.len() as u64);
                cuts.extend((0..12).map(|_| 1 + rng.below(all.len().max(1) as u64) as usize));
                cuts.sort_unstable();
                cuts.dedup();
                for &n in cuts.iter().filter(|&&n| n >= 1).take(scale::pick(60, 6)) {
                    let few = compare(what, &view, &config(t, n, s))?;
                    if few[..] != all[..n.min(all.len())] {
                        return Err(format!("{what}: the first {n} are not a prefix").into());
                    }
                    keypoints += few.len();
                    runs += 1;
                }
            }
        }
        println!("plateaus and tied cuts: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    pub fn flat_images() -> Result<(), Failed> {
        let mut runs = 0;
        for (w, h) in [
            (64usize, 64usize),
            (100, 97),
            scale::pick((1920, 1080), (384, 216)),
        ] {
            for level in [0u8, 128, 255] {
                let image = from_fn(w, h, |_, _| level);
                for &t in &scale::thin(THRESHOLDS, 2) {
                    for &s in &scale::thin(SIZES, 2) {
                        let found = compare("flat", &image.view(), &config(t, usize::MAX, s))?;
                        if !found.is_empty() {
                            return Err(format!("{w}x{h} flat {level}: {found:?}").into());
                        }
                        runs += 1;
                    }
                }
            }
        }
        println!("flat images: {runs} configurations, 0 keypoints on both backends");
        Ok(())
    }

    /// Images just larger than twice the margin: a scored area of 0 to a few pixels, where the output
    /// capacity bound (one survivor per 2x2 block) is tight.
    pub fn margin_edges() -> Result<(), Failed> {
        let (mut runs, mut keypoints) = (0, 0);
        for (s, m) in [(16.0f32, 16usize), (64.0, 48), (200.0, 144)] {
            assert_eq!(config(20, 1, s).margin(), m);
            for extra in (0..6).step_by(scale::pick(1, 2)) {
                for (w, h) in [(2 * m + extra, 2 * m + 5), (2 * m + 7, 2 * m + extra)] {
                    let (w, h) = (w.max(64), h.max(64));
                    for seed in 0..scale::pick(3, 1) {
                        let image = noise(w, h, seed * 100 + extra as u64);
                        let (r, k) =
                            grid("noise", &image.view(), &[1, 20], &[1, usize::MAX], &[s])?;
                        runs += r;
                        keypoints += k;
                    }
                }
            }
        }
        println!("around twice the margin: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    pub fn extreme_shapes() -> Result<(), Failed> {
        let max = clatch::MAX_IMAGE_SIDE;
        let (mut runs, mut keypoints) = (0, 0);
        // CLATCH_TEST_SCALE=sanitizer: the widest and the tallest, one limit.
        let shapes = scale::pick(
            vec![(max, 64), (64, max), (max, 300)],
            vec![(max, 64), (64, max)],
        );
        for (w, h) in shapes {
            let image = noise(w, h, (w * 3 + h) as u64);
            let limits = scale::pick(&[1000, usize::MAX][..], &[1000]);
            let (r, k) = grid("noise", &image.view(), &[20], limits, &[16.0])?;
            runs += r;
            keypoints += k;
        }
        println!("widest and tallest: {runs} configurations, {keypoints} keypoints identical");
        Ok(())
    }

    /// `clatch_subpixel` against `detect::cpu::subpixel_offset` on every pixel of small images (the
    /// border rows and columns included, where both give 0), on random pixels of photos and noise,
    /// and on every detected keypoint at the lowest threshold (many non-peak and tied neighbours).
    pub fn subpixel_offsets() -> Result<(), Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        let mut rng = SplitMix64::new(29);
        let (mut compared, mut nonzero) = (0usize, 0usize);
        let mut images = vec![
            ("astronaut", astronaut()),
            ("rectangles 333x517", rectangles(333, 517, 2)),
        ];
        for (w, h) in [(9usize, 9usize), (17, 40), (64, 64), (101, 33)] {
            let pixels = clatch::synthetic::noise(w, h, (w * h) as u64).expect("synthetic image");
            images.push(("noise", Gray::new(pixels, w, h)));
            // Few grey levels: many equal scores, so many ties and non-peaks.
            let steps = (0..w * h).map(|_| 60 * rng.below(3) as u8).collect();
            images.push(("three levels", Gray::new(steps, w, h)));
        }
        for (name, image) in &images {
            let view = image.view();
            let (w, h) = (image.width, image.height);
            let mut points: Vec<KeyPoint> = if w * h <= 64 * 64 {
                (0..w * h)
                    .map(|i| KeyPoint::new((i % w) as f32, (i / w) as f32))
                    .collect()
            } else {
                (0..20_000)
                    .map(|_| KeyPoint::new(rng.below(w as u64) as f32, rng.below(h as u64) as f32))
                    .collect()
            };
            if w >= 64 && h >= 64 {
                let detected = Extractor::new(
                    Backend::Cpu,
                    ExtractorConfig::single_scale().with_detector(config(1, usize::MAX, 16.0)),
                )?
                .detect(&view)?;
                points.extend(detected);
            }
            let gpu = clatch::cuda::hooks::debug_subpixel_offsets(&dev, &view, &points)?;
            for (k, got) in points.iter().zip(&gpu) {
                let cpu = clatch::detect::cpu::subpixel_offset(&view, k.x as usize, k.y as usize);
                if cpu != *got {
                    return Err(format!(
                        "{name} {w}x{h} at ({}, {}): cpu {cpu:?}, gpu {got:?}",
                        k.x, k.y
                    )
                    .into());
                }
                nonzero += usize::from(cpu != [0, 0]);
            }
            compared += points.len();
        }
        println!("{compared} sub-pixel offsets ({nonzero} non-zero), 0 differences");
        if nonzero == 0 {
            return Err("every offset was 0: the comparison proved nothing".into());
        }
        Ok(())
    }
}
