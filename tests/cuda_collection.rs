//! The device-resident `DescriptorCollection` and grouped matching (`kernels/match_pairs.cu`) against
//! the CPU, pair by pair: every pair's kept matches equal `Matcher::match_descriptors` on the CPU (no
//! matches for a pair without queries or with too small a gallery), ties included; differences are
//! counted and must be 0.
//!
//! Runs only with the `cuda` feature and a device; otherwise every test is reported as ignored with
//! `skipped: no CUDA device`, never as passed. `CLATCH_TEST_SCALE=sanitizer` shrinks every trial
//! (fewer widths and configurations, smaller sets) so that the whole binary runs under racecheck.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_collection")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test(
            "collection_every_width_and_config",
            gpu::every_width_and_config,
        ),
        Trial::test("collection_tile_boundaries", gpu::tile_boundaries),
        Trial::test("collection_many_blocks", gpu::many_blocks),
        Trial::test("collection_search", gpu::search),
        Trial::test("collection_grows_and_matches_again", gpu::grows),
        Trial::test(
            "collection_match_pairs_of_the_matcher",
            gpu::matcher_match_pairs,
        ),
        Trial::test("collection_exhaustive_512_bits", gpu::exhaustive),
        Trial::test(
            "collection_two_threads_and_reentrant_callbacks",
            gpu::concurrent_and_reentrant,
        ),
        Trial::test("collection_add_pending_equals_the_cpu", gpu::add_pending),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::cuda::hooks::{HeldCollection, MatchKernel};
    use clatch::synthetic::SplitMix64;
    use clatch::{
        Backend, DescriptorCollection, DescriptorSet, DescriptorWidth, Match, MatchConfig, Matcher,
    };
    use libtest_mimic::Failed;

    use super::common::{match_configs, random_set, scale, tied_collection};

    const GPU: Backend = Backend::Cuda { device: 0 };
    const WIDTHS: [usize; 7] = [8, 64, 72, 136, 256, 504, 512];

    fn matcher(backend: Backend, config: &MatchConfig) -> Result<Matcher, Failed> {
        Ok(Matcher::new(backend, config.clone())?)
    }

    /// Every filter combination; under `CLATCH_TEST_SCALE=sanitizer` every fifth.
    fn configs() -> Vec<MatchConfig> {
        scale::thin(match_configs(), 5)
    }

    /// The kernel families the device runs: popcount always, the tensor cores where it has them.
    fn families() -> Result<Vec<MatchKernel>, Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        let mut all = vec![MatchKernel::Popcount];
        if dev.has_tensor_matcher() {
            all.push(MatchKernel::Tensor);
        }
        Ok(all)
    }

    /// Every pair of `sets` both ways through `match_pairs_in_blocks` on each family (the default
    /// budget), against `want`.
    fn every_family(
        what: &str,
        sets: &[&DescriptorSet],
        pairs: &[(usize, usize)],
        config: &MatchConfig,
        want: &[Vec<Match>],
    ) -> Result<(), Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        for family in families()? {
            let got = clatch::cuda::hooks::match_pairs_in_blocks(
                dev.clone(),
                sets,
                pairs,
                config,
                (1 << 16, 1 << 21),
                Some(family),
            )?;
            compare(
                &format!("{what}, {config:?}, {family:?}"),
                want,
                &got,
                &|i| format!("pair {:?}", pairs[i]),
            )?;
        }
        Ok(())
    }

    /// What pair (query, train) must give.
    fn expected(cpu: &Matcher, query: &DescriptorSet, train: &DescriptorSet) -> Vec<Match> {
        let needed = if cpu.config().ratio.is_some() { 2 } else { 1 };
        if query.is_empty() || train.len() < needed {
            return Vec::new();
        }
        cpu.match_descriptors(query, train).expect("valid sets")
    }

    /// Compares per-pair results with the CPU's: `Err` naming the first differing pair and how many
    /// differ; `Ok` the number of matches compared.
    fn compare(
        what: &str,
        expected: &[Vec<Match>],
        got: &[Vec<Match>],
        labels: &dyn Fn(usize) -> String,
    ) -> Result<usize, Failed> {
        if expected.len() != got.len() {
            return Err(
                format!("{what}: {} results, expected {}", got.len(), expected.len()).into(),
            );
        }
        let differing: Vec<usize> = (0..got.len()).filter(|&i| expected[i] != got[i]).collect();
        if let Some(&i) = differing.first() {
            let at = expected[i].iter().zip(&got[i]).position(|(a, b)| a != b);
            return Err(format!(
                "{what}: {} of {} pairs differ; first {}: cpu kept {}, gpu {}; first difference at {at:?}: cpu {:?} gpu {:?}",
                differing.len(),
                got.len(),
                labels(i),
                expected[i].len(),
                got[i].len(),
                at.map(|j| expected[i][j]),
                at.map(|j| got[i][j]),
            )
            .into());
        }
        Ok(expected.iter().map(Vec::len).sum())
    }

    /// The collection's results on the GPU for `pairs`, checked to come once per pair in order.
    fn gpu_pairs(
        c: &DescriptorCollection,
        pairs: &[(usize, usize)],
    ) -> Result<Vec<Vec<Match>>, Failed> {
        let mut out = Vec::new();
        let mut order = true;
        c.match_pairs_each(pairs, |i, m| {
            order &= i == out.len();
            out.push(m);
        })?;
        if !order {
            return Err("results not handed out once per pair in order".into());
        }
        Ok(out)
    }

    /// Every pair of `sets` both ways (each set with itself too) through a GPU collection, against the
    /// CPU, under each of `configs`; the matches compared.
    fn all_ways(
        what: &str,
        sets: &[DescriptorSet],
        configs: &[MatchConfig],
    ) -> Result<usize, Failed> {
        let n = sets.len();
        let pairs: Vec<(usize, usize)> = (0..n).flat_map(|a| (0..n).map(move |b| (a, b))).collect();
        let refs: Vec<&DescriptorSet> = sets.iter().collect();
        let mut compared = 0;
        for config in configs {
            let cpu = matcher(Backend::Cpu, config)?;
            let mut c = DescriptorCollection::new(&matcher(GPU, config)?, sets[0].width())?;
            c.add(&refs)?;
            let got = gpu_pairs(&c, &pairs)?;
            let want: Vec<Vec<Match>> = pairs
                .iter()
                .map(|&(a, b)| expected(&cpu, &sets[a], &sets[b]))
                .collect();
            let label = |i: usize| {
                let (a, b) = pairs[i];
                format!(
                    "pair ({a}, {b}) of {} x {} rows",
                    sets[a].len(),
                    sets[b].len()
                )
            };
            compared += compare(&format!("{what}, {config:?}"), &want, &got, &label)?;
            every_family(what, &refs, &pairs, config, &want)?;
        }
        Ok(compared)
    }

    pub fn every_width_and_config() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(41);
        let sizes = scale::pick(vec![0, 1, 2, 300, 65, 257, 1000], vec![0, 1, 2, 70, 257]);
        let mut compared = 0;
        for bits in scale::thin(WIDTHS, 3) {
            let tied = tied_collection(bits, &sizes, &mut rng);
            compared += all_ways(&format!("tied {bits} bits"), &tied, &configs())?;
            let w = DescriptorWidth::from_bits(bits)?;
            let random: Vec<DescriptorSet> =
                sizes.iter().map(|&n| random_set(w, n, &mut rng)).collect();
            compared += all_ways(&format!("random {bits} bits"), &random, &configs()[..1])?;
        }
        println!(
            "{} widths, sizes {sizes:?}, {} configurations: {compared} matches, 0 differences",
            scale::thin(WIDTHS, 3).len(),
            configs().len()
        );
        Ok(())
    }

    pub fn tile_boundaries() -> Result<(), Failed> {
        // Around the 64-row tile, the 256-query block and the 16-row set alignment.
        let mut rng = SplitMix64::new(42);
        let sizes = scale::pick(
            vec![
                1, 15, 16, 17, 63, 64, 65, 127, 128, 129, 255, 256, 257, 511, 513,
            ],
            vec![1, 16, 63, 65, 255, 257],
        );
        let mut compared = 0;
        for bits in [72, 512] {
            let sets = tied_collection(bits, &sizes, &mut rng);
            compared += all_ways(
                &format!("tied {bits} bits"),
                &sets,
                &scale::thin(match_configs(), 7),
            )?;
        }
        println!("sizes {sizes:?}, every pair both ways: {compared} matches, 0 differences");
        Ok(())
    }

    pub fn many_blocks() -> Result<(), Failed> {
        // Budgets of a few pairs or rows per block: many blocks, both slots, blocks of one pair larger
        // than the budget, blocks with no device work (empty and one-row sets run together).
        let mut rng = SplitMix64::new(43);
        let sizes = scale::pick(
            vec![0, 0, 1, 300, 1, 0, 700, 2, 40, 0, 1, 513, 90],
            vec![0, 0, 1, 300, 1, 0, 70, 2],
        );
        let sets = tied_collection(136, &sizes, &mut rng);
        let refs: Vec<&DescriptorSet> = sets.iter().collect();
        let n = sets.len();
        let mut pairs: Vec<(usize, usize)> =
            (0..n).flat_map(|a| (0..n).map(move |b| (a, b))).collect();
        let extra = scale::pick(50, 10);
        pairs.extend(
            (0..extra).map(|_| (rng.below(n as u64) as usize, rng.below(n as u64) as usize)),
        );
        let dev = clatch::cuda::hooks::device(0)?;
        let mut compared = 0;
        // Under the sanitizer scale every pair runs once per (configuration, family, budget) and each
        // block is a launch: fewer configurations and budgets, the block shapes all still there.
        for config in scale::thin(match_configs(), scale::pick(4, 13)) {
            let cpu = matcher(Backend::Cpu, &config)?;
            let want: Vec<Vec<Match>> = pairs
                .iter()
                .map(|&(a, b)| expected(&cpu, &sets[a], &sets[b]))
                .collect();
            for family in families()? {
                for budget in scale::thin([(1, 1 << 20), (3, 1 << 20), (1 << 16, 400), (7, 100)], 2)
                {
                    let got = clatch::cuda::hooks::match_pairs_in_blocks(
                        dev.clone(),
                        &refs,
                        &pairs,
                        &config,
                        budget,
                        Some(family),
                    )?;
                    let label = |i: usize| format!("pair {:?}", pairs[i]);
                    compared += compare(
                        &format!("{config:?}, {family:?}, blocks of {budget:?}"),
                        &want,
                        &got,
                        &label,
                    )?;
                }
            }
        }
        println!(
            "{} pairs in blocks of 1, 3, 7 pairs and of 100, 400 rows: {compared} matches, 0 differences",
            pairs.len()
        );
        Ok(())
    }

    pub fn search() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(44);
        let sizes = scale::pick(vec![500, 0, 1, 2, 64, 1000, 257], vec![100, 0, 1, 2, 257]);
        let dev = clatch::cuda::hooks::device(0)?;
        let mut compared = 0;
        for bits in scale::thin([8, 64, 256, 512], 3) {
            let sets = tied_collection(bits, &sizes, &mut rng);
            let refs: Vec<&DescriptorSet> = sets.iter().collect();
            let queries = tied_collection(bits, &[0, 1, scale::pick(700, 90)], &mut rng);
            for config in configs() {
                let cpu = matcher(Backend::Cpu, &config)?;
                let mut c = DescriptorCollection::new(&matcher(GPU, &config)?, sets[0].width())?;
                c.add(&refs)?;
                for query in &queries {
                    let want: Vec<Vec<Match>> =
                        sets.iter().map(|s| expected(&cpu, query, s)).collect();
                    let mut got = Vec::new();
                    c.search_each(query, |_, m| got.push(m))?;
                    let label = |i: usize| {
                        format!("set {i} ({} rows), {} queries", sets[i].len(), query.len())
                    };
                    compared += compare(
                        &format!("search, {bits} bits, {config:?}"),
                        &want,
                        &got,
                        &label,
                    )?;
                    let ids = [sets.len() - 1, 0, sets.len() - 1];
                    let mut listed = Vec::new();
                    c.search_sets_each(query, &ids, |_, m| listed.push(m))?;
                    let want_listed: Vec<Vec<Match>> =
                        ids.iter().map(|&i| want[i].clone()).collect();
                    compare(
                        &format!("search_sets, {bits} bits"),
                        &want_listed,
                        &listed,
                        &|i| format!("id {}", ids[i]),
                    )?;
                    for family in families()? {
                        let small = clatch::cuda::hooks::search_in_blocks(
                            dev.clone(),
                            &refs,
                            query,
                            &config,
                            (2, 300),
                            Some(family),
                        )?;
                        compare(
                            &format!("search in small blocks, {bits} bits, {family:?}"),
                            &want,
                            &small,
                            &label,
                        )?;
                    }
                }
            }
        }
        println!(
            "a query set against every held set (and listed ones, and in small blocks): {compared} matches, 0 differences"
        );
        Ok(())
    }

    pub fn grows() -> Result<(), Failed> {
        // Sets added one call at a time (the buffer grows, copied on the device), matched after each.
        let mut rng = SplitMix64::new(45);
        let config = MatchConfig::default();
        let cpu = matcher(Backend::Cpu, &config)?;
        let mut c = DescriptorCollection::new(&matcher(GPU, &config)?, DescriptorWidth::FULL)?;
        let mut sets: Vec<DescriptorSet> = Vec::new();
        let mut compared = 0;
        for round in 0..scale::pick(6, 3) {
            let added = tied_collection(512, &[scale::pick(400, 60) + 37 * round, 1, 5], &mut rng);
            let refs: Vec<&DescriptorSet> = added.iter().collect();
            let ids = c.add(&refs)?;
            if ids != (sets.len()..sets.len() + added.len()) {
                return Err(format!("round {round}: ids {ids:?}").into());
            }
            sets.extend(added);
            let pairs = Matcher::all_pairs(sets.len());
            let got = gpu_pairs(&c, &pairs)?;
            let want: Vec<Vec<Match>> = pairs
                .iter()
                .map(|&(a, b)| expected(&cpu, &sets[a], &sets[b]))
                .collect();
            compared += compare(&format!("round {round}"), &want, &got, &|i| {
                format!("pair {:?}", pairs[i])
            })?;
        }
        println!(
            "{} sets added in rounds, all pairs after each: {compared} matches, 0 differences",
            sets.len()
        );
        Ok(())
    }

    pub fn matcher_match_pairs() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(46);
        let sizes = scale::thin([700, 0, 1, 2000, 65, 1500, 300, 9], 2);
        let sets = tied_collection(256, &sizes, &mut rng);
        let refs: Vec<&DescriptorSet> = sets.iter().collect();
        let mut pairs = Matcher::all_pairs(sets.len());
        pairs.extend([(3, 3), (1, 0), (0, 1), (3, 0)]);
        let mut compared = 0;
        for config in configs() {
            let want = matcher(Backend::Cpu, &config)?.match_pairs(&refs, &pairs)?;
            let done = std::sync::Mutex::new(Vec::new());
            let got = matcher(GPU, &config)?
                .match_pairs_with_progress(&refs, &pairs, &|p| done.lock().unwrap().push(p))?;
            if *done.lock().unwrap() != (0..pairs.len()).collect::<Vec<_>>() {
                return Err(format!("{config:?}: pairs not reported once each in order").into());
            }
            compared += compare(&format!("{config:?}"), &want, &got, &|i| {
                format!("pair {:?}", pairs[i])
            })?;
        }
        println!(
            "Matcher::match_pairs, {} pairs x {} configurations: {compared} matches, 0 differences",
            pairs.len(),
            configs().len()
        );
        Ok(())
    }

    pub fn exhaustive() -> Result<(), Failed> {
        // Many pairs of realistic size in one collection: 512 bits, the default configuration.
        let mut rng = SplitMix64::new(47);
        let (n, rows) = scale::pick((24, 2000), (6, 300));
        let sizes: Vec<usize> = (0..n).map(|i| rows - 37 * (i % 5)).collect();
        let sets = tied_collection(512, &sizes, &mut rng);
        let refs: Vec<&DescriptorSet> = sets.iter().collect();
        let config = MatchConfig::default();
        let cpu = matcher(Backend::Cpu, &config)?;
        let mut c = DescriptorCollection::new(&matcher(GPU, &config)?, DescriptorWidth::FULL)?;
        c.add(&refs)?;
        let pairs = Matcher::all_pairs(n);
        let mut got = Vec::new();
        c.match_all_pairs_each(|_, m| got.push(m))?;
        let want: Vec<Vec<Match>> = pairs
            .iter()
            .map(|&(a, b)| expected(&cpu, &sets[a], &sets[b]))
            .collect();
        let compared = compare("exhaustive", &want, &got, &|i| {
            format!("pair {:?}", pairs[i])
        })?;
        println!(
            "{n} sets of about {rows}, {} pairs: {compared} matches, 0 differences",
            pairs.len()
        );
        Ok(())
    }

    /// What one run of `pairs` on `held` gave, checked to come once per pair in order; `inner` is
    /// called inside the callback before each pair's result is kept (a re-entrant run, or nothing).
    fn held_run(
        held: &HeldCollection,
        pairs: &[(usize, usize)],
        config: &MatchConfig,
        family: MatchKernel,
        inner: &mut dyn FnMut(usize),
    ) -> Result<Vec<Vec<Match>>, Failed> {
        let mut out = Vec::new();
        let mut order = true;
        // Small blocks: both slots in flight while a callback runs.
        held.match_pairs(pairs, config, (3, 1 << 21), Some(family), &mut |i, m| {
            inner(i);
            order &= i == out.len();
            out.push(m);
        })?;
        if !order {
            return Err("results not handed out once per pair in order".into());
        }
        Ok(out)
    }

    pub fn concurrent_and_reentrant() -> Result<(), Failed> {
        // One collection matched from two threads at once, and again from inside its own callbacks
        // (pairs and a search), on each kernel family: no lock is held while callbacks run, and every
        // run's pinned results are its own.
        let mut rng = SplitMix64::new(48);
        let dev = clatch::cuda::hooks::device(0)?;
        let sizes = scale::pick(vec![300, 0, 65, 700, 2, 257, 1], vec![70, 0, 65, 2, 1]);
        let repeats = scale::pick(4, 2);
        let mut compared = 0;
        for bits in scale::thin([72, 512], 2) {
            let sets = tied_collection(bits, &sizes, &mut rng);
            let refs: Vec<&DescriptorSet> = sets.iter().collect();
            let query = &tied_collection(bits, &[scale::pick(400, 50)], &mut rng)[0];
            let n = sets.len();
            let pairs: Vec<(usize, usize)> =
                (0..n).flat_map(|a| (0..n).map(move |b| (a, b))).collect();
            let reversed: Vec<(usize, usize)> = pairs.iter().rev().copied().collect();
            for config in scale::thin(configs(), 3) {
                let cpu = matcher(Backend::Cpu, &config)?;
                let want = |list: &[(usize, usize)]| -> Vec<Vec<Match>> {
                    list.iter()
                        .map(|&(a, b)| expected(&cpu, &sets[a], &sets[b]))
                        .collect()
                };
                let (want_pairs, want_reversed) = (want(&pairs), want(&reversed));
                let want_search: Vec<Vec<Match>> =
                    sets.iter().map(|set| expected(&cpu, query, set)).collect();
                let label = |list: &[(usize, usize)], i: usize| format!("pair {:?}", list[i]);
                for family in families()? {
                    let what = format!("{bits} bits, {config:?}, {family:?}");
                    let held = HeldCollection::new(dev.clone(), &refs)?;
                    // Two threads, each running its list several times, at once.
                    let run = |list: &[(usize, usize)]| {
                        (0..repeats)
                            .map(|_| {
                                held_run(&held, list, &config, family, &mut |_| {})
                                    .map_err(|e| format!("{e:?}"))
                            })
                            .collect::<Result<Vec<_>, String>>()
                    };
                    let (first, second) = std::thread::scope(|scope| {
                        let first = scope.spawn(|| run(&pairs));
                        let second = scope.spawn(|| run(&reversed));
                        (first.join(), second.join())
                    });
                    let first =
                        first.map_err(|_| format!("{what}: the first thread panicked"))??;
                    let second =
                        second.map_err(|_| format!("{what}: the second thread panicked"))??;
                    for got in &first {
                        compared +=
                            compare(&format!("{what}, thread 1"), &want_pairs, got, &|i| {
                                label(&pairs, i)
                            })?;
                    }
                    for got in &second {
                        compared +=
                            compare(&format!("{what}, thread 2"), &want_reversed, got, &|i| {
                                label(&reversed, i)
                            })?;
                    }
                    // Re-entrant: inside the callback of each pair, a run of two pairs; inside the
                    // first, a whole run and a search.
                    let mut inner_failures: Vec<String> = Vec::new();
                    let mut inner_compared = 0;
                    let outer = held_run(&held, &pairs, &config, family, &mut |i| {
                        let check = || -> Result<usize, Failed> {
                            let j = (i * 7 + 3) % pairs.len();
                            let two = [pairs[i], pairs[j]];
                            let got = held_run(&held, &two, &config, family, &mut |_| {})?;
                            let mut done = compare(
                                &format!("{what}, inside pair {i}"),
                                &want(&two),
                                &got,
                                &|k| label(&two, k),
                            )?;
                            if i == 0 {
                                let got = held_run(&held, &reversed, &config, family, &mut |_| {})?;
                                done += compare(
                                    &format!("{what}, inside pair 0"),
                                    &want_reversed,
                                    &got,
                                    &|k| label(&reversed, k),
                                )?;
                                let mut found = Vec::new();
                                held.search(
                                    query,
                                    &config,
                                    (2, 1 << 21),
                                    Some(family),
                                    &mut |_, m| found.push(m),
                                )?;
                                done += compare(
                                    &format!("{what}, search inside pair 0"),
                                    &want_search,
                                    &found,
                                    &|k| format!("set {k}"),
                                )?;
                            }
                            Ok(done)
                        };
                        match check() {
                            Ok(done) => inner_compared += done,
                            Err(e) => inner_failures.push(format!("{e:?}")),
                        }
                    })?;
                    if let Some(first) = inner_failures.first() {
                        return Err(format!(
                            "{} of {} re-entrant runs failed; first: {first}",
                            inner_failures.len(),
                            pairs.len()
                        )
                        .into());
                    }
                    compared += inner_compared;
                    compared +=
                        compare(&format!("{what}, outer run"), &want_pairs, &outer, &|i| {
                            label(&pairs, i)
                        })?;
                }
            }
        }
        // The public collection (the device's family) the same ways.
        let config = MatchConfig::default().with_cross_check(true);
        let cpu = matcher(Backend::Cpu, &config)?;
        let sets = tied_collection(256, &sizes, &mut rng);
        let refs: Vec<&DescriptorSet> = sets.iter().collect();
        let mut c = DescriptorCollection::new(&matcher(GPU, &config)?, sets[0].width())?;
        c.add(&refs)?;
        let pairs = Matcher::all_pairs(sets.len());
        let want: Vec<Vec<Match>> = pairs
            .iter()
            .map(|&(a, b)| expected(&cpu, &sets[a], &sets[b]))
            .collect();
        let (first, second) = std::thread::scope(|scope| {
            let run = || gpu_pairs(&c, &pairs).map_err(|e| format!("{e:?}"));
            let first = scope.spawn(run);
            let second = scope.spawn(run);
            (first.join(), second.join())
        });
        for got in [first, second] {
            let got = got.map_err(|_| "a thread panicked")??;
            compared += compare("public collection, two threads", &want, &got, &|i| {
                format!("pair {:?}", pairs[i])
            })?;
        }
        let mut inner = Vec::new();
        let outer = {
            let mut out = Vec::new();
            c.match_pairs_each(&pairs, |i, m| {
                inner.push(gpu_pairs(&c, &pairs[i..=i]).map_err(|e| format!("{e:?}")));
                out.push(m);
            })?;
            out
        };
        compared += compare("public collection, outer run", &want, &outer, &|i| {
            format!("pair {:?}", pairs[i])
        })?;
        for (i, got) in inner.into_iter().enumerate() {
            compared += compare(
                &format!("public collection, inside pair {i}"),
                &want[i..=i],
                &got?,
                &|_| format!("pair {:?}", pairs[i]),
            )?;
        }
        println!(
            "one collection from two threads and from its own callbacks: {compared} matches, 0 differences"
        );
        Ok(())
    }

    /// Features handed from extraction to a collection on the device (`add_pending`: no host copy of
    /// the descriptors) equal the CPU's extraction bit for bit (read back from the device), and every
    /// pair of such sets matches as the CPU matches the CPU's features; with the default pyramid (its
    /// rows gathered into the reported order) and the single-scale preset, several images in flight
    /// on two streams, an image without keypoints, a host-added set in between, a CPU collection
    /// taking the same pending results, and a width mismatch refused with nothing added.
    pub fn add_pending() -> Result<(), Failed> {
        use clatch::cuda::GpuStream;
        use clatch::cuda::hooks::read_set;
        use clatch::{Error, Extractor, ExtractorConfig, GrayView};

        let sizes: Vec<(usize, usize)> = scale::pick(
            vec![(640, 480), (1280, 720), (333, 257), (800, 600)],
            vec![(320, 240), (333, 257)],
        );
        let mut images: Vec<(Vec<u8>, usize, usize)> = sizes
            .iter()
            .enumerate()
            .map(|(i, &(w, h))| Ok((clatch::synthetic::rectangles(w, h, 40 + i as u64)?, w, h)))
            .collect::<Result<_, clatch::Error>>()?;
        // A blank image: no keypoints, an empty set.
        images.insert(1, (vec![128; 300 * 200], 300, 200));
        fn view((p, w, h): &(Vec<u8>, usize, usize)) -> clatch::Result<GrayView<'_>> {
            GrayView::new(p, *w, *h, *w)
        }
        let streams = [GpuStream::new(0)?, GpuStream::new(0)?];
        let config = MatchConfig::default();
        let (gpu_matcher, cpu_matcher) = (matcher(GPU, &config)?, matcher(Backend::Cpu, &config)?);
        let mut differences = 0usize;
        for extractor_config in [ExtractorConfig::default(), ExtractorConfig::single_scale()] {
            let gpu = Extractor::new(GPU, extractor_config.clone())?;
            let cpu = Extractor::new(Backend::Cpu, extractor_config.clone())?;
            let width = extractor_config.descriptor.width;
            let mut on_device = DescriptorCollection::new(&gpu_matcher, width)?;
            let mut on_host = DescriptorCollection::new(&cpu_matcher, width)?;
            let mut host_taken = DescriptorCollection::new(&cpu_matcher, width)?;
            let wanted = images
                .iter()
                .map(|i| cpu.detect_and_describe(&view(i)?))
                .collect::<Result<Vec<_>, clatch::Error>>()?;
            // Everything queued first (two streams, several images in flight), then taken in order.
            let pending = images
                .iter()
                .enumerate()
                .map(|(i, image)| gpu.detect_and_describe_async(&streams[i % 2], &view(image)?))
                .collect::<Result<Vec<_>, clatch::Error>>()?;
            for (i, (p, want)) in pending.into_iter().zip(&wanted).enumerate() {
                if i == 2 {
                    // A set added from the host between device-added ones.
                    on_device.add(&[&wanted[0].descriptors])?;
                    on_host.add(&[&wanted[0].descriptors])?;
                }
                let (id, keypoints) = on_device.add_pending(p)?;
                on_host.add(&[&want.descriptors])?;
                if id != on_host.len() - 1 || keypoints != want.keypoints {
                    differences += 1;
                    eprintln!(
                        "image {i}: id {id}, {} keypoints, {} wanted",
                        keypoints.len(),
                        want.keypoints.len()
                    );
                }
                if read_set(&on_device, id)? != want.descriptors {
                    differences += 1;
                    eprintln!("image {i}: descriptors on the device differ from the CPU's");
                }
                // The same pending result taken by a CPU collection (it waits and keeps the copy).
                let again = gpu.detect_and_describe_async(&streams[0], &view(&images[i])?)?;
                let (_, keypoints) = host_taken.add_pending(again)?;
                if keypoints != want.keypoints {
                    differences += 1;
                }
            }
            let (mut device_pairs, mut host_pairs) = (Vec::new(), Vec::new());
            on_device.match_all_pairs_each(|_, m| device_pairs.push(m))?;
            on_host.match_all_pairs_each(|_, m| host_pairs.push(m))?;
            let kept: usize = host_pairs.iter().map(Vec::len).sum();
            differences += device_pairs
                .iter()
                .zip(&host_pairs)
                .filter(|(a, b)| a != b)
                .count();
            differences += device_pairs.len().abs_diff(host_pairs.len());
            println!(
                "add_pending, {} levels: {} sets, {} pairs, {kept} matches kept",
                extractor_config.pyramid.map_or(1, |p| p.levels),
                on_device.len(),
                host_pairs.len()
            );
            if kept == 0 {
                return Err(
                    "the images gave no matches: the comparison would prove nothing".into(),
                );
            }
            // A width mismatch is refused before anything is added.
            let narrow = DescriptorWidth::from_bits(256)?;
            let mut other = DescriptorCollection::new(&gpu_matcher, narrow)?;
            let refused =
                other.add_pending(gpu.detect_and_describe_async(&streams[1], &view(&images[0])?)?);
            if !matches!(refused, Err(Error::DescriptorWidthMismatch { .. })) || !other.is_empty() {
                return Err(format!("width mismatch: {refused:?}, {} sets", other.len()).into());
            }
        }
        if differences > 0 {
            return Err(format!("{differences} differences").into());
        }
        Ok(())
    }
}
