//! `DescriptorCollection` on the CPU: every result equals `Matcher::match_descriptors` of its pair
//! (no matches for a pair without queries or with too small a gallery), handed out once per pair in
//! request order, and bad requests are refused before any work. The CUDA twin is compared with this in
//! `tests/cuda_collection.rs`.

mod common;

use clatch::synthetic::SplitMix64;
use clatch::{
    Backend, DescriptorCollection, DescriptorSet, DescriptorWidth, Error, Match, MatchConfig,
    Matcher,
};
use common::{match_configs, random_set, tied_collection};

/// What one pair must give: `match_descriptors`, or nothing where `match_pairs` gives nothing.
fn expected(matcher: &Matcher, query: &DescriptorSet, train: &DescriptorSet) -> Vec<Match> {
    let needed = if matcher.config().ratio.is_some() {
        2
    } else {
        1
    };
    if query.is_empty() || train.len() < needed {
        return Vec::new();
    }
    matcher.match_descriptors(query, train).unwrap()
}

/// Calls of `each`, checked to come once per index in increasing order.
fn collect(n: usize, run: impl FnOnce(&mut dyn FnMut(usize, Vec<Match>))) -> Vec<Vec<Match>> {
    let mut out = Vec::new();
    run(&mut |i, m| {
        assert_eq!(i, out.len(), "results in request order, once each");
        out.push(m);
    });
    assert_eq!(out.len(), n);
    out
}

fn collection(matcher: &Matcher, sets: &[DescriptorSet]) -> DescriptorCollection {
    let mut c = DescriptorCollection::new(matcher, sets[0].width()).unwrap();
    let refs: Vec<&DescriptorSet> = sets.iter().collect();
    let (head, tail) = refs.split_at(refs.len() / 2);
    assert_eq!(c.add(head).unwrap(), 0..head.len());
    assert_eq!(c.add(tail).unwrap(), head.len()..refs.len());
    c
}

#[test]
fn pairs_and_searches_equal_one_call_per_pair() {
    let mut rng = SplitMix64::new(31);
    // Empty and single-descriptor sets among tie-heavy ones; more than one host block of pairs.
    let sizes = [
        40, 0, 1, 2, 65, 300, 17, 1, 90, 33, 0, 128, 7, 64, 200, 3, 50, 25, 10, 70, 5, 130, 9, 44,
    ];
    let sets = tied_collection(16, &sizes, &mut rng);
    let configs: Vec<MatchConfig> = match_configs().into_iter().step_by(3).collect();
    let mut kept = 0;
    for config in configs {
        let matcher = Matcher::new(Backend::Cpu, config.clone()).unwrap();
        let c = collection(&matcher, &sets);
        assert_eq!(
            (c.len(), c.set_len(5), c.set_len(sizes.len())),
            (sizes.len(), Some(300), None)
        );
        let all = Matcher::all_pairs(sets.len());
        let got = collect(all.len(), |each| c.match_all_pairs_each(each).unwrap());
        assert_eq!(
            c.match_all_pairs().unwrap(),
            got,
            "the plain call returns them"
        );
        for (&(a, b), g) in all.iter().zip(&got) {
            assert_eq!(
                g,
                &expected(&matcher, &sets[a], &sets[b]),
                "{config:?} ({a}, {b})"
            );
            kept += g.len();
        }
        let listed = [(3, 3), (5, 0), (0, 5), (1, 2), (2, 1), (5, 5), (5, 0)];
        let got = collect(listed.len(), |each| {
            c.match_pairs_each(&listed, each).unwrap()
        });
        assert_eq!(c.match_pairs(&listed).unwrap(), got);
        for (&(a, b), g) in listed.iter().zip(&got) {
            assert_eq!(
                g,
                &expected(&matcher, &sets[a], &sets[b]),
                "{config:?} ({a}, {b})"
            );
        }
        let query = &tied_collection(16, &[150], &mut rng)[0];
        let got = collect(sets.len(), |each| c.search_each(query, each).unwrap());
        assert_eq!(c.search(query).unwrap(), got);
        for (set, g) in sets.iter().zip(&got) {
            assert_eq!(g, &expected(&matcher, query, set), "{config:?} search");
        }
        let ids = [7, 0, 7, 5];
        let got = collect(ids.len(), |each| {
            c.search_sets_each(query, &ids, each).unwrap()
        });
        assert_eq!(c.search_sets(query, &ids).unwrap(), got);
        for (&id, g) in ids.iter().zip(&got) {
            assert_eq!(
                g,
                &expected(&matcher, query, &sets[id]),
                "{config:?} search {id}"
            );
        }
        let empty = DescriptorSet::empty(sets[0].width());
        let got = collect(sets.len(), |each| c.search_each(&empty, each).unwrap());
        assert!(got.iter().all(Vec::is_empty), "no queries, no matches");
    }
    assert!(kept > 1000, "matching found something: {kept}");
}

#[test]
fn bad_requests_are_refused_before_any_work() {
    let mut rng = SplitMix64::new(32);
    let w = DescriptorWidth::from_bits(64).unwrap();
    let sets = [random_set(w, 30, &mut rng), random_set(w, 20, &mut rng)];
    let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
    let mut c = collection(&matcher, &sets);
    let narrow = random_set(DescriptorWidth::from_bits(8).unwrap(), 5, &mut rng);
    let mut called = 0;
    assert!(matches!(
        c.match_pairs_each(&[(0, 1), (1, 2)], |_, _| called += 1),
        Err(Error::PairOutOfRange {
            pair: 1,
            index: 2,
            sets: 2
        })
    ));
    assert!(matches!(
        c.search_sets_each(&sets[0], &[0, 9], |_, _| called += 1),
        Err(Error::PairOutOfRange {
            pair: 1,
            index: 9,
            sets: 2
        })
    ));
    assert!(matches!(
        c.search_each(&narrow, |_, _| called += 1),
        Err(Error::DescriptorWidthMismatch {
            query_bits: 8,
            train_bits: 64
        })
    ));
    assert_eq!(called, 0);
    assert!(matches!(
        c.add(&[&sets[0], &narrow]),
        Err(Error::DescriptorWidthMismatch { .. })
    ));
    assert_eq!(c.len(), 2, "a refused add adds nothing");
    c.match_pairs_each(&[], |_, _| called += 1).unwrap();
    let empty = DescriptorCollection::new(&matcher, w).unwrap();
    assert!(empty.is_empty());
    empty.match_all_pairs_each(|_, _| called += 1).unwrap();
    empty.search_each(&sets[0], |_, _| called += 1).unwrap();
    assert_eq!(c.match_pairs(&[]), Ok(vec![]));
    assert_eq!(empty.match_all_pairs(), Ok(vec![]));
    assert_eq!(empty.search(&sets[0]), Ok(vec![]));
    assert!(matches!(
        c.match_pairs(&[(2, 0)]),
        Err(Error::PairOutOfRange {
            pair: 0,
            index: 2,
            sets: 2
        })
    ));
    assert!(matches!(
        c.search_sets(&narrow, &[0]),
        Err(Error::DescriptorWidthMismatch { .. })
    ));
    assert_eq!(called, 0);
    assert_eq!((c.width(), c.matcher().backend()), (w, Backend::Cpu));
}

#[test]
fn callbacks_may_match_again_and_threads_share_a_collection() {
    // A callback matching on its own collection (pairs and a search) and two threads matching one
    // collection at once get what a lone call gets.
    let mut rng = SplitMix64::new(32);
    let sets = tied_collection(64, &[70, 0, 1, 2, 65, 130, 9, 300], &mut rng);
    let query = &tied_collection(64, &[90], &mut rng)[0];
    let config = MatchConfig::default().with_cross_check(true);
    let matcher = Matcher::new(Backend::Cpu, config).unwrap();
    let c = collection(&matcher, &sets);
    let all = Matcher::all_pairs(sets.len());
    let want: Vec<Vec<Match>> = all
        .iter()
        .map(|&(a, b)| expected(&matcher, &sets[a], &sets[b]))
        .collect();
    let want_search: Vec<Vec<Match>> = sets.iter().map(|s| expected(&matcher, query, s)).collect();
    let outer = collect(all.len(), |each| {
        c.match_pairs_each(&all, |i, m| {
            let inner = collect(2, |e| c.match_pairs_each(&[all[i], all[0]], e).unwrap());
            assert_eq!(inner, [want[i].clone(), want[0].clone()], "inside pair {i}");
            let found = collect(sets.len(), |e| c.search_each(query, e).unwrap());
            assert_eq!(found, want_search, "search inside pair {i}");
            each(i, m);
        })
        .unwrap()
    });
    assert_eq!(outer, want, "outer run");
    std::thread::scope(|scope| {
        let runs: Vec<_> = (0..2)
            .map(|_| {
                scope.spawn(|| collect(all.len(), |each| c.match_all_pairs_each(each).unwrap()))
            })
            .collect();
        for run in runs {
            assert_eq!(run.join().unwrap(), want, "one of two threads");
        }
    });
}
