//! GPU against CPU verification, field by field: configuration, F, E and H bit for bit, inlier
//! indices and counts, on generated pairs of every shape (`tests/common/verify_cases.rs`: general
//! 3-D, planar, pure rotation, degenerate, watermarks, 0 to 850 matches, 0 to 90 % outliers, with and
//! without cameras, duplicate matches, huge coordinates), under several settings, in batches split
//! into chunks, and the same typed errors for bad input on both backends.
//!
//! Runs only with the `cuda` feature and a device; otherwise every test is reported as ignored with
//! `skipped: no CUDA device`, never as passed. `sanitizer_subset` is the trial meant for
//! compute-sanitizer's racecheck; `CLATCH_TEST_SCALE=sanitizer` shrinks every trial (fewer and
//! smaller pairs, see `tests/common/scale.rs`).

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_verify")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("sanitizer_subset", gpu::sanitizer_subset),
        Trial::test("small_pairs_every_shape", gpu::small_pairs),
        Trial::test("generated_pairs_default_settings", gpu::generated_pairs),
        Trial::test("generated_pairs_other_settings", gpu::other_settings),
        Trial::test("bench_sized_pairs", gpu::bench_sized_pairs),
        Trial::test("batch_larger_than_one_chunk", gpu::chunked_batch),
        Trial::test("errors_and_edge_cases", gpu::errors_and_edges),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::verify::{
        Camera, Intrinsics, TwoViewGeometry, VerifyConfig, ViewPair, verify_pairs,
    };
    use clatch::{Backend, KeyPoint, Match, Verifier};
    use libtest_mimic::Failed;

    use super::common::scale;
    use super::common::scene_pair::ScenePair;
    use super::common::two_view::{Shape, scene};
    use super::common::verify_cases::{Case, case, differences, other_configs};

    const GPU: Backend = Backend::Cuda { device: 0 };

    /// `config`, with at most 200 trials per estimation under `CLATCH_TEST_SCALE=sanitizer` (a pair
    /// that no homography explains runs to its trial ceiling, 5,295 by default).
    fn scaled(config: VerifyConfig) -> VerifyConfig {
        let trials = config.max_num_trials.min(scale::pick(u32::MAX, 200));
        let min = config.min_num_trials.min(trials);
        config.with_max_num_trials(trials).with_min_num_trials(min)
    }

    /// GPU and CPU on `cases` under `config`: the number of pairs compared, an error naming the
    /// first difference.
    fn compare(cases: &[Case], config: &VerifyConfig) -> Result<usize, Failed> {
        let pairs: Vec<ViewPair<'_>> = cases.iter().map(Case::pair).collect();
        let config = &scaled(config.clone());
        let want = verify_pairs(&pairs, config)?;
        let got = Verifier::new(GPU, config.clone())?.verify_pairs(&pairs)?;
        compare_results(cases, &want, &got)
    }

    fn compare_results(
        cases: &[Case],
        want: &[TwoViewGeometry],
        got: &[TwoViewGeometry],
    ) -> Result<usize, Failed> {
        if want.len() != got.len() {
            return Err(format!("{} geometries for {} pairs", got.len(), want.len()).into());
        }
        let mut differing = 0;
        let mut first = None;
        for ((c, w), g) in cases.iter().zip(want).zip(got) {
            let (count, what) = differences(w, g);
            differing += count;
            if first.is_none() {
                first = what.map(|what| format!("{}: {what}", c.name));
            }
        }
        if differing > 0 {
            return Err(format!(
                "{differing} fields differ over {} pairs; first: {}",
                cases.len(),
                first.unwrap_or_default()
            )
            .into());
        }
        Ok(cases.len())
    }

    /// Cases `0..count` of family `seed`, keeping those with at most `max_matches` matches.
    fn cases(seed: u64, count: usize, max_matches: usize) -> Vec<Case> {
        (0..count)
            .map(|i| case(seed, i))
            .filter(|c| c.matches.len() <= max_matches)
            .collect()
    }

    pub fn sanitizer_subset() -> Result<(), Failed> {
        let cases = cases(5, 60, 24);
        let cases: Vec<Case> = cases.into_iter().step_by(6).collect();
        let n = compare(&cases, &VerifyConfig::default().with_max_num_trials(200))?;
        println!("compared {n} pairs, 0 differences");
        Ok(())
    }

    pub fn small_pairs() -> Result<(), Failed> {
        let cases = cases(1, scale::pick(600, 60), scale::pick(100, 16));
        let n = compare(&cases, &VerifyConfig::default())?;
        println!("compared {n} pairs, 0 differences");
        Ok(())
    }

    pub fn generated_pairs() -> Result<(), Failed> {
        let cases = cases(2, scale::pick(1530, 40), scale::pick(usize::MAX, 40));
        let n = compare(&cases, &VerifyConfig::default())?;
        println!("compared {n} pairs, 0 differences");
        Ok(())
    }

    pub fn other_settings() -> Result<(), Failed> {
        let cases = cases(3, scale::pick(510, 30), scale::pick(usize::MAX, 30));
        let configs = other_configs();
        let mut compared = 0;
        for config in &configs {
            compared += compare(&cases, config)?;
        }
        println!(
            "compared {compared} pairs ({} settings), 0 differences",
            configs.len()
        );
        Ok(())
    }

    /// The bench's pairs: 850 matches, 40 % outliers, with and without intrinsics.
    pub fn bench_sized_pairs() -> Result<(), Failed> {
        let count = scale::pick(96, 4);
        let cases: Vec<Case> = (0..count)
            .map(|i| bench_case(i as u64, scale::pick(850, 60), i % 2 == 0))
            .collect();
        let n = compare(&cases, &VerifyConfig::default())?;
        println!("compared {n} pairs, 0 differences");
        Ok(())
    }

    fn bench_case(seed: u64, n: usize, calibrated: bool) -> Case {
        let shape = [Shape::General, Shape::Planar, Shape::Rotation][seed as usize % 3];
        let pair = ScenePair::new(&scene(1000 + seed, shape, n, 0.4, 0.5));
        Case {
            name: format!("bench pair {seed} ({shape:?}, calibrated {calibrated})"),
            a: pair.a,
            b: pair.b,
            matches: pair.matches,
            cameras: calibrated.then_some(pair.cameras),
            key: seed,
        }
    }

    pub fn chunked_batch() -> Result<(), Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        let cases = cases(4, scale::pick(300, 24), scale::pick(250, 24));
        let pairs: Vec<ViewPair<'_>> = cases.iter().map(Case::pair).collect();
        let config = scaled(VerifyConfig::default());
        let want = verify_pairs(&pairs, &config)?;
        // Half the batch's point records (16 bytes a match; a pair takes more on the device), so at
        // least two chunks at either scale; and one byte: every pair alone.
        let half = cases.iter().map(|c| c.matches.len()).sum::<usize>() * 8;
        for budget in [half, 1] {
            let (got, chunks) =
                clatch::cuda::hooks::verify_pairs_in_chunks(&dev, &pairs, &config, budget)?;
            if chunks < 2 {
                return Err(format!("{chunks} chunk for {} pairs", pairs.len()).into());
            }
            let n = compare_results(&cases, &want, &got)?;
            println!("compared {n} pairs in {chunks} chunks, 0 differences");
        }
        Ok(())
    }

    pub fn errors_and_edges() -> Result<(), Failed> {
        let config = VerifyConfig::default();
        let cpu = Verifier::new(Backend::Cpu, config.clone())?;
        let gpu = Verifier::new(GPU, config.clone())?;
        // No pairs, and pairs without matches.
        if !gpu.verify_pairs(&[])?.is_empty() {
            return Err("an empty batch gives geometries".into());
        }
        let a = [KeyPoint::new(1.0, 2.0), KeyPoint::new(f32::NAN, 3.0)];
        let none: [Match; 0] = [];
        let empty = [ViewPair::new(&a, &a, &none), ViewPair::new(&[], &[], &none)];
        if gpu.verify_pairs(&empty)? != cpu.verify_pairs(&empty)? {
            return Err("pairs without matches differ".into());
        }
        // Bad input: the same typed error, message included, on both backends.
        let out_of_range = [Match {
            query: 0,
            train: 5,
            distance: 0,
        }];
        let nan = [Match {
            query: 1,
            train: 0,
            distance: 0,
        }];
        let good = [Match {
            query: 0,
            train: 0,
            distance: 0,
        }];
        let flat = Camera::new(0, 10);
        let bad_focal = Camera::new(10, 10).with_intrinsics(Intrinsics::new(-1.0, 1.0, 0.0, 0.0));
        let batches: Vec<Vec<ViewPair<'_>>> = vec![
            vec![
                ViewPair::new(&a, &a, &good),
                ViewPair::new(&a, &a, &out_of_range),
            ],
            vec![ViewPair::new(&a, &a, &nan)],
            vec![ViewPair::new(&a, &a, &good).with_cameras(&flat, &flat)],
            vec![ViewPair::new(&a, &a, &good).with_cameras(&bad_focal, &bad_focal)],
        ];
        for pairs in &batches {
            let (c, g) = (cpu.verify_pairs(pairs), gpu.verify_pairs(pairs));
            match (c, g) {
                (Err(c), Err(g)) if c.to_string() == g.to_string() && c.kind() == g.kind() => {}
                (c, g) => return Err(format!("cpu {c:?}, gpu {g:?}").into()),
            }
        }
        // A bad configuration is refused at construction, on either backend.
        let bad = VerifyConfig::default().with_confidence(1.5);
        for backend in [Backend::Cpu, GPU] {
            if Verifier::new(backend, bad.clone()).is_ok() {
                return Err(format!("confidence 1.5 accepted on {backend}").into());
            }
        }
        println!("compared {} bad batches and 2 empty pairs", batches.len());
        Ok(())
    }
}
