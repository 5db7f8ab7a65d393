//! GPU soak: 16 host threads, two streams each, random image sizes and settings, extraction and
//! matching queued asynchronously for `CLATCH_SOAK_SECONDS` (default 5; the device run uses as much of
//! its call as it can). Every eighth result is compared with the CPU's (0 differences allowed).
//!
//! Memory: each thread first runs the largest work the random draws can ask for on both its streams,
//! so that their arenas hold buffers for any later call. From then on the device's free memory,
//! sampled once a second, may fall only by what the arenas are seen to grow (the hook
//! `arena_bytes_grown`, each growth allowed one 32 MiB block of the driver's allocator): a leak
//! outside the arenas shows as a fall no growth explains. A leak through them (buffers never given
//! back, so every call allocates) shows as calls that grow an arena: at most 1 in 100. Both are
//! judged on runs of a minute or more. Once the work stops and the streams are gone, the memory must
//! come back.
mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_soak")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![Trial::test("soak_threads_streams_random_work", gpu::soak)]
}

#[cfg(feature = "cuda")]
mod gpu {
    use std::ops::Range;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    use std::time::{Duration, Instant};

    use clatch::cuda::GpuStream;
    use clatch::cuda::hooks::{arena_bytes_grown, device_memory};
    use clatch::synthetic::SplitMix64;
    use clatch::{
        Backend, DescriptorConfig, DescriptorWidth, DetectorConfig, Extractor, ExtractorConfig,
        Features, GrayView, MatchConfig, Matcher, Pyramid,
    };
    use libtest_mimic::Failed;

    const GPU: Backend = Backend::Cuda { device: 0 };
    const THREADS: u64 = 16;

    fn seconds() -> u64 {
        std::env::var("CLATCH_SOAK_SECONDS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(5)
    }

    /// What the random work draws from (`random_config`, `worker`); the warm-up runs the top of each.
    const WIDTHS: Range<usize> = 64..1664;
    const HEIGHTS: Range<usize> = 64..1264;
    const THRESHOLDS: Range<usize> = 8..38;
    const MAX_KEYPOINTS: Range<usize> = 200..6200;
    /// Descriptor widths in bytes (8 to 512 bits).
    const WIDTH_BYTES: Range<usize> = 1..65;
    const LEVELS: Range<usize> = 2..5;
    const SCALE_FACTORS: [f32; 3] = [1.2, 1.5, 2.0];

    /// A value of `range`, drawn from `rng`.
    fn draw(rng: &mut SplitMix64, range: Range<usize>) -> usize {
        range.start + rng.below((range.end - range.start) as u64) as usize
    }

    fn random_config(rng: &mut SplitMix64) -> ExtractorConfig {
        ExtractorConfig::default()
            .with_detector(
                DetectorConfig::default()
                    .with_threshold(draw(rng, THRESHOLDS) as u8)
                    .with_max_keypoints(draw(rng, MAX_KEYPOINTS)),
            )
            .with_descriptor(DescriptorConfig::default().with_width(
                DescriptorWidth::from_bits(8 * draw(rng, WIDTH_BYTES)).expect("a multiple of 8"),
            ))
            .with_pyramid((rng.below(3) == 0).then_some(Pyramid::new(
                draw(rng, LEVELS),
                SCALE_FACTORS[rng.below(3) as usize],
            )))
    }

    /// The largest image the random draws make (`worker`), as noise (the most corners).
    const LARGEST: (usize, usize) = (WIDTHS.end - 1, HEIGHTS.end - 1);

    /// The configurations whose buffers hold those of any random one at the same image size: the most
    /// keypoints, the widest descriptor, the lowest threshold, with and without each pyramid.
    fn largest_configs() -> Vec<ExtractorConfig> {
        let mut configs = vec![None];
        for levels in LEVELS {
            for scale_factor in SCALE_FACTORS {
                configs.push(Some(Pyramid::new(levels, scale_factor)));
            }
        }
        configs
            .into_iter()
            .map(|pyramid| {
                ExtractorConfig::default()
                    .with_detector(
                        DetectorConfig::default()
                            .with_threshold(THRESHOLDS.start as u8)
                            .with_max_keypoints(MAX_KEYPOINTS.end - 1),
                    )
                    .with_descriptor(DescriptorConfig::default().with_width(
                        DescriptorWidth::from_bits(8 * (WIDTH_BYTES.end - 1)).expect("512 bits"),
                    ))
                    .with_pyramid(pyramid)
            })
            .collect()
    }

    /// Runs the largest work on both `streams` (extraction on each, matching of its result on each).
    fn warm_up(streams: &[GpuStream; 2], seed: u64) -> Result<(), clatch::Error> {
        let (w, h) = LARGEST;
        let pixels = clatch::synthetic::noise(w, h, seed)?;
        let view = GrayView::new(&pixels, w, h, w)?;
        let matcher = Matcher::new(GPU, MatchConfig::default())?;
        for config in largest_configs() {
            let extractor = Extractor::new(GPU, config)?;
            for stream in streams {
                let features = extractor.detect_and_describe_async(stream, &view)?.wait()?;
                for on in streams {
                    matcher
                        .match_descriptors_async(on, &features.descriptors, &features.descriptors)?
                        .wait()?;
                }
            }
        }
        Ok(())
    }

    /// What the workers share with the sampler.
    #[derive(Default)]
    struct Shared {
        stop: AtomicBool,
        /// Workers whose streams have run the largest work.
        warmed: AtomicUsize,
        /// Workers that have stopped.
        finished: AtomicUsize,
        /// Arena growth after the warm-up, summed over workers: bytes, each rounded up to the
        /// allocator's block ([`BLOCK`]).
        grown: AtomicUsize,
        /// Calls after the warm-up that grew an arena.
        growing_calls: AtomicUsize,
    }

    /// The driver's allocator takes device memory in blocks of this size (free memory falls in steps
    /// of it on an H200); a small buffer that opens a new block costs the whole block.
    const BLOCK: usize = 32 << 20;

    /// One worker: returns (extractions, comparisons with the CPU) or the first difference.
    fn worker(t: u64, deadline: Instant, shared: &Shared) -> Result<(usize, usize), String> {
        let err = |e: clatch::Error| e.to_string();
        let mut rng = SplitMix64::new(0x50a4 + t);
        let streams = [
            GpuStream::new(0).map_err(err)?,
            GpuStream::new(0).map_err(err)?,
        ];
        warm_up(&streams, rng.next_u64()).map_err(err)?;
        shared.warmed.fetch_add(1, Ordering::SeqCst);
        let mut previous: Option<Features> = None;
        let (mut runs, mut compared) = (0, 0);
        // At least 8 calls, so that each worker compares one with the CPU even when the warm-up
        // took a short run's whole time.
        while (Instant::now() < deadline || runs < 8) && !shared.stop.load(Ordering::Relaxed) {
            let grown_before = arena_bytes_grown();
            let (w, h) = (draw(&mut rng, WIDTHS), draw(&mut rng, HEIGHTS));
            let pixels = if rng.below(4) == 0 {
                clatch::synthetic::noise(w, h, rng.next_u64())
            } else {
                clatch::synthetic::rectangles(w, h, rng.next_u64())
            }
            .map_err(err)?;
            let view = GrayView::new(&pixels, w, h, w).map_err(err)?;
            let config = random_config(&mut rng);
            let extractor = Extractor::new(GPU, config.clone()).map_err(err)?;
            let matcher = Matcher::new(GPU, MatchConfig::default()).map_err(err)?;
            let pending = extractor
                .detect_and_describe_async(&streams[0], &view)
                .map_err(err)?;
            // Match the previous image against itself reversed while this one is extracted.
            let pair = match &previous {
                Some(p) if p.descriptors.len() >= 2 => Some((
                    p.descriptors.clone(),
                    matcher
                        .match_descriptors_async(&streams[1], &p.descriptors, &p.descriptors)
                        .map_err(err)?,
                )),
                _ => None,
            };
            let features = pending.wait().map_err(err)?;
            let matches = match pair {
                Some((set, p)) => Some((set, p.wait().map_err(err)?)),
                None => None,
            };
            runs += 1;
            let grown = arena_bytes_grown() - grown_before;
            if grown > 0 {
                shared
                    .grown
                    .fetch_add(grown.next_multiple_of(BLOCK), Ordering::SeqCst);
                shared.growing_calls.fetch_add(1, Ordering::SeqCst);
            }
            if runs % 8 == 0 {
                let cpu = Extractor::new(Backend::Cpu, config)
                    .and_then(|e| e.detect_and_describe(&view))
                    .map_err(err)?;
                if cpu != features {
                    return Err(format!("thread {t}, run {runs}: {w}x{h} features differ"));
                }
                if let Some((set, gpu)) = &matches {
                    let cpu = Matcher::new(Backend::Cpu, MatchConfig::default())
                        .and_then(|m| m.match_descriptors(set, set))
                        .map_err(err)?;
                    if &cpu != gpu {
                        return Err(format!("thread {t}, run {runs}: matches differ"));
                    }
                }
                compared += 1;
            }
            previous = Some(features);
        }
        Ok((runs, compared))
    }

    /// One sample of the sampler: seconds since the start, free device memory, and [`Shared::grown`]
    /// at that moment, taken once every worker has warmed up.
    struct Sample {
        at: f32,
        free: usize,
        grown: usize,
    }

    pub fn soak() -> Result<(), Failed> {
        let duration = Duration::from_secs(seconds());
        // Warm: the device and its kernels loaded, then the baseline.
        Extractor::new(GPU, ExtractorConfig::default())?.detect_and_describe(&GrayView::new(
            &[0; 128 * 128],
            128,
            128,
            128,
        )?)?;
        let (baseline, _) = device_memory(0)?;
        let start = Instant::now();
        let deadline = start + duration;
        let shared = Shared::default();
        let mut samples = Vec::new();
        let results: Vec<Result<(usize, usize), String>> = std::thread::scope(|scope| {
            let workers: Vec<_> = (0..THREADS)
                .map(|t| {
                    let shared = &shared;
                    scope.spawn(move || {
                        let r = worker(t, deadline, shared);
                        if r.is_err() {
                            shared.stop.store(true, Ordering::Relaxed);
                        }
                        shared.finished.fetch_add(1, Ordering::SeqCst);
                        r
                    })
                })
                .collect();
            // Free device memory once a second while the workers run, from when all have warmed up.
            while shared.finished.load(Ordering::SeqCst) == 0 {
                if shared.warmed.load(Ordering::SeqCst) == THREADS as usize {
                    // Growth read before the free memory: a fall is never paired with growth after it.
                    let grown = shared.grown.load(Ordering::SeqCst);
                    if let Ok((free, _)) = device_memory(0) {
                        samples.push(Sample {
                            at: start.elapsed().as_secs_f32(),
                            free,
                            grown,
                        });
                    }
                }
                std::thread::sleep(Duration::from_millis(1000));
            }
            workers
                .into_iter()
                .map(|h| h.join().unwrap_or(Err("worker panicked".into())))
                .collect()
        });
        let (mut runs, mut compared) = (0, 0);
        for r in results {
            let (a, b) = r?;
            runs += a;
            compared += b;
        }
        let (after, total) = device_memory(0)?;
        let mib = |b: usize| b as f64 / (1 << 20) as f64;
        let lo = samples.iter().map(|s| s.free).min().unwrap_or(after);
        let hi = samples.iter().map(|s| s.free).max().unwrap_or(after);
        let growing = shared.growing_calls.load(Ordering::SeqCst);
        println!(
            "{} s, {THREADS} threads: {runs} extractions and matchings, {compared} compared with the CPU, \
             0 differences; free device memory {:.0} MiB before, {:.0}..{:.0} MiB while running \
             (after the warm-up), {:.0} MiB after (of {:.0}); {growing} calls grew an arena after the \
             warm-up ({:.0} MiB in {}-MiB blocks)",
            duration.as_secs(),
            mib(baseline),
            mib(lo),
            mib(hi),
            mib(after),
            mib(total),
            mib(shared.grown.load(Ordering::SeqCst)),
            BLOCK >> 20
        );
        // The free memory over the run, at about every tenth of it.
        let step = samples.len().div_ceil(10).max(1);
        let timeline: Vec<String> = samples
            .iter()
            .step_by(step)
            .map(|s| {
                format!(
                    "{:.0} s: {:.0} (grown {:.0})",
                    s.at,
                    mib(s.free),
                    mib(s.grown)
                )
            })
            .collect();
        println!(
            "free device memory (MiB) while running: {}",
            timeline.join(", ")
        );
        if samples.len() < 60 {
            println!(
                "{} s of samples after the warm-up: too short to judge; flatness not judged",
                samples.len()
            );
        } else {
            // A leak outside the arenas: free memory falls below its level after the warm-up by more
            // than the arenas grew since (16 MiB for the measurement's own noise).
            let first = &samples[0];
            for s in &samples {
                let fell = first.free.saturating_sub(s.free);
                let explained = s.grown - first.grown + (16 << 20);
                if fell > explained {
                    return Err(format!(
                        "device memory fell by {:.0} MiB from {:.0} s to {:.0} s, the arenas grew by {:.0} \
                         MiB (in {}-MiB blocks)",
                        mib(fell),
                        first.at,
                        s.at,
                        mib(s.grown - first.grown),
                        BLOCK >> 20
                    )
                    .into());
                }
            }
            // A leak through the arenas: calls that keep growing them.
            if growing * 100 > runs {
                return Err(format!(
                    "{growing} of {runs} calls grew an arena after the warm-up: buffers not given back?"
                )
                .into());
            }
        }
        if after < lo {
            return Err(format!(
                "device memory did not come back: {:.0} MiB free after, {:.0} MiB at the lowest while running",
                mib(after),
                mib(lo)
            )
            .into());
        }
        if compared == 0 {
            return Err("nothing was compared with the CPU".into());
        }
        Ok(())
    }
}
