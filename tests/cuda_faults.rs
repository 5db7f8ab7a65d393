//! GPU faults and concurrency: device memory exhaustion is a typed error that leaves the context
//! usable; the widest images the API accepts work through the texture path; many host threads, each
//! on its own stream, get exactly the CPU's results.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_faults")
}

/// A trial's body.
#[cfg(feature = "cuda")]
type Body = fn() -> Result<(), libtest_mimic::Failed>;

/// The trials run one at a time, although libtest-mimic runs trials on parallel threads: the
/// allocation-site trial empties the device's caches before each call
/// (`hooks::release_cached_memory`), descriptor weight tables included, which is valid only while no
/// other call is in flight: beside another trial it can free a weight table that trial's describe
/// kernels are still queued to read (cudarc frees without waiting for other streams).
/// `arena_growth_fails_cleanly` failed with that signature (the last levels' descriptors a few bits
/// off) in whole-binary runs under loaded sanitizers on 2026-12-02, never when run alone.
#[cfg(feature = "cuda")]
fn one_at_a_time(
    trial: Body,
) -> impl FnOnce() -> Result<(), libtest_mimic::Failed> + Send + 'static {
    static TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());
    move || {
        let _turn = TURN.lock().unwrap_or_else(|p| p.into_inner());
        trial()
    }
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    let trials: [(&str, Body); 8] = [
        ("out_of_memory_is_typed_and_recoverable", gpu::out_of_memory),
        ("widest_and_tallest_images", gpu::extreme_shapes),
        ("many_threads_many_streams", gpu::many_threads),
        (
            "every_allocation_site_fails_cleanly",
            gpu::every_allocation_site,
        ),
        ("arena_growth_fails_cleanly", gpu::arena_growth),
        (
            "release_cached_memory_frees_the_staging_buffers",
            gpu::release_frees_staging,
        ),
        (
            "weight_tables_outlive_the_work_that_reads_them",
            gpu::weight_tables_outlive_their_work,
        ),
        (
            "idle_lanes_keep_one_budget_per_device",
            gpu::one_budget_per_device,
        ),
    ];
    trials
        .into_iter()
        .map(|(name, body)| Trial::test(name, one_at_a_time(body)))
        .collect()
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::synthetic::SplitMix64;
    use clatch::{Backend, Error, Extractor, ExtractorConfig, GrayView, KeyPoint};
    use libtest_mimic::Failed;

    use super::common::{on_threads, rectangles, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };

    pub fn out_of_memory() -> Result<(), Failed> {
        let huge = 1usize << 42; // 4 TiB
        match clatch::cuda::hooks::probe_allocation(0, huge) {
            Err(Error::DeviceOutOfMemory { bytes, .. }) if bytes == huge => {}
            other => {
                return Err(
                    format!("expected DeviceOutOfMemory of {huge} bytes, got {other:?}").into(),
                );
            }
        }
        // The context is still usable: a real describe after the failure matches the CPU.
        clatch::cuda::hooks::probe_allocation(0, 1 << 20)?;
        let image = rectangles(300, 200, 1);
        let keypoints = [KeyPoint::new(150.0, 100.0).with_angle(33.0)];
        let gpu =
            Extractor::new(GPU, ExtractorConfig::default())?.describe(&image.view(), &keypoints)?;
        let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
            .describe(&image.view(), &keypoints)?;
        if gpu != cpu {
            return Err("describe after an out-of-memory error differs from the CPU".into());
        }
        println!("4 TiB request: DeviceOutOfMemory; context usable afterwards");
        Ok(())
    }

    /// `clatch::cuda::release_cached_memory` gives back the page-locked staging buffers that uploads
    /// from pageable memory went through (it kept them before), and the next call still gives the
    /// CPU's results. Run alone (no upload in flight), so every staging buffer is idle.
    pub fn release_frees_staging() -> Result<(), Failed> {
        use clatch::cuda::hooks::staging_buffers;
        let image = rectangles(1280, 720, 7);
        let gpu = Extractor::new(GPU, ExtractorConfig::default())?;
        let expected = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
            .detect_and_describe(&image.view())?;
        for _ in 0..2 {
            gpu.detect_and_describe(&image.view())?;
        }
        let warm = staging_buffers(0);
        clatch::cuda::release_cached_memory(0)?;
        let released = staging_buffers(0);
        let again = gpu.detect_and_describe(&image.view())?;
        if warm.0 == 0 || released != (0, 0) || again != expected {
            return Err(format!(
                "staging buffers (all, idle): {warm:?} warm, {released:?} after the release; \
                 the call after equals the CPU's: {}",
                again == expected
            )
            .into());
        }
        println!("staging buffers {warm:?} warm, {released:?} after release_cached_memory");
        Ok(())
    }

    /// The device's weight-table cache let go while describe kernels that read a table are still
    /// queued (a 21-megapixel-class image on its own stream): their results still equal the CPU's,
    /// and under compute-sanitizer's memcheck no kernel reads freed memory. Then a cold table again.
    pub fn weight_tables_outlive_their_work() -> Result<(), Failed> {
        use clatch::cuda::GpuStream;
        use clatch::cuda::hooks::forget_weight_tables;
        let (w, h) = scale::pick((5600, 3700), (640, 480));
        let image = rectangles(w, h, 11);
        let gpu = Extractor::new(GPU, ExtractorConfig::default())?;
        let expected = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
            .detect_and_describe(&image.view())?;
        let stream = GpuStream::new(0)?;
        for round in 0..3 {
            let pending = gpu.detect_and_describe_async(&stream, &image.view())?;
            forget_weight_tables(0)?;
            // Memory the table held is reused at once if it was freed: a new table of other
            // weights, uploaded while the first work may still run.
            let _other = clatch::cuda::hooks::probe_allocation(0, 1 << 20);
            let got = pending.wait()?;
            if got != expected {
                return Err(format!("round {round}: features differ from the CPU's").into());
            }
        }
        println!("{w}x{h}: 3 rounds with the table cache dropped mid-flight, equal to the CPU");
        Ok(())
    }

    /// Sixteen lanes of the device's pool held at once, each grown by a 200 MiB buffer (kept by the
    /// per-lane rules), then given back: together the idle lanes keep at most the device's budget, and
    /// they do keep up to it (not nothing).
    pub fn one_budget_per_device() -> Result<(), Failed> {
        use clatch::cuda::hooks::{KEPT_DEVICE_BYTES, fill_idle_lanes, release_cached_memory};
        release_cached_memory(0)?;
        let each = 200 << 20;
        let kept = fill_idle_lanes(0, 16, each)?;
        if kept > KEPT_DEVICE_BYTES || kept + 2 * each < KEPT_DEVICE_BYTES {
            return Err(
                format!("idle lanes keep {kept} bytes; the budget is {KEPT_DEVICE_BYTES}").into(),
            );
        }
        println!(
            "16 lanes of 200 MiB given back: the idle lanes keep {} MiB",
            kept >> 20
        );
        release_cached_memory(0)?;
        Ok(())
    }

    /// The extraction settings of the allocation-site trial's default-config calls: the library's
    /// default, or under `CLATCH_TEST_SCALE=sanitizer` the same settings with two pyramid levels
    /// instead of eight. Each level repeats the same allocation sites, so two levels still reach every
    /// site kind (level 0 and a downscaled level) while the trial's quadratic number of partial calls
    /// (every site failed in turn) shrinks enough for racecheck to finish the binary.
    fn site_config() -> ExtractorConfig {
        let default = scale::budget(ExtractorConfig::default());
        if !scale::sanitizer() {
            return default;
        }
        let pyramid = default.pyramid.map(|p| p.with_levels(2));
        default.with_pyramid(pyramid)
    }

    /// One call of the public API on the GPU, and the CPU's answer it must equal when it succeeds.
    type Call<'a> = Box<dyn Fn(Backend) -> Result<String, Error> + 'a>;

    /// Every public GPU path, each as a call whose result is summarised for comparison.
    /// Matching runs `descriptors` against themselves.
    fn calls<'a>(
        view: &'a GrayView<'a>,
        keypoints: &'a [KeyPoint],
        descriptors: &'a clatch::DescriptorSet,
    ) -> Vec<(&'static str, Call<'a>)> {
        use clatch::{MatchConfig, Matcher, OpencvLatch, Pyramid, cuda::GpuStream};
        let default = site_config();
        let pyramid = ExtractorConfig::default().with_pyramid(Some(Pyramid::new(3, 2.0)));
        let (d1, d2, d3, d4) = (default.clone(), default.clone(), default.clone(), default);
        vec![
            (
                "detect_and_describe",
                Box::new(move |b| {
                    Ok(format!(
                        "{:?}",
                        Extractor::new(b, d1.clone())?.detect_and_describe(view)?
                    ))
                }) as Call,
            ),
            (
                "detect_and_describe (pyramid)",
                Box::new(move |b| {
                    Ok(format!(
                        "{:?}",
                        Extractor::new(b, pyramid.clone())?.detect_and_describe(view)?
                    ))
                }),
            ),
            (
                "describe",
                Box::new(move |b| {
                    Ok(format!(
                        "{:?}",
                        Extractor::new(b, d2.clone())?.describe(view, keypoints)?
                    ))
                }),
            ),
            (
                "describe_opencv",
                Box::new(move |b| {
                    let e = Extractor::new(b, d3.clone())?;
                    Ok(format!(
                        "{:?}",
                        e.describe_opencv(&OpencvLatch::default(), view, keypoints)?
                    ))
                }),
            ),
            (
                "knn",
                Box::new(move |b| {
                    Ok(format!(
                        "{:?}",
                        Matcher::new(b, MatchConfig::default())?.knn(
                            descriptors,
                            descriptors,
                            2
                        )?
                    ))
                }),
            ),
            (
                "match_descriptors",
                Box::new(move |b| {
                    Ok(format!(
                        "{:?}",
                        Matcher::new(b, MatchConfig::default())?
                            .match_descriptors(descriptors, descriptors)?
                    ))
                }),
            ),
            (
                "descriptor collection: pairs and search",
                Box::new(move |b| {
                    let m = Matcher::new(b, MatchConfig::default())?;
                    let mut c = clatch::DescriptorCollection::new(&m, descriptors.width())?;
                    c.add(&[descriptors])?;
                    c.add(&[descriptors, descriptors])?; // grows the device buffer
                    let mut found = Vec::new();
                    c.match_all_pairs_each(|_, matches| found.push(matches))?;
                    c.search_each(descriptors, |_, matches| found.push(matches))?;
                    Ok(format!("{found:?}"))
                }),
            ),
            (
                "async extraction and matching",
                Box::new(move |b| {
                    let e = Extractor::new(b, d4.clone())?;
                    let m = Matcher::new(b, MatchConfig::default())?;
                    if b == Backend::Cpu {
                        return Ok(format!(
                            "{:?} {:?}",
                            e.detect_and_describe(view)?,
                            m.match_descriptors(descriptors, descriptors)?
                        ));
                    }
                    let stream = GpuStream::new(0)?;
                    let f = e.detect_and_describe_async(&stream, view)?;
                    let p = m.match_descriptors_async(&stream, descriptors, descriptors)?;
                    Ok(format!("{:?} {:?}", f.wait()?, p.wait()?))
                }),
            ),
        ]
    }

    /// Makes each device allocation of each public GPU path fail in turn: every failure is a typed
    /// `DeviceOutOfMemory` naming its operation, the next call gives the CPU's answer, and after 1000
    /// failed calls the device's free memory is back where it was. Every call starts cold
    /// (`release_cached_memory`: no stream arena or staging buffer kept from an earlier call), so that
    /// it reaches every allocation site; the growth of a warm arena is `arena_growth_fails_cleanly`.
    ///
    /// Under `CLATCH_TEST_SCALE=sanitizer`: a 400x400 image (still three pyramid levels) and 100
    /// keypoints, and 2 failed calls per allocation site instead of 1000 in all. Under any sanitizer the
    /// free-memory comparison is reported, not judged: the sanitizer's own device allocations move it.
    pub fn every_allocation_site() -> Result<(), Failed> {
        use clatch::cuda::hooks::{device_memory, fail_allocation, release_cached_memory};
        let cold = || release_cached_memory(0);
        let (width, height) = scale::pick((640, 480), (320, 240));
        let image = rectangles(width, height, 9);
        let view = image.view();
        // 30 columns from x = 40 to 40 px short of the right edge, whatever the image's width.
        let column_step = (width - 80) as f32 / 30.0;
        let keypoints: Vec<KeyPoint> = (0..scale::pick(300, 100))
            .map(|i| {
                KeyPoint::new(
                    40.0 + (i % 30) as f32 * column_step,
                    40.0 + (i / 30) as f32 * 40.25,
                )
                .with_angle(i as f32 * 7.0)
            })
            .collect();
        let descriptors = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
            .detect_and_describe(&view)?
            .descriptors;
        let calls = calls(&view, &keypoints, &descriptors);
        let mut sites_per_call = Vec::new();
        let mut answers = Vec::new();
        for (name, call) in &calls {
            let expected = call(Backend::Cpu)?;
            answers.push(expected.clone());
            let mut sites = Vec::new();
            for n in 0.. {
                cold()?;
                fail_allocation(Some(n));
                let result = call(GPU);
                let injected = fail_allocation(None);
                match (injected, result) {
                    (true, Err(Error::DeviceOutOfMemory { operation, .. })) => {
                        sites.push(operation)
                    }
                    (false, Ok(got)) if got == expected => break,
                    (injected, other) => {
                        return Err(format!(
                            "{name}, allocation {n} (failure injected: {injected}): {:?}",
                            other.map(|_| "a result that differs from the CPU's")
                        )
                        .into());
                    }
                }
                if n > 200 {
                    return Err(format!("{name}: more than 200 allocations").into());
                }
            }
            println!(
                "{name}: {} allocation sites fail cleanly: {sites:?}",
                sites.len()
            );
            sites_per_call.push(sites.len());
        }
        // Memory: a warm round, then 1000 failed calls spread over every site, each from a cold start;
        // free memory compared with nothing cached, before and after.
        for (_, call) in &calls {
            call(GPU)?;
        }
        cold()?;
        let (baseline, total) = device_memory(0)?;
        let mut failed = 0;
        if scale::sanitizer() {
            // The staging pool allocates a buffer only when no idle one has finished its copy, so a
            // call's allocation count depends on the copies' timing (under a sanitizer more than
            // anywhere): the last site may not be reached again. Such a call must still be right.
            let mut not_reached = 0;
            for (((name, call), &sites), expected) in
                calls.iter().zip(&sites_per_call).zip(&answers)
            {
                for n in 0..sites {
                    cold()?;
                    fail_allocation(Some(n % sites));
                    let result = call(GPU);
                    match (fail_allocation(None), result) {
                        (true, Err(Error::DeviceOutOfMemory { .. })) => failed += 1,
                        (false, Ok(got)) if &got == expected => not_reached += 1,
                        (injected, other) => {
                            return Err(format!(
                                "{name}, allocation {} again (failure injected: {injected}): {:?}",
                                n % sites,
                                other.map(|_| "a result")
                            )
                            .into());
                        }
                    }
                }
            }
            println!(
                "second pass: {failed} failed calls; {not_reached} calls allocated less than the first \
                 time (staging timing) and gave the CPU's answer"
            );
        }
        while failed < scale::pick(1000, 0) {
            for ((_, call), &sites) in calls.iter().zip(&sites_per_call) {
                cold()?;
                fail_allocation(Some(failed % sites.max(1)));
                let result = call(GPU);
                fail_allocation(None);
                if result.is_err() {
                    failed += 1;
                }
            }
        }
        for (_, call) in &calls {
            call(GPU)?;
        }
        cold()?;
        let (after, _) = device_memory(0)?;
        println!(
            "{failed} failed calls: free device memory {baseline} bytes before, {after} after (of {total})"
        );
        if scale::under_sanitizer() {
            println!(
                "under a sanitizer: the free-memory comparison is not judged (the sanitizer's shadow \
                 memory comes and goes on the device)"
            );
        } else if after < baseline {
            return Err(format!("device memory leaked: {} bytes", baseline - after).into());
        }
        Ok(())
    }

    /// A stream whose arena holds a small image's buffers, then gets a larger image: each allocation
    /// the growth needs (device scratch, pinned staging and read-back buffers) fails in turn with a
    /// typed `DeviceOutOfMemory`, after which the same stream gives the CPU's answer for the large
    /// image; the loop ends when a call reaches no injected failure and equals the CPU.
    pub fn arena_growth() -> Result<(), Failed> {
        use clatch::cuda::GpuStream;
        use clatch::cuda::hooks::fail_allocation;
        let small = rectangles(320, 240, 3);
        // Larger than one 4 MiB upload band: the copy stream and its band events are in the growth.
        let (w, h) = scale::pick((2400, 1800), (2100, 2100));
        let large = rectangles(w, h, 4);
        // Under the sanitizer scale the single-scale preset alone: the arena's growth is the same,
        // and the pyramid's levels would triple the pixels racecheck follows on every attempt.
        let single = (
            "single scale",
            scale::budget(ExtractorConfig::single_scale()),
        );
        let configs = scale::pick(
            vec![("pyramid", ExtractorConfig::default()), single.clone()],
            vec![single],
        );
        for (name, config) in configs {
            let gpu = Extractor::new(GPU, config.clone())?;
            let expected =
                Extractor::new(Backend::Cpu, config)?.detect_and_describe(&large.view())?;
            let mut sites = Vec::new();
            for n in 0.. {
                // A fresh stream warmed on the small image: its arena must grow for the large one.
                let stream = GpuStream::new(0)?;
                gpu.detect_and_describe_async(&stream, &small.view())?
                    .wait()?;
                fail_allocation(Some(n));
                let result = gpu
                    .detect_and_describe_async(&stream, &large.view())
                    .and_then(|p| p.wait());
                let injected = fail_allocation(None);
                match (injected, result) {
                    (true, Err(Error::DeviceOutOfMemory { operation, .. })) => {
                        let again = gpu
                            .detect_and_describe_async(&stream, &large.view())?
                            .wait()?;
                        if again != expected {
                            // What differs, and whether it lasts: two more calls, the second after
                            // waiting for the stream (a race would pass there; a stale buffer not).
                            let third = gpu
                                .detect_and_describe_async(&stream, &large.view())?
                                .wait()?;
                            stream.synchronize()?;
                            let fourth = gpu
                                .detect_and_describe_async(&stream, &large.view())?
                                .wait()?;
                            let first_keypoint = again
                                .keypoints
                                .iter()
                                .zip(&expected.keypoints)
                                .position(|(a, b)| a != b);
                            // Which rows differ, by pyramid level (octave): a level's quad texture,
                            // its keypoints or its output rows.
                            let words = expected.descriptors.width().words();
                            let rows = again.descriptors.as_words().chunks(words);
                            let mut levels = std::collections::BTreeMap::new();
                            // What the wrong rows are: all zero (never written), another row of the
                            // answer (written in the wrong place), or how far from the right one
                            // (a few bits: a wrong angle or window; about half: other pixels).
                            let expected_rows: std::collections::HashSet<&[u64]> =
                                expected.descriptors.as_words().chunks(words).collect();
                            let (mut zero, mut elsewhere, mut distance) = (0, 0, 0u64);
                            for (i, (a, b)) in rows
                                .zip(expected.descriptors.as_words().chunks(words))
                                .enumerate()
                            {
                                if a != b {
                                    *levels.entry(expected.keypoints[i].octave).or_insert(0) += 1;
                                    zero += usize::from(a.iter().all(|&w| w == 0));
                                    elsewhere += usize::from(expected_rows.contains(a));
                                    distance += a
                                        .iter()
                                        .zip(b)
                                        .map(|(x, y)| u64::from((x ^ y).count_ones()))
                                        .sum::<u64>();
                                }
                            }
                            let wrong: usize = levels.values().sum();
                            let diagnosis = format!(
                                "of the {wrong} wrong rows {zero} are all zero, {elsewhere} are another \
                                 row of the answer, mean Hamming distance to the right row {:.1} bits",
                                distance as f64 / wrong.max(1) as f64
                            );
                            return Err(format!(
                                "{name}: after the failure at {operation} (growth allocation {n}), the \
                                 stream's answer differs from the CPU's: {} keypoints against {}, first \
                                 different keypoint {first_keypoint:?} ({:?} against {:?}), descriptors \
                                 equal: {} (rows differing by level: {levels:?}; {diagnosis}); the \
                                 next call equal: {}, after a synchronize: {}",
                                again.keypoints.len(),
                                expected.keypoints.len(),
                                first_keypoint.map(|i| again.keypoints[i]),
                                first_keypoint.map(|i| expected.keypoints[i]),
                                again.descriptors == expected.descriptors,
                                third == expected,
                                fourth == expected,
                            )
                            .into());
                        }
                        sites.push(operation);
                    }
                    (false, Ok(got)) if got == expected => break,
                    (injected, other) => {
                        return Err(format!(
                            "{name}, growth allocation {n} (failure injected: {injected}): {:?}",
                            other.map(|_| "a result that differs from the CPU's")
                        )
                        .into());
                    }
                }
                if n > 200 {
                    return Err(format!("{name}: more than 200 growth allocations").into());
                }
            }
            if sites.is_empty() {
                return Err(format!("{name}: the larger image grew nothing").into());
            }
            println!(
                "{name}: {} growth sites fail cleanly: {sites:?}",
                sites.len()
            );
        }
        Ok(())
    }

    pub fn extreme_shapes() -> Result<(), Failed> {
        let max = clatch::MAX_IMAGE_SIDE;
        for (w, h) in [(max, 64), (64, max), (max, 300)] {
            let pixels =
                clatch::synthetic::noise(w, h, (w * 7 + h) as u64).expect("synthetic image");
            let image = GrayView::new(&pixels, w, h, w)?;
            let mut rng = SplitMix64::new(3);
            let keypoints: Vec<KeyPoint> = (0..scale::pick(2000, 200))
                .map(|_| {
                    KeyPoint::new(rng.below(w as u64) as f32, rng.below(h as u64) as f32)
                        .with_size(16.0 + rng.below(48) as f32)
                        .with_angle(rng.below(360) as f32)
                })
                .collect();
            let gpu =
                Extractor::new(GPU, ExtractorConfig::default())?.describe(&image, &keypoints)?;
            let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())?
                .describe(&image, &keypoints)?;
            if gpu != cpu {
                return Err(format!("{w}x{h}: GPU and CPU differ").into());
            }
            println!("{w}x{h}: {} descriptors identical", cpu.descriptors.len());
        }
        Ok(())
    }

    pub fn many_threads() -> Result<(), Failed> {
        // Under CLATCH_TEST_SCALE=sanitizer, 4 threads of 1 round.
        let (threads, rounds) = scale::pick((16, 5), (4, 1));
        let total = on_threads(threads, |t| {
            let image = rectangles(640 + 16 * t, 480, 100 + t as u64);
            let view = image.view();
            let mut compared = 0;
            for round in 0..rounds {
                let gpu =
                    Extractor::new(GPU, ExtractorConfig::default()).map_err(|e| e.to_string())?;
                let cpu = Extractor::new(Backend::Cpu, ExtractorConfig::default())
                    .map_err(|e| e.to_string())?;
                let a = gpu.detect_and_describe(&view).map_err(|e| e.to_string())?;
                let b = cpu.detect_and_describe(&view).map_err(|e| e.to_string())?;
                if a != b {
                    return Err(format!("thread {t}, round {round}: GPU and CPU differ"));
                }
                compared += a.descriptors.len();
            }
            Ok(compared)
        })?;
        println!("{threads} threads x {rounds} rounds: {total} descriptors identical to the CPU");
        Ok(())
    }
}
