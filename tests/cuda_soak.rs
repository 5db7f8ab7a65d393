//! GPU soak: 16 host threads, two streams each, random image sizes and settings, extraction and
//! matching queued asynchronously for `CLATCH_SOAK_SECONDS` (default 5; the device run uses 600).
//! Every eighth result is compared with the CPU's (0 differences allowed) and the device's free memory
//! is sampled once a second: it must stay flat while the work goes on (the last third of the run no
//! lower than the first third after warm-up; judged on runs of a minute or more, as the arenas grow
//! for longer than a short run), and come back once the work stops.

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
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    use std::time::{Duration, Instant};

    use clatch::cuda::GpuStream;
    use clatch::cuda::hooks::device_memory;
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

    fn random_config(rng: &mut SplitMix64) -> ExtractorConfig {
        ExtractorConfig {
            detector: DetectorConfig {
                threshold: 8 + rng.below(30) as u8,
                max_keypoints: 200 + rng.below(6000) as usize,
                ..DetectorConfig::default()
            },
            descriptor: DescriptorConfig {
                width: DescriptorWidth::from_bits(8 * (1 + rng.below(64) as usize))
                    .expect("a multiple of 8"),
                ..DescriptorConfig::default()
            },
            pyramid: (rng.below(3) == 0).then_some(Pyramid {
                levels: 2 + rng.below(3) as usize,
                scale_factor: [1.2, 1.5, 2.0][rng.below(3) as usize],
            }),
        }
    }

    /// One worker: returns (extractions, comparisons with the CPU) or the first difference.
    fn worker(t: u64, deadline: Instant, stop: &AtomicBool) -> Result<(usize, usize), String> {
        let err = |e: clatch::Error| e.to_string();
        let mut rng = SplitMix64::new(0x50a4 + t);
        let streams = [
            GpuStream::new(0).map_err(err)?,
            GpuStream::new(0).map_err(err)?,
        ];
        let mut previous: Option<Features> = None;
        let (mut runs, mut compared) = (0, 0);
        while Instant::now() < deadline && !stop.load(Ordering::Relaxed) {
            let (w, h) = (64 + rng.below(1600) as usize, 64 + rng.below(1200) as usize);
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
        let stop = AtomicBool::new(false);
        let samples = std::sync::Mutex::new(Vec::new());
        let finished = AtomicUsize::new(0);
        let results: Vec<Result<(usize, usize), String>> = std::thread::scope(|scope| {
            let workers: Vec<_> = (0..THREADS)
                .map(|t| {
                    let (stop, finished) = (&stop, &finished);
                    scope.spawn(move || {
                        let r = worker(t, deadline, stop);
                        if r.is_err() {
                            stop.store(true, Ordering::Relaxed);
                        }
                        finished.fetch_add(1, Ordering::Relaxed);
                        r
                    })
                })
                .collect();
            // Free device memory once a second while the workers run.
            while finished.load(Ordering::Relaxed) < THREADS as usize {
                if let Ok((free, _)) = device_memory(0) {
                    samples
                        .lock()
                        .expect("samples")
                        .push((start.elapsed().as_secs_f32(), free));
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
        let samples = samples.into_inner().expect("samples");
        let (after, total) = device_memory(0)?;
        let warm: Vec<usize> = samples
            .iter()
            .filter(|(t, _)| *t >= 2.0)
            .map(|&(_, f)| f)
            .collect();
        let mib = |b: usize| b as f64 / (1 << 20) as f64;
        let (lo, hi) = (
            warm.iter().min().copied().unwrap_or(after),
            warm.iter().max().copied().unwrap_or(after),
        );
        println!(
            "{} s, {THREADS} threads: {runs} extractions and matchings, {compared} compared with the CPU, \
             0 differences; free device memory {:.0} MiB before, {:.0}..{:.0} MiB while running, \
             {:.0} MiB after (of {:.0})",
            duration.as_secs(),
            mib(baseline),
            mib(lo),
            mib(hi),
            mib(after),
            mib(total)
        );
        // The free memory over the run, at about every tenth of it.
        let step = samples.len().div_ceil(10).max(1);
        let timeline: Vec<String> = samples
            .iter()
            .step_by(step)
            .map(|&(t, f)| format!("{t:.0} s: {:.0}", mib(f)))
            .collect();
        println!(
            "free device memory (MiB) while running: {}",
            timeline.join(", ")
        );
        // Flat: a leak grows with the work, so the last third of the run must not sit lower than the
        // first third (16 MiB for the allocator's granularity). The streams' arenas grow until each
        // has seen the largest sizes of the random work, which takes longer than a short run: the
        // judgement needs at least a minute of samples (the device run is 10 minutes). What the
        // driver keeps after the workers' streams are gone (50 to 84 MiB on an H200, the same after
        // 5 s as after 560 s) is reported, not judged.
        let third = warm.len() / 3;
        if warm.len() < 60 {
            println!(
                "{} s of samples: too short to tell arena growth from a leak; flatness not judged",
                warm.len()
            );
        } else if third > 0 {
            let first = warm[..third].iter().min().copied().unwrap_or(lo);
            let last = warm[warm.len() - third..]
                .iter()
                .min()
                .copied()
                .unwrap_or(lo);
            if last + (16 << 20) < first {
                return Err(format!(
                    "device memory fell while running: {:.0} MiB free at the lowest of the first third, \
                     {:.0} MiB of the last",
                    mib(first),
                    mib(last)
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
