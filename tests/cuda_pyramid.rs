//! The GPU pyramid against the CPU reference, bit for bit: every level's pixels, then keypoints
//! (position, size, angle, response, octave, order) and descriptors of multi-scale extraction.
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
    common::gpu::feature_missing("cuda_pyramid")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("pyramid_levels_pixel_for_pixel", gpu::levels),
        Trial::test("pyramid_detect_equals_cpu", gpu::detect),
        Trial::test(
            "pyramid_detect_and_describe_equals_cpu",
            gpu::detect_and_describe,
        ),
        Trial::test(
            "pyramid_async_on_several_streams_equals_cpu",
            gpu::async_streams,
        ),
        Trial::test("selection_grid_and_level_shares_equal_cpu", gpu::selection),
        Trial::test("subpixel_positions_equal_cpu", gpu::subpixel),
        Trial::test(
            "pyramid_smoothed_description_equals_cpu",
            gpu::smoothed_description,
        ),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::pyramid::{Plan, cpu::build_levels};
    use clatch::{Backend, DetectorConfig, Extractor, ExtractorConfig, GrayView, Pyramid};
    use libtest_mimic::Failed;

    use super::common::{Gray, astronaut, first_keypoint_difference, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    /// Under CLATCH_TEST_SCALE=sanitizer, the photograph and the odd-sized rectangles only.
    fn images() -> Vec<(&'static str, Gray)> {
        let mut images = vec![
            ("astronaut", astronaut()),
            ("rectangles 1920x1080", rectangles(1920, 1080, 8)),
            ("rectangles 333x517", rectangles(333, 517, 2)),
            (
                "noise 1023x769",
                Gray::new(
                    clatch::synthetic::noise(1023, 769, 6).expect("synthetic image"),
                    1023,
                    769,
                ),
            ),
        ];
        if scale::sanitizer() {
            images.retain(|(name, _)| *name == "astronaut" || *name == "rectangles 333x517");
        }
        images
    }

    fn pyramids() -> Vec<Pyramid> {
        [(5, 2.0f32), (8, 1.2), (4, 1.5), (3, 1.999), (6, 1.0001)]
            .into_iter()
            .map(|(levels, scale_factor)| Pyramid::new(levels, scale_factor))
            .collect()
    }

    fn extractor(backend: Backend, detector: &DetectorConfig, pyramid: Pyramid) -> Extractor {
        Extractor::new(
            backend,
            ExtractorConfig::default()
                .with_detector(detector.clone())
                .with_pyramid(Some(pyramid)),
        )
        .expect("valid configuration")
    }

    fn detectors() -> Vec<DetectorConfig> {
        let mut out = Vec::new();
        for threshold in [5u8, 20, 80] {
            for max_keypoints in [1usize, 300, 5000, usize::MAX] {
                out.push(
                    DetectorConfig::default()
                        .with_threshold(threshold)
                        .with_max_keypoints(max_keypoints),
                );
            }
        }
        out.push(DetectorConfig::default().with_keypoint_size(16.0));
        out
    }

    pub fn levels() -> Result<(), Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        let mut count = 0;
        for (name, image) in images() {
            for p in pyramids() {
                for margin in [16usize, 48] {
                    let view = image.view();
                    let plan = Plan::new(&p, image.width, image.height, margin);
                    let mut cpu = vec![image.pixels.clone()];
                    cpu.extend(build_levels(&view, &plan));
                    let gpu = clatch::cuda::hooks::debug_pyramid_levels(&dev, &view, &p, margin)?;
                    if cpu != gpu {
                        let level = cpu.iter().zip(&gpu).position(|(c, g)| c != g);
                        return Err(format!(
                            "{name} {p:?} margin {margin}: levels differ (cpu {}, gpu {}, first differing level {level:?})",
                            cpu.len(),
                            gpu.len()
                        )
                        .into());
                    }
                    count += cpu.len() - 1;
                }
            }
        }
        println!("{count} pyramid levels equal pixel for pixel");
        Ok(())
    }

    pub fn detect() -> Result<(), Failed> {
        let (mut runs, mut keypoints) = (0, 0);
        for (name, image) in images() {
            for p in scale::thin(pyramids(), 2) {
                for detector in scale::thin(detectors(), 5) {
                    let view: GrayView = image.view();
                    let cpu = extractor(Backend::Cpu, &detector, p).detect(&view)?;
                    let gpu = extractor(GPU, &detector, p).detect(&view)?;
                    if let Some(i) = first_keypoint_difference(&cpu, &gpu) {
                        return Err(format!(
                            "{name} {p:?} {detector:?}: cpu {} keypoints, gpu {}; first difference at {i}: cpu {:?}, gpu {:?}",
                            cpu.len(),
                            gpu.len(),
                            cpu.get(i),
                            gpu.get(i)
                        )
                        .into());
                    }
                    runs += 1;
                    keypoints += cpu.len();
                }
            }
        }
        println!("{runs} multi-scale detections, {keypoints} keypoints, 0 differences");
        Ok(())
    }

    /// Demands the same keypoints and descriptors from the CPU and the GPU; `label` names the case.
    fn same_features(
        label: &str,
        cpu: &clatch::Features,
        gpu: &clatch::Features,
    ) -> Result<(), Failed> {
        if let Some(i) = first_keypoint_difference(&cpu.keypoints, &gpu.keypoints) {
            return Err(format!(
                "{label}: keypoints differ at {i}: cpu {:?}, gpu {:?}",
                cpu.keypoints.get(i),
                gpu.keypoints.get(i)
            )
            .into());
        }
        if let Some(i) =
            (0..cpu.descriptors.len()).find(|&i| cpu.descriptors.get(i) != gpu.descriptors.get(i))
        {
            return Err(format!(
                "{label}: descriptor {i} of {} differs (keypoint {:?})",
                cpu.descriptors.len(),
                cpu.keypoints[i]
            )
            .into());
        }
        if cpu.descriptors.len() != gpu.descriptors.len() {
            return Err(format!("{label}: descriptor counts differ").into());
        }
        Ok(())
    }

    /// Prints what a multi-scale comparison covered; an error if no keypoint came from above level 0.
    fn covered(what: &str, runs: usize, descriptors: usize, upper: usize) -> Result<(), Failed> {
        println!("{runs} {what}, {descriptors} descriptors ({upper} above level 0), 0 differences");
        if upper == 0 {
            return Err("no keypoint above level 0: the comparison proved nothing".into());
        }
        Ok(())
    }

    pub fn detect_and_describe() -> Result<(), Failed> {
        let (mut runs, mut descriptors, mut upper) = (0, 0, 0);
        for (name, image) in images() {
            for p in scale::thin(pyramids(), 2) {
                for detector in [DetectorConfig::default(), detectors()[0].clone()] {
                    let view = image.view();
                    let cpu = extractor(Backend::Cpu, &detector, p).detect_and_describe(&view)?;
                    let gpu = extractor(GPU, &detector, p).detect_and_describe(&view)?;
                    same_features(&format!("{name} {p:?} {detector:?}"), &cpu, &gpu)?;
                    runs += 1;
                    descriptors += cpu.descriptors.len();
                    upper += cpu.keypoints.iter().filter(|k| k.octave > 0).count();
                }
            }
        }
        covered("multi-scale extractions", runs, descriptors, upper)
    }

    /// Spreading over a grid and ORB's level shares (host selection over the device's candidates,
    /// every corner with a grid), with and without a pyramid, blocking and asynchronous.
    pub fn selection() -> Result<(), Failed> {
        use clatch::{LevelBudget, Ranking};
        let stream = clatch::cuda::GpuStream::new(0)?;
        let (mut runs, mut keypoints) = (0, 0);
        for (name, image) in images() {
            for p in [None, Some(pyramids()[0]), Some(Pyramid::new(8, 1.2))]
                .into_iter()
                .take(scale::pick(3, 2))
            {
                for (grid, level_budget, ranking) in [
                    (8, LevelBudget::Global, Ranking::Fast),
                    (1, LevelBudget::Geometric, Ranking::Fast),
                    (4, LevelBudget::Geometric, Ranking::Fast),
                    (1, LevelBudget::Global, Ranking::Harris),
                    (1, LevelBudget::Geometric, Ranking::Harris),
                ] {
                    let detector = DetectorConfig::default()
                        .with_grid(grid)
                        .with_level_budget(level_budget)
                        .with_ranking(ranking)
                        .with_max_keypoints(scale::pick(700, 150));
                    let config = ExtractorConfig::default()
                        .with_detector(detector)
                        .with_pyramid(p);
                    let view = image.view();
                    let cpu =
                        Extractor::new(Backend::Cpu, config.clone())?.detect_and_describe(&view)?;
                    let gpu = Extractor::new(GPU, config.clone())?;
                    let blocking = gpu.detect_and_describe(&view)?;
                    let queued = gpu.detect_and_describe_async(&stream, &view)?.wait()?;
                    for (how, got) in [("blocking", &blocking), ("asynchronous", &queued)] {
                        if first_keypoint_difference(&cpu.keypoints, &got.keypoints).is_some()
                            || cpu.descriptors != got.descriptors
                        {
                            return Err(format!(
                                "{name} {p:?} grid {grid} {level_budget:?} {ranking:?} ({how}): differs from the CPU"
                            )
                            .into());
                        }
                    }
                    runs += 1;
                    keypoints += cpu.keypoints.len();
                }
            }
        }
        println!(
            "{runs} selections (grid, level shares, Harris ranking), {keypoints} keypoints, 0 differences"
        );
        Ok(())
    }

    /// Each level smoothed before its keypoints are described, blocking and asynchronous, with plain
    /// pyramids and with ORB's level shares: keypoints (found on the unsmoothed levels) and
    /// descriptors equal the CPU's, and the smoothing changed the descriptors.
    pub fn smoothed_description() -> Result<(), Failed> {
        use clatch::{DescriptorConfig, LevelBudget, Smoothing};
        let stream = clatch::cuda::GpuStream::new(0)?;
        let (mut runs, mut descriptors, mut upper) = (0, 0, 0);
        for (name, image) in images() {
            for p in scale::thin(pyramids().into_iter().take(3), 2) {
                for level_budget in [LevelBudget::Global, LevelBudget::Geometric] {
                    let detector = DetectorConfig::default()
                        .with_level_budget(level_budget)
                        .with_max_keypoints(scale::pick(3000, 300));
                    let view = image.view();
                    let plain = extractor(Backend::Cpu, &detector, p).detect_and_describe(&view)?;
                    for smoothing in [Smoothing::Binomial3, Smoothing::Binomial5] {
                        let config = ExtractorConfig::default()
                            .with_detector(detector.clone())
                            .with_descriptor(DescriptorConfig::default().with_smoothing(smoothing))
                            .with_pyramid(Some(p));
                        let cpu = Extractor::new(Backend::Cpu, config.clone())?
                            .detect_and_describe(&view)?;
                        let gpu = Extractor::new(GPU, config)?;
                        let blocking = gpu.detect_and_describe(&view)?;
                        let queued = gpu.detect_and_describe_async(&stream, &view)?.wait()?;
                        for (how, got) in [("blocking", &blocking), ("asynchronous", &queued)] {
                            let label =
                                format!("{name} {p:?} {level_budget:?} {smoothing:?} ({how})");
                            same_features(&label, &cpu, got)?;
                        }
                        if first_keypoint_difference(&cpu.keypoints, &plain.keypoints).is_some() {
                            return Err(
                                format!("{name} {p:?}: smoothing moved the keypoints").into()
                            );
                        }
                        if !cpu.descriptors.is_empty() && cpu.descriptors == plain.descriptors {
                            return Err(format!(
                                "{name} {p:?}: {smoothing:?} changed no descriptor"
                            )
                            .into());
                        }
                        runs += 1;
                        descriptors += cpu.descriptors.len();
                        upper += cpu.keypoints.iter().filter(|k| k.octave > 0).count();
                    }
                }
            }
        }
        covered("smoothed multi-scale extractions", runs, descriptors, upper)
    }

    pub fn async_streams() -> Result<(), Failed> {
        // Every image with two pyramids queued at once, round-robin over three streams, then waited
        // for in order: each result equals the CPU's.
        let streams = (0..3)
            .map(|_| clatch::cuda::GpuStream::new(0))
            .collect::<Result<Vec<_>, _>>()?;
        let images = images();
        let two = &pyramids()[..2];
        let jobs: Vec<(&str, &Gray, Pyramid)> = images
            .iter()
            .flat_map(|(name, image)| two.iter().map(move |&p| (*name, image, p)))
            .collect();
        let detector = DetectorConfig::default();
        let pending = jobs
            .iter()
            .zip(streams.iter().cycle())
            .map(|((_, image, p), stream)| {
                extractor(GPU, &detector, *p).detect_and_describe_async(stream, &image.view())
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut descriptors = 0;
        for ((name, image, p), pending) in jobs.iter().zip(pending) {
            let gpu = pending.wait()?;
            let cpu = extractor(Backend::Cpu, &detector, *p).detect_and_describe(&image.view())?;
            if first_keypoint_difference(&cpu.keypoints, &gpu.keypoints).is_some()
                || cpu.descriptors != gpu.descriptors
            {
                return Err(format!(
                    "{name} {p:?}: the asynchronous result differs from the CPU's"
                )
                .into());
            }
            descriptors += cpu.descriptors.len();
        }
        println!(
            "{} asynchronous multi-scale extractions on 3 streams, {descriptors} descriptors, 0 differences",
            jobs.len()
        );
        Ok(())
    }

    /// Sub-pixel positions (`Subpixel::Score`), single-scale and on pyramids, with the selection
    /// options: keypoints bit for bit (the refined positions), descriptors equal to the CPU's and to
    /// the unrefined run's, from `detect`, `detect_and_describe` and the asynchronous path.
    pub fn subpixel() -> Result<(), Failed> {
        use clatch::{LevelBudget, Subpixel};
        let stream = clatch::cuda::GpuStream::new(0)?;
        let (mut runs, mut keypoints, mut moved) = (0, 0, 0);
        for (name, image) in images() {
            // CLATCH_TEST_SCALE=sanitizer: the first and last of each list.
            let chosen_pyramids = scale::thin(
                vec![
                    None,
                    Some(pyramids()[0]),
                    Some(pyramids()[1]),
                    Some(pyramids()[4]),
                ],
                3,
            );
            let selections = scale::thin(
                vec![
                    (1, LevelBudget::Global, 5000),
                    (1, LevelBudget::Global, usize::MAX),
                    (4, LevelBudget::Geometric, 700),
                ],
                2,
            );
            for &p in &chosen_pyramids {
                for &(grid, level_budget, max_keypoints) in &selections {
                    let detector = DetectorConfig::default()
                        .with_grid(grid)
                        .with_level_budget(level_budget)
                        .with_max_keypoints(max_keypoints)
                        .with_subpixel(Subpixel::Score);
                    let config = ExtractorConfig::default()
                        .with_detector(detector.clone())
                        .with_pyramid(p);
                    let whole_config = config
                        .clone()
                        .with_detector(detector.with_subpixel(Subpixel::None));
                    let view = image.view();
                    let cpu =
                        Extractor::new(Backend::Cpu, config.clone())?.detect_and_describe(&view)?;
                    let gpu = Extractor::new(GPU, config.clone())?;
                    let detected = gpu.detect(&view)?;
                    let blocking = gpu.detect_and_describe(&view)?;
                    let queued = gpu.detect_and_describe_async(&stream, &view)?.wait()?;
                    let whole = Extractor::new(GPU, whole_config)?.detect_and_describe(&view)?;
                    let results = [
                        ("detect", &detected, None),
                        ("blocking", &blocking.keypoints, Some(&blocking.descriptors)),
                        ("asynchronous", &queued.keypoints, Some(&queued.descriptors)),
                    ];
                    for (how, got, descriptors) in results {
                        let keypoint = first_keypoint_difference(&cpu.keypoints, got);
                        let descriptors_differ = descriptors.is_some_and(|d| {
                            *d != cpu.descriptors || whole.descriptors != cpu.descriptors
                        });
                        if keypoint.is_some() || descriptors_differ {
                            let at = keypoint.map(|i| (i, cpu.keypoints.get(i), got.get(i)));
                            return Err(format!(
                                "{name} {p:?} grid {grid} {level_budget:?} ({how}): first keypoint difference \
                                 (index, cpu, gpu) {at:?}, descriptors differ: {descriptors_differ}"
                            )
                            .into());
                        }
                    }
                    runs += 1;
                    keypoints += cpu.keypoints.len();
                    moved += cpu
                        .keypoints
                        .iter()
                        .zip(&whole.keypoints)
                        .filter(|(r, w)| (r.x, r.y) != (w.x, w.y))
                        .count();
                }
            }
        }
        println!(
            "{runs} sub-pixel extractions, {keypoints} keypoints ({moved} moved off the whole pixel), 0 differences"
        );
        if moved == 0 {
            return Err("no keypoint moved: the comparison proved nothing".into());
        }
        Ok(())
    }
}
