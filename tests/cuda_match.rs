//! GPU against CPU matching, result for result: kNN indices and distances (ties included) and the kept
//! matches of `match_descriptors` under every filter combination.
//!
//! Runs only with the `cuda` feature and a device; otherwise every test is reported as ignored with
//! `skipped: no CUDA device`, never as passed. The trials named `small_*` are the subset meant for
//! compute-sanitizer (`cuda_match small_`); `sanitizer_subset` is smaller still, for racecheck.
//! `CLATCH_TEST_SCALE=sanitizer` shrinks every trial (fewer widths, k values, configurations, smaller
//! sets, see `tests/common/scale.rs`) so that the whole binary runs under racecheck.

mod common;

use libtest_mimic::Trial;

fn main() {
    common::gpu::run(trials())
}

#[cfg(not(feature = "cuda"))]
fn trials() -> Vec<Trial> {
    common::gpu::feature_missing("cuda_match")
}

#[cfg(feature = "cuda")]
fn trials() -> Vec<Trial> {
    vec![
        Trial::test("sanitizer_subset", gpu::sanitizer_subset),
        Trial::test("small_knn_every_width_and_k", gpu::small_knn),
        Trial::test("small_knn_planted_ties", gpu::small_ties),
        Trial::test("small_match_every_config", gpu::small_match),
        Trial::test("small_errors_and_edge_cases", gpu::errors_and_edges),
        Trial::test("knn_random_every_width_and_k", gpu::knn_random),
        Trial::test("knn_planted_ties", gpu::knn_ties),
        Trial::test("knn_large_and_grid_limits", gpu::knn_large),
        Trial::test("match_every_config", gpu::every_config),
        Trial::test("match_ratio_boundary", gpu::ratio_boundary),
        Trial::test("match_real_descriptors_rotated", gpu::real_descriptors),
        Trial::test("match_pairs_of_a_collection", gpu::match_pairs),
    ]
}

#[cfg(feature = "cuda")]
mod gpu {
    use clatch::cuda::hooks::MatchKernel;
    use clatch::synthetic::SplitMix64;
    use clatch::{
        Backend, DescriptorSet, DescriptorWidth, Error, Extractor, ExtractorConfig, KnnMatches,
        MatchConfig, Matcher,
    };
    use libtest_mimic::Failed;

    use super::common::{astronaut, flip_bits, match_configs, random_set, scale};

    const GPU: Backend = Backend::Cuda { device: 0 };
    const WIDTHS: [usize; 7] = [8, 64, 72, 136, 256, 504, 512];
    /// Segment lengths forced on the kNN, in tiles: one block per tile, an odd count, one segment.
    const SEGMENTS: [usize; 3] = [1, 3, usize::MAX];

    /// The widths of [`WIDTHS`], every `n`-th one (and the last) under `CLATCH_TEST_SCALE=sanitizer`.
    fn widths(n: usize) -> Vec<usize> {
        scale::thin(WIDTHS, n)
    }

    /// k = 1..=`max`; under `CLATCH_TEST_SCALE=sanitizer` 1, 2, 3 and 8 (lists of 1, 2, 4 and 8).
    fn ks(max: usize) -> Vec<usize> {
        scale::pick((1..=8).collect(), vec![1, 2, 3, 8])
            .into_iter()
            .filter(|&k| k <= max)
            .collect()
    }

    /// Every filter combination; under `CLATCH_TEST_SCALE=sanitizer` every fifth (each ratio, each
    /// cross-check setting and each distance limit still among them).
    fn configs() -> Vec<MatchConfig> {
        scale::thin(match_configs(), 5)
    }

    /// The kNN kernel families the device runs for k neighbours: the popcount kernels always, the
    /// tensor-core kernels where the device has them and k <= 2.
    fn families(k: usize) -> Result<Vec<MatchKernel>, Failed> {
        let dev = clatch::cuda::hooks::device(0)?;
        let mut all = vec![MatchKernel::Popcount];
        if dev.has_tensor_matcher() && k <= 2 {
            all.push(MatchKernel::Tensor);
        }
        Ok(all)
    }

    fn matcher(backend: Backend, config: MatchConfig) -> Matcher {
        Matcher::new(backend, config).expect("valid matcher")
    }

    fn plain() -> MatchConfig {
        MatchConfig::default()
            .with_ratio(None)
            .with_cross_check(false)
            .with_max_distance(None)
    }

    fn describe_difference(what: &str, cpu: &KnnMatches, gpu: &KnnMatches) -> Failed {
        if cpu.as_slice().len() != gpu.as_slice().len() {
            return format!(
                "{what}: cpu returned {} matches, gpu {}",
                cpu.as_slice().len(),
                gpu.as_slice().len()
            )
            .into();
        }
        let q = (0..cpu.len())
            .find(|&q| cpu.neighbours(q) != gpu.neighbours(q))
            .unwrap_or(0);
        let differing = (0..cpu.len())
            .filter(|&q| cpu.neighbours(q) != gpu.neighbours(q))
            .count();
        format!(
            "{what}: {differing} of {} queries differ; first, query {q}:\n cpu {:?}\n gpu {:?}",
            cpu.len(),
            cpu.neighbours(q),
            gpu.neighbours(q)
        )
        .into()
    }

    /// kNN on both backends (the GPU through the Matcher and with each forced segment length); returns
    /// the number of descriptor pairs compared per backend run.
    fn compare_knn(
        what: &str,
        query: &DescriptorSet,
        train: &DescriptorSet,
        k: usize,
        segmented: bool,
    ) -> Result<usize, Failed> {
        let cpu = matcher(Backend::Cpu, plain()).knn(query, train, k)?;
        let gpu = matcher(GPU, plain()).knn(query, train, k)?;
        if cpu != gpu {
            return Err(describe_difference(&format!("{what}, k {k}"), &cpu, &gpu));
        }
        let dev = clatch::cuda::hooks::device(0)?;
        let mut runs = 1;
        for family in families(k)? {
            let segments = if segmented { &SEGMENTS[..] } else { &[] };
            for tiles in std::iter::once(None).chain(segments.iter().map(|&t| Some(t))) {
                let got = clatch::cuda::hooks::knn_on(&dev, query, train, k, tiles, family)?;
                if cpu != got {
                    return Err(describe_difference(
                        &format!("{what}, k {k}, {family:?}, segments of {tiles:?} tiles"),
                        &cpu,
                        &got,
                    ));
                }
                runs += 1;
            }
        }
        Ok(runs * query.len() * train.len())
    }

    fn width(bits: usize) -> DescriptorWidth {
        DescriptorWidth::from_bits(bits).unwrap()
    }

    /// A gallery with duplicated rows and rows equidistant from a centre, and queries that are random,
    /// copies of gallery rows, a few bits from gallery rows, or the centre itself.
    fn tied_sets(
        bits: usize,
        n_query: usize,
        n_train: usize,
        seed: u64,
    ) -> (DescriptorSet, DescriptorSet) {
        let w = width(bits);
        let per = w.words();
        let mut rng = SplitMix64::new(seed);
        let base = random_set(w, n_train, &mut rng);
        let mut train: Vec<Vec<u64>> = base.rows().map(|r| r.to_vec()).collect();
        for _ in 0..n_train / 4 {
            let from = rng.below(n_train as u64) as usize;
            let to = rng.below(n_train as u64) as usize;
            train[to] = train[from].clone();
        }
        let centre = train[0].clone();
        for _ in 0..n_train / 8 {
            let mut row = centre.clone();
            flip_bits(&mut row, bits, 3, &mut rng);
            let at = rng.below(n_train as u64) as usize;
            train[at] = row;
        }
        let mut query: Vec<Vec<u64>> = Vec::new();
        for i in 0..n_query {
            let row = match i % 4 {
                0 => (0..per).map(|_| rng.next_u64()).collect(),
                1 => train[rng.below(n_train as u64) as usize].clone(),
                2 => {
                    let mut r = train[rng.below(n_train as u64) as usize].clone();
                    let flips = 1 + rng.below(4) as usize;
                    flip_bits(&mut r, bits, flips, &mut rng);
                    r
                }
                _ => centre.clone(),
            };
            query.push(row);
        }
        let to_set = |rows: Vec<Vec<u64>>| DescriptorSet::from_words(w, rows.concat()).unwrap();
        (to_set(query), to_set(train))
    }

    /// Queries whose k-th and (k+1)-th neighbours are equally far (so the tie rule picks the index).
    fn ties_at_cut(query: &DescriptorSet, train: &DescriptorSet, k: usize) -> usize {
        let all = matcher(Backend::Cpu, plain())
            .knn(query, train, (k + 1).min(train.len()))
            .unwrap();
        all.iter()
            .filter(|n| n.len() > k && n[k - 1].distance == n[k].distance)
            .count()
    }

    /// A few cases through every kernel: the direct and merged kNN paths, k = 1, 2, 8 (lists of 1, 2
    /// and 8), odd and even word counts, partial tiles, and match_descriptors with every filter.
    pub fn sanitizer_subset() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(9);
        let mut pairs = 0;
        for bits in [8, 72, 512] {
            for (nq, nt) in [(1, 1), (7, 300), (257, 129)] {
                let query = random_set(width(bits), nq, &mut rng);
                let train = random_set(width(bits), nt, &mut rng);
                for k in [1, 2, 8] {
                    if k <= nt {
                        pairs += compare_knn(
                            &format!("{bits} bits, {nq}x{nt}"),
                            &query,
                            &train,
                            k,
                            true,
                        )?;
                    }
                }
            }
        }
        let (query, train) = tied_sets(72, 300, 250, 11);
        let (queries, kept) = compare_match("tied 72 bits", &query, &train)?;
        println!(
            "sanitizer subset: {pairs} kNN pairs, {queries} queries matched ({kept} kept): identical"
        );
        Ok(())
    }

    pub fn small_knn() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(1);
        let mut pairs = 0;
        let mut runs = 0;
        for bits in widths(3) {
            for (nq, nt) in scale::thin([(1, 1), (1, 2), (7, 300), (130, 64), (257, 129)], 2) {
                let query = random_set(width(bits), nq, &mut rng);
                let train = random_set(width(bits), nt, &mut rng);
                for k in ks(nt) {
                    pairs +=
                        compare_knn(&format!("{bits} bits, {nq}x{nt}"), &query, &train, k, true)?;
                    runs += 1;
                }
            }
        }
        println!(
            "{runs} kNN runs, {pairs} pairs each on CPU and GPU (and 3 forced segmentations): identical"
        );
        Ok(())
    }

    pub fn small_ties() -> Result<(), Failed> {
        let (mut pairs, mut ties) = (0, 0);
        for (i, bits) in widths(2).into_iter().enumerate() {
            let (query, train) = tied_sets(bits, 200, 150, 40 + i as u64);
            for k in [1, 2, 3, 8] {
                ties += ties_at_cut(&query, &train, k);
                pairs += compare_knn(&format!("tied {bits} bits"), &query, &train, k, true)?;
            }
        }
        if ties < 100 {
            return Err(
                format!("only {ties} ties at the cut: the tie rule was not exercised").into(),
            );
        }
        println!(
            "tied sets: {pairs} pairs, {ties} queries with a tie at the k-th neighbour: identical"
        );
        Ok(())
    }

    /// match_descriptors on both backends under every configuration; returns (queries, kept matches).
    fn compare_match(
        what: &str,
        query: &DescriptorSet,
        train: &DescriptorSet,
    ) -> Result<(usize, usize), Failed> {
        let (mut queries, mut kept) = (0, 0);
        for config in configs() {
            if config.ratio.is_some() && train.len() < 2 {
                continue;
            }
            let cpu = matcher(Backend::Cpu, config.clone()).match_descriptors(query, train)?;
            let dev = clatch::cuda::hooks::device(0)?;
            let mut runs = vec![(
                "Matcher".to_string(),
                matcher(GPU, config.clone()).match_descriptors(query, train)?,
            )];
            for family in families(2)? {
                let got =
                    clatch::cuda::hooks::match_descriptors_on(&dev, query, train, &config, family)?;
                runs.push((format!("{family:?}"), got));
            }
            for (how, gpu) in runs {
                if cpu != gpu {
                    let first = cpu.iter().zip(&gpu).position(|(a, b)| a != b);
                    return Err(format!(
                        "{what}, {config:?}, {how}: cpu kept {}, gpu {}; first difference at {first:?}: cpu {:?} gpu {:?}",
                        cpu.len(),
                        gpu.len(),
                        first.map(|i| cpu[i]),
                        first.map(|i| gpu[i])
                    )
                    .into());
                }
                queries += query.len();
                kept += cpu.len();
            }
        }
        Ok((queries, kept))
    }

    pub fn small_match() -> Result<(), Failed> {
        let (mut queries, mut kept) = (0, 0);
        let mut rng = SplitMix64::new(2);
        for (i, bits) in widths(3).into_iter().enumerate() {
            let (query, train) = tied_sets(bits, 300, 250, 70 + i as u64);
            let (q, k) = compare_match(&format!("tied {bits} bits"), &query, &train)?;
            queries += q;
            kept += k;
            for (nq, nt) in scale::thin([(1, 1), (1, 2), (7, 300), (300, 7)], 3) {
                let query = random_set(width(bits), nq, &mut rng);
                let train = random_set(width(bits), nt, &mut rng);
                let (q, k) = compare_match(&format!("{bits} bits, {nq}x{nt}"), &query, &train)?;
                queries += q;
                kept += k;
            }
        }
        println!(
            "match_descriptors, every config: {queries} queries, {kept} kept matches: identical"
        );
        Ok(())
    }

    pub fn errors_and_edges() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(3);
        let w = width(72);
        let train = random_set(w, 20, &mut rng);
        let query = random_set(w, 5, &mut rng);
        let gpu = matcher(GPU, MatchConfig::default());
        match gpu.knn(&query, &train, 9) {
            Err(Error::KTooLargeForBackend { k: 9, max: 8, .. }) => {}
            other => return Err(format!("k = 9 on the GPU gave {other:?}").into()),
        }
        match gpu.knn(&query, &train, 0) {
            Err(Error::InvalidK { k: 0, .. }) => {}
            other => return Err(format!("k = 0 gave {other:?}").into()),
        }
        match gpu.knn(&query, &random_set(width(64), 3, &mut rng), 1) {
            Err(Error::DescriptorWidthMismatch { .. }) => {}
            other => return Err(format!("mismatched widths gave {other:?}").into()),
        }
        match gpu.match_descriptors(&query, &DescriptorSet::empty(w)) {
            Err(Error::EmptyGallery) => {}
            other => return Err(format!("empty gallery gave {other:?}").into()),
        }
        let empty = DescriptorSet::empty(w);
        if !gpu.knn(&empty, &train, 3)?.is_empty() {
            return Err("an empty query set gave matches".into());
        }
        for config in match_configs() {
            if !matcher(GPU, config)
                .match_descriptors(&empty, &train)?
                .is_empty()
            {
                return Err("an empty query set gave kept matches".into());
            }
        }
        // Every gallery row equal: every query's neighbours are 0..k, whatever the segmentation.
        let row = random_set(width(256), 1, &mut rng);
        let same = DescriptorSet::from_words(width(256), row.as_words().repeat(700)).unwrap();
        let query = random_set(width(256), 333, &mut rng);
        for k in ks(8) {
            compare_knn("all-equal gallery", &query, &same, k, true)?;
        }
        println!(
            "errors (k > 8, k = 0, widths, empty gallery), empty queries, all-equal gallery: as the CPU"
        );
        Ok(())
    }

    pub fn knn_random() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(4);
        let mut pairs = 0;
        let shapes = scale::pick([(1000, 1000), (4097, 3001)], [(100, 100), (257, 301)]);
        for bits in widths(2) {
            for (nq, nt) in shapes {
                let query = random_set(width(bits), nq, &mut rng);
                let train = random_set(width(bits), nt, &mut rng);
                for k in ks(8) {
                    let segmented = (nq, nt) == shapes[0] && (k == 1 || k == 8);
                    pairs += compare_knn(
                        &format!("{bits} bits, {nq}x{nt}"),
                        &query,
                        &train,
                        k,
                        segmented,
                    )?;
                }
            }
        }
        println!(
            "random descriptors, {} widths, k in {:?}, {shapes:?}: {pairs} pairs: identical",
            widths(2).len(),
            ks(8)
        );
        Ok(())
    }

    pub fn knn_ties() -> Result<(), Failed> {
        let (mut pairs, mut ties) = (0, 0);
        let (nq, nt) = scale::pick((3000, 2500), (300, 250));
        for (i, bits) in widths(2).into_iter().enumerate() {
            let (query, train) = tied_sets(bits, nq, nt, 90 + i as u64);
            for k in [1, 2, 4, 5, 8] {
                ties += ties_at_cut(&query, &train, k);
                pairs += compare_knn(&format!("tied {bits} bits"), &query, &train, k, k == 2)?;
            }
        }
        println!(
            "tied sets {nq}x{nt}: {pairs} pairs, {ties} queries with a tie at the k-th neighbour: identical"
        );
        Ok(())
    }

    pub fn knn_large() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(5);
        let mut pairs = 0;
        // CLATCH_TEST_SCALE=sanitizer: 1000x1000 for the large sets, and one gallery row, k = 1, for
        // the grid limit.
        let n = scale::pick(20_000, 1_000);
        let big_query = random_set(width(512), n, &mut rng);
        let big_train = random_set(width(512), n, &mut rng);
        pairs += compare_knn(
            &format!("512 bits, {n}x{n}"),
            &big_query,
            &big_train,
            2,
            false,
        )?;
        let (query, train) = tied_sets(136, n, n, 6);
        pairs += compare_knn(&format!("tied 136 bits, {n}x{n}"), &query, &train, 8, false)?;
        // More queries than a grid of 65535 blocks of one query per thread could hold.
        let (n_few, k) = scale::pick((5, 3), (1, 1));
        let many = random_set(width(8), 65_535 * 128 + 3, &mut rng);
        let few = random_set(width(8), n_few, &mut rng);
        pairs += compare_knn(&format!("8 bits, 8388483x{n_few}"), &many, &few, k, false)?;
        // One query against a long gallery: many segments, merged.
        let one = random_set(width(512), 1, &mut rng);
        let long = random_set(width(512), 200_003, &mut rng);
        pairs += compare_knn("512 bits, 1x200003", &one, &long, 8, false)?;
        pairs += compare_knn("512 bits, 1x200003", &one, &long, 2, false)?;
        println!("large sets and grid limits: {pairs} pairs: identical");
        Ok(())
    }

    pub fn every_config() -> Result<(), Failed> {
        let (mut queries, mut kept) = (0, 0);
        let mut rng = SplitMix64::new(7);
        // CLATCH_TEST_SCALE=sanitizer: a tenth of each set, three widths.
        let (tied, random, large) = scale::pick(
            ((3000, 2000), (4097, 3001), 20_000),
            ((300, 200), (257, 301), 1_000),
        );
        for (i, bits) in widths(3).into_iter().enumerate() {
            let (query, train) = tied_sets(bits, tied.0, tied.1, 200 + i as u64);
            let (q, k) = compare_match(&format!("tied {bits} bits {tied:?}"), &query, &train)?;
            queries += q;
            kept += k;
            let query = random_set(width(bits), random.0, &mut rng);
            let train = random_set(width(bits), random.1, &mut rng);
            let (q, k) = compare_match(&format!("{bits} bits {random:?}"), &query, &train)?;
            queries += q;
            kept += k;
        }
        // Large and tie-heavy: many blocks fold the reverse 1-NN of the same gallery rows.
        let (query, train) = tied_sets(512, large, large, 300);
        for config in [
            MatchConfig::default(),
            MatchConfig::default().with_ratio(None),
        ] {
            let cpu = matcher(Backend::Cpu, config.clone()).match_descriptors(&query, &train)?;
            let dev = clatch::cuda::hooks::device(0)?;
            for family in families(2)? {
                let gpu = clatch::cuda::hooks::match_descriptors_on(
                    &dev, &query, &train, &config, family,
                )?;
                if cpu != gpu {
                    return Err(format!(
                        "tied 512 bits {large}x{large}, {config:?}, {family:?}: cpu kept {}, gpu {}",
                        cpu.len(),
                        gpu.len()
                    )
                    .into());
                }
                queries += query.len();
                kept += cpu.len();
            }
        }
        println!(
            "match_descriptors, every config: {queries} queries, {kept} kept matches: identical"
        );
        Ok(())
    }

    pub fn ratio_boundary() -> Result<(), Failed> {
        // d1 < ratio * d2 in one f32 product, for every d1 < d2 <= 64: query 0 against rows with d1 and
        // d2 low bits set.
        let w = width(64);
        let ones = |n: u32| if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
        let query = DescriptorSet::from_words(w, vec![0]).unwrap();
        let mut cases = 0;
        // CLATCH_TEST_SCALE=sanitizer: four ratios, every ninth d2, and only the d1 next to the
        // boundary (and the extremes).
        for ratio in scale::thin([0.8f32, 0.75, 0.7, 0.9, 1.0, 0.3], 2) {
            let config = MatchConfig::default()
                .with_ratio(Some(ratio))
                .with_cross_check(false)
                .with_max_distance(None);
            let (cpu, gpu) = (matcher(Backend::Cpu, config.clone()), matcher(GPU, config));
            for d2 in (1..=64u32).step_by(scale::pick(1, 9)) {
                let edge = (ratio * d2 as f32) as u32;
                for d1 in (0..d2).filter(|&d1| {
                    !scale::sanitizer() || d1 == 0 || d1 + 1 == d2 || d1.abs_diff(edge) <= 1
                }) {
                    let train = DescriptorSet::from_words(w, vec![ones(d1), ones(d2)]).unwrap();
                    let (c, g) = (
                        cpu.match_descriptors(&query, &train)?,
                        gpu.match_descriptors(&query, &train)?,
                    );
                    if c != g {
                        return Err(format!(
                            "ratio {ratio}, d1 {d1}, d2 {d2}: cpu {c:?}, gpu {g:?}"
                        )
                        .into());
                    }
                    cases += 1;
                }
            }
        }
        println!("ratio boundary: {cases} (ratio, d1, d2) cases: identical");
        Ok(())
    }

    pub fn real_descriptors() -> Result<(), Failed> {
        let image = astronaut();
        let rotated = image.rotate90();
        let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
        let a = extractor.detect_and_describe(&image.view())?;
        let b = extractor.detect_and_describe(&rotated.view())?;
        // CLATCH_TEST_SCALE=sanitizer: the first 300 descriptors of each.
        let first = |set: &DescriptorSet| {
            let n = scale::pick(set.len(), set.len().min(300));
            DescriptorSet::from_words(
                set.width(),
                set.as_words()[..n * set.width().words()].to_vec(),
            )
        };
        let (query, train) = (&first(&a.descriptors)?, &first(&b.descriptors)?);
        let mut pairs = 0;
        for k in ks(8) {
            pairs += compare_knn("astronaut vs rotated", query, train, k, k <= 2)?;
        }
        let (q, kept) = compare_match("astronaut vs rotated", query, train)?;
        let default = matcher(GPU, MatchConfig::default()).match_descriptors(query, train)?;
        println!(
            "astronaut ({} descriptors) vs its 90-degree rotation ({}): {pairs} kNN pairs, {q} queries \
             through every config ({kept} kept); default config keeps {}: identical",
            query.len(),
            train.len(),
            default.len()
        );
        Ok(())
    }

    /// `Matcher::match_pairs` on the GPU (several streams, pairs in flight) against the CPU's, pair by
    /// pair, with empty and single-descriptor sets among the real ones.
    pub fn match_pairs() -> Result<(), Failed> {
        let mut rng = SplitMix64::new(21);
        let w = width(512);
        let sizes = scale::thin([700, 0, 1, 2000, 65, 1500, 300, 5000, 9], 2);
        let owned: Vec<DescriptorSet> = sizes.iter().map(|&n| random_set(w, n, &mut rng)).collect();
        let sets: Vec<&DescriptorSet> = owned.iter().collect();
        let pairs = Matcher::all_pairs(sets.len());
        let mut compared = 0;
        for config in configs() {
            let cpu = matcher(Backend::Cpu, config.clone()).match_pairs(&sets, &pairs)?;
            let done = std::sync::Mutex::new(Vec::new());
            let gpu =
                matcher(GPU, config.clone())
                    .match_pairs_with_progress(&sets, &pairs, &|p| done.lock().unwrap().push(p))?;
            if *done.lock().unwrap() != (0..pairs.len()).collect::<Vec<_>>() {
                return Err(format!("{config:?}: pairs not reported once each in order").into());
            }
            for (p, (c, g)) in cpu.iter().zip(&gpu).enumerate() {
                if c != g {
                    return Err(format!("{config:?}: pair {:?} differs", pairs[p]).into());
                }
                compared += c.len();
            }
        }
        println!(
            "{} sets, {} pairs x {} configurations: {compared} matches identical",
            sets.len(),
            pairs.len(),
            configs().len()
        );
        Ok(())
    }
}
