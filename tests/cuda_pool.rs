//! `DevicePool` on the GPU: the one device listed as 1, 2 and 4 workers (and beside CPU workers)
//! gives exactly what one-device `Matcher::match_pairs` and `Extractor::detect_and_describe_batch`
//! give on the GPU, and those equal the CPU's, pair by pair and image by image.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_pool")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("pairs_on_one_gpu_as_several_workers", gpu::pairs),
        Trial::test("batch_on_one_gpu_as_several_workers", gpu::batch),
        Trial::test("absent_device_is_a_worker_error", gpu::absent_device),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use std::sync::Mutex;

    use clatch::synthetic::SplitMix64;
    use clatch::{Backend, DescriptorSet, DevicePool, Error, Extractor, ExtractorConfig, Matcher};
    use libtest_mimic::Failed;

    use super::common::{Gray, astronaut, match_configs, rectangles, scale, scrambled_collection};

    const GPU: Backend = Backend::Cuda { device: 0 };

    /// The pools compared: the GPU as 1, 2 and 4 workers, and the GPU twice beside a CPU worker.
    fn pools() -> Vec<Vec<Backend>> {
        let all = vec![
            vec![GPU],
            vec![GPU; 2],
            vec![GPU; 4],
            vec![GPU, Backend::Cpu, GPU],
        ];
        // The sanitizer scale keeps one GPU-only pool of several workers and the mixed one.
        scale::thin(all, 2)
    }

    /// Whether `done` named every index exactly once.
    fn once_each(reported: Mutex<Vec<usize>>) -> bool {
        reported.into_inner().unwrap().iter().all(|&c| c == 1)
    }

    pub fn pairs() -> Result<(), Failed> {
        // 512-bit sets up to 5000 descriptors, and 16-bit ones where ties are everywhere.
        let big = scale::thin([700, 0, 1, 2000, 65, 1500, 300, 5000, 9], 2);
        let tied = [400, 1, 0, 129, 64, 700];
        let mut compared = 0;
        for (bits, sizes, seed) in [(512, &big[..], 31), (16, &tied[..], 32)] {
            let (owned, pairs) = scrambled_collection(bits, sizes, 10, &mut SplitMix64::new(seed));
            let sets: Vec<&DescriptorSet> = owned.iter().collect();
            for config in scale::thin(match_configs().into_iter().step_by(5), 2) {
                let cpu = Matcher::new(Backend::Cpu, config.clone())?.match_pairs(&sets, &pairs)?;
                let gpu = Matcher::new(GPU, config.clone())?.match_pairs(&sets, &pairs)?;
                if gpu != cpu {
                    return Err(format!(
                        "{bits} bits, {config:?}: one-device GPU differs from the CPU"
                    )
                    .into());
                }
                for workers in pools() {
                    for tile in scale::thin([1, 3, pairs.len() + 1], 2) {
                        let pool = DevicePool::new(&workers)?.with_tile(tile)?;
                        let reported = Mutex::new(vec![0usize; pairs.len()]);
                        let got = pool.match_pairs_with_progress(&config, &sets, &pairs, &|p| {
                            reported.lock().unwrap()[p] += 1
                        })?;
                        let what =
                            format!("{bits} bits, {config:?}, workers {workers:?}, tile {tile}");
                        if !once_each(reported) {
                            return Err(format!("{what}: pairs not reported once each").into());
                        }
                        if got.len() != gpu.len() {
                            return Err(format!(
                                "{what}: {} results for {} pairs",
                                got.len(),
                                gpu.len()
                            )
                            .into());
                        }
                        if let Some(p) = (0..gpu.len()).find(|&p| got[p] != gpu[p]) {
                            return Err(format!(
                                "{what}: pair {p} {:?} differs from one device",
                                pairs[p]
                            )
                            .into());
                        }
                    }
                }
                compared += gpu.iter().map(Vec::len).sum::<usize>();
            }
        }
        println!(
            "the GPU as 1, 2 and 4 workers and beside a CPU worker: {compared} matches identical to one \
             device and to the CPU"
        );
        Ok(())
    }

    pub fn batch() -> Result<(), Failed> {
        // Under the sanitizer scale, smaller images and no photo: racecheck pays per shared-memory
        // access, and the pools (not the image sizes) are what this test is about.
        let (w, h) = scale::pick((640, 480), (224, 160));
        let mut images: Vec<Gray> = scale::thin(0..7, 3)
            .into_iter()
            .map(|i| rectangles(w + 64 * i, h + 8 * i, 50 + i as u64))
            .collect();
        if !scale::sanitizer() {
            images.push(astronaut());
        }
        images.push(Gray::new(vec![90; 128 * 96], 128, 96));
        let views: Vec<clatch::GrayView> = images.iter().map(Gray::view).collect();
        let mut keypoints = 0;
        for config in
            [ExtractorConfig::default(), ExtractorConfig::single_scale()].map(scale::budget)
        {
            let cpu = Extractor::new(Backend::Cpu, config.clone())?;
            let gpu = Extractor::new(GPU, config.clone())?.detect_and_describe_batch(&views)?;
            for (i, view) in views.iter().enumerate() {
                if gpu[i] != cpu.detect_and_describe(view)? {
                    return Err(format!(
                        "image {i}: one-device GPU features differ from the CPU's"
                    )
                    .into());
                }
            }
            for workers in pools() {
                let pool = DevicePool::new(&workers)?;
                let reported = Mutex::new(vec![0usize; views.len()]);
                let got = pool.detect_and_describe_batch_with_progress(&config, &views, &|i| {
                    reported.lock().unwrap()[i] += 1
                })?;
                if !once_each(reported) {
                    return Err(
                        format!("workers {workers:?}: images not reported once each").into(),
                    );
                }
                if let Some(i) = (0..views.len()).find(|&i| got.get(i) != gpu.get(i)) {
                    return Err(format!(
                        "workers {workers:?}, {config:?}: image {i} differs from one device"
                    )
                    .into());
                }
            }
            keypoints += gpu.iter().map(|f| f.keypoints.len()).sum::<usize>();
        }
        println!(
            "{} images x 2 configurations, the GPU as 1, 2 and 4 workers and beside a CPU worker: {keypoints} \
             keypoints and descriptors identical to one device and to the CPU",
            views.len()
        );
        Ok(())
    }

    pub fn absent_device() -> Result<(), Failed> {
        match DevicePool::new(&[GPU, Backend::Cuda { device: 4096 }]) {
            Err(Error::Worker {
                worker: 1, source, ..
            }) if matches!(*source, Error::BackendUnavailable { .. }) => Ok(()),
            other => Err(format!("expected worker 1 unavailable, got {other:?}").into()),
        }
    }
}
