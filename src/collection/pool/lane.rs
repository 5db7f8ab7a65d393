//! What one worker of a pool runs on its device: pairs of blocks with the block's sets held resident
//! ([`PairLane`], the plug for a device's own kind of resident set), and images.
//!
//! A lane prepares each set a block reads once, keeps it for the whole block, and drops it when the
//! next block no longer reads it. On the CPU a prepared set is the host set itself (`HostCpu`). A CUDA
//! worker takes whole blocks instead ([`match_blocks_grouped`]): its sets live in one
//! `DescriptorCollection` for the whole run (each uploaded the first time a block reads it, resident
//! for every later block, up to a bound) and each block's pairs are matched many per launch, as
//! one-device `Matcher::match_pairs` does with all of its sets.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::convert::Infallible;

use super::super::DescriptorCollection;
use super::schedule::{Block, WorkQueue};
use crate::backend::Backend;
use crate::cuda::PendingFeatures;
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::extract::Extractor;
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::in_flight::{IN_FLIGHT_PER_STREAM, Queued, STREAMS, run_window, streams};
use crate::matcher::Matcher;
use crate::matching::{self, Match};

/// A device as a worker drives it through blocks of pairs.
pub(super) trait PairLane<'s> {
    /// A descriptor set made ready for this device's matcher: what the worker holds resident for a
    /// block. Pairs in flight keep their own clones, so a lane may drop a set while they run.
    type Set: Clone;
    /// One pair queued on the device.
    type Pending;
    /// Pairs kept queued before the oldest is waited for (at least one).
    fn window(&self) -> usize;
    /// Makes `set` ready for matching on this device.
    fn prepare(&mut self, set: &'s DescriptorSet) -> Result<Self::Set>;
    /// Queues the matching of `query` against `train` (a matchable pair of prepared sets).
    fn queue(
        &mut self,
        query: &Self::Set,
        train: &Self::Set,
    ) -> Result<Queued<Self::Pending, Vec<Match>>>;
    /// Waits for a queued pair: its matches, exactly as `Matcher::match_descriptors` gives them.
    fn wait(pending: Self::Pending) -> Result<Vec<Match>>;
}

/// What every worker matches: the collection, its pairs cut into blocks, and the configuration.
pub(super) struct Collection<'a, 's> {
    pub(super) sets: &'a [&'s DescriptorSet],
    pub(super) pairs: &'a [(usize, usize)],
    pub(super) blocks: Vec<Block>,
    pub(super) matcher: Matcher,
}

/// The prepared sets a worker holds: those of its current block.
struct Resident<S> {
    held: HashMap<usize, S>,
}

impl<S> Resident<S> {
    /// Holds exactly the sets `needed` (increasing): keeps those already held, drops the others and
    /// prepares the missing ones.
    fn hold<'s, L: PairLane<'s, Set = S>>(
        &mut self,
        lane: &mut L,
        needed: &[usize],
        sets: &[&'s DescriptorSet],
    ) -> Result<()> {
        self.held.retain(|s, _| needed.binary_search(s).is_ok());
        for &s in needed {
            if let Entry::Vacant(slot) = self.held.entry(s) {
                slot.insert(lane.prepare(sets[s])?);
            }
        }
        Ok(())
    }

    fn get(&self, s: usize) -> Result<&S> {
        self.held.get(&s).ok_or_else(|| not_resident(s))
    }
}

/// The scheduler's promise broken: a block's pair reads set `s`, which the block does not list.
fn not_resident(s: usize) -> Error {
    Error::Internal {
        operation: "device pool",
        message: format!("set {s} is not resident for its block"),
    }
}

/// Claims blocks from `queue` until none is left or a worker has failed, and matches their pairs on
/// `lane`, each block's sets held resident while the worker is on it; `done(p)` as pair `p`
/// finishes. The `(pair, matches)` of every pair this worker finished.
pub(super) fn match_blocks<'s, L: PairLane<'s>>(
    lane: &mut L,
    collection: &Collection<'_, 's>,
    queue: &WorkQueue,
    done: &(dyn Fn(usize) + Sync),
) -> Result<Vec<(usize, Vec<Match>)>> {
    let Collection {
        sets,
        pairs,
        blocks,
        matcher,
    } = collection;
    let mut resident = Resident {
        held: HashMap::new(),
    };
    let mut current = None;
    let mut finished = Vec::new();
    let items = std::iter::from_fn(|| queue.claim())
        .flat_map(|b| blocks[b].pairs.iter().map(move |&p| (b, p)))
        .take_while(|_| !queue.stopped());
    let window = lane.window();
    run_window(
        items,
        window,
        |(b, p)| {
            if current != Some(b) {
                resident.hold(lane, &blocks[b].sets, sets)?;
                current = Some(b);
            }
            let (a, t) = pairs[p];
            if !matcher.matchable(sets, (a, t)) {
                return Ok(Queued::Ready(Vec::new()));
            }
            lane.queue(resident.get(a)?, resident.get(t)?)
        },
        L::wait,
        |(_, p), matches| {
            done(p);
            finished.push((p, matches));
        },
    )?;
    Ok(finished)
}

/// The pairs of `collection` that this worker claims, on the device of `matcher` (the worker's).
pub(super) fn match_on(
    matcher: &Matcher,
    collection: &Collection,
    queue: &WorkQueue,
    done: &(dyn Fn(usize) + Sync),
) -> Result<Vec<(usize, Vec<Match>)>> {
    match matcher.backend() {
        Backend::Cpu => match_blocks(&mut HostCpu(matcher), collection, queue, done),
        Backend::Cuda { .. } => match_blocks_grouped(matcher, collection, queue, done),
    }
}

/// Descriptor rows a CUDA worker keeps resident across blocks (2^24 rows: 1 GiB at 512 bits) before it
/// starts its collection afresh: sets stay on the device for every later block that reads them, and
/// memory stays bounded for any collection.
const RESIDENT_ROWS: usize = 1 << 24;

/// [`match_blocks`] for a CUDA worker: each claimed block matched whole on `matcher`'s device, its
/// matchable pairs in one grouped run (the others get no matches), over a `DescriptorCollection`
/// the worker keeps for the whole run: a set is uploaded the first time a block reads it and stays
/// resident for later blocks (up to [`RESIDENT_ROWS`], then the collection starts afresh).
fn match_blocks_grouped(
    matcher: &Matcher,
    collection: &Collection,
    queue: &WorkQueue,
    done: &(dyn Fn(usize) + Sync),
) -> Result<Vec<(usize, Vec<Match>)>> {
    let Collection {
        sets,
        pairs,
        blocks,
        ..
    } = collection;
    let mut finished = Vec::new();
    let mut on_device: Option<DescriptorCollection> = None;
    // Set index -> id in `on_device`, and the rows it holds.
    let mut ids: HashMap<usize, usize> = HashMap::new();
    let mut rows = 0usize;
    while let Some(b) = queue.claim() {
        let block = &blocks[b];
        let mut listed = Vec::new();
        for &p in &block.pairs {
            let (a, t) = pairs[p];
            if matcher.matchable(sets, (a, t)) {
                listed.push((p, (a, t)));
            } else {
                done(p);
                finished.push((p, Vec::new()));
            }
        }
        let Some(&(_, (first, _))) = listed.first() else {
            continue;
        };
        let absent = |ids: &HashMap<usize, usize>| -> Vec<usize> {
            block
                .sets
                .iter()
                .copied()
                .filter(|s| !ids.contains_key(s))
                .collect()
        };
        let new_rows: usize = absent(&ids).iter().map(|&s| sets[s].len()).sum();
        if on_device.is_none() || rows + new_rows > RESIDENT_ROWS {
            on_device = Some(DescriptorCollection::new(matcher, sets[first].width())?);
            ids.clear();
            rows = 0;
        }
        let held = on_device.as_mut().expect("made above");
        let adding = absent(&ids);
        // Only when something is new: adding drops the tensor path's expanded rows.
        if !adding.is_empty() {
            let added = held.add(&adding.iter().map(|&s| sets[s]).collect::<Vec<_>>())?;
            for (&s, id) in adding.iter().zip(added) {
                ids.insert(s, id);
                rows += sets[s].len();
            }
        }
        let id = |s: usize| ids.get(&s).copied().ok_or_else(|| not_resident(s));
        let local = listed
            .iter()
            .map(|&(_, (a, t))| Ok((id(a)?, id(t)?)))
            .collect::<Result<Vec<_>>>()?;
        held.match_pairs_each(&local, |i, matches| {
            let p = listed[i].0;
            done(p);
            finished.push((p, matches));
        })?;
    }
    Ok(finished)
}

/// The CPU: its sets need no preparing; one pair at a time over all of its threads.
struct HostCpu<'m>(&'m Matcher);

impl<'s> PairLane<'s> for HostCpu<'_> {
    type Set = &'s DescriptorSet;
    type Pending = Infallible;

    fn window(&self) -> usize {
        1
    }

    fn prepare(&mut self, set: &'s DescriptorSet) -> Result<Self::Set> {
        Ok(set)
    }

    fn queue(
        &mut self,
        query: &Self::Set,
        train: &Self::Set,
    ) -> Result<Queued<Infallible, Vec<Match>>> {
        Ok(Queued::Ready(matching::cpu::match_descriptors(
            query,
            train,
            self.0.config(),
        )))
    }

    fn wait(pending: Infallible) -> Result<Vec<Match>> {
        match pending {}
    }
}

/// The images this worker claims from `queue`, on the device of `extractor` (the worker's): one at a
/// time on the CPU (each image over all threads), several in flight on a CUDA device's streams;
/// `done(i)` as image `i` finishes. The `(image, features)` of every image this worker finished.
pub(super) fn extract_on(
    extractor: &Extractor,
    images: &[GrayView],
    queue: &WorkQueue,
    done: &(dyn Fn(usize) + Sync),
) -> Result<Vec<(usize, Features)>> {
    let mut finished = Vec::new();
    let claims = std::iter::from_fn(|| queue.claim());
    let finish = |i, features| {
        done(i);
        finished.push((i, features));
    };
    match extractor.backend() {
        Backend::Cpu => run_window(
            claims,
            1,
            |i| extractor.detect_and_describe(&images[i]).map(Queued::Ready),
            |never: Infallible| match never {},
            finish,
        )?,
        Backend::Cuda { device } => {
            let streams = streams(device)?;
            let mut next = 0;
            run_window(
                claims,
                STREAMS * IN_FLIGHT_PER_STREAM,
                |i| {
                    let stream = &streams[next % STREAMS];
                    next += 1;
                    extractor
                        .detect_and_describe_async(stream, &images[i])
                        .map(Queued::Pending)
                },
                PendingFeatures::wait,
                finish,
            )?
        }
    }
    Ok(finished)
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::super::schedule::{blocks, run_workers};
    use super::*;
    use crate::descriptor::DescriptorWidth;
    use crate::matching::MatchConfig;

    /// A lane that names each set by its first word, records every preparation, and "matches" a
    /// pair by naming its two sets; it fails to prepare the set named `fail_on`.
    struct Recording<'r> {
        prepared: &'r Mutex<Vec<u64>>,
        fail_on: Option<u64>,
    }

    impl<'s> PairLane<'s> for Recording<'_> {
        type Set = u64;
        type Pending = (u64, u64);

        fn window(&self) -> usize {
            3
        }

        fn prepare(&mut self, set: &'s DescriptorSet) -> Result<u64> {
            let name = set.as_words()[0];
            if self.fail_on == Some(name) {
                return Err(Error::DeviceOutOfMemory {
                    operation: "preparing".into(),
                    bytes: 1,
                });
            }
            self.prepared.lock().unwrap().push(name);
            Ok(name)
        }

        fn queue(&mut self, query: &u64, train: &u64) -> Result<Queued<(u64, u64), Vec<Match>>> {
            Ok(Queued::Pending((*query, *train)))
        }

        fn wait((query, train): (u64, u64)) -> Result<Vec<Match>> {
            Ok(vec![Match {
                query: query as u32,
                train: train as u32,
                distance: 0,
            }])
        }
    }

    /// Nine sets of three descriptors named 0..9, and set 9, empty; pairs in a scrambled order with
    /// repeats, the empty set among them.
    fn collection_parts() -> (Vec<DescriptorSet>, Vec<(usize, usize)>) {
        let width = DescriptorWidth::from_bits(64).unwrap();
        let mut owned: Vec<DescriptorSet> = (0..9u64)
            .map(|s| DescriptorSet::from_words(width, vec![s, !s, s << 7]).unwrap())
            .collect();
        owned.push(DescriptorSet::from_words(width, vec![]).unwrap());
        let pairs = (0..150u64)
            .map(|i| {
                let h = (i + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                ((h >> 20) as usize % 10, (h >> 40) as usize % 10)
            })
            .collect();
        (owned, pairs)
    }

    #[test]
    fn each_set_is_prepared_once_per_block_and_kept_while_the_next_block_reads_it() {
        let (owned, pairs) = collection_parts();
        let sets: Vec<&DescriptorSet> = owned.iter().collect();
        let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
        for tile in [1, 2, 3, 4, 200] {
            let collection = Collection {
                sets: &sets,
                pairs: &pairs,
                blocks: blocks(&pairs, tile, |pair| matcher.matchable(&sets, pair)),
                matcher: matcher.clone(),
            };
            let prepared = Mutex::new(Vec::new());
            let done = Mutex::new(vec![0; pairs.len()]);
            let results = run_workers(
                &[Backend::Cpu],
                collection.blocks.len(),
                pairs.len(),
                |_, _, queue| {
                    let mut lane = Recording {
                        prepared: &prepared,
                        fail_on: None,
                    };
                    match_blocks(&mut lane, &collection, queue, &|p| {
                        done.lock().unwrap()[p] += 1
                    })
                },
            )
            .unwrap();
            assert_eq!(done.into_inner().unwrap(), vec![1; pairs.len()]);
            let mut matched = 0;
            for (&(a, b), got) in pairs.iter().zip(&results) {
                if a == 9 || b == 9 {
                    assert!(got.is_empty(), "tile {tile}: ({a}, {b})");
                } else {
                    let named = [Match {
                        query: a as u32,
                        train: b as u32,
                        distance: 0,
                    }];
                    assert_eq!(got[..], named, "tile {tile}");
                    matched += 1;
                }
            }
            assert!(matched > 100, "tile {tile}: {matched}");
            // One worker takes the blocks in order: each block prepares what the one before did not
            // hold, and nothing else (never the empty set).
            let mut expected = Vec::new();
            let mut held: &[usize] = &[];
            for block in &collection.blocks {
                let new = block.sets.iter().filter(|s| !held.contains(s));
                expected.extend(new.map(|&s| s as u64));
                held = &block.sets;
            }
            assert_eq!(prepared.into_inner().unwrap(), expected, "tile {tile}");
        }
    }

    #[test]
    fn a_failed_preparation_stops_the_pool() {
        let (owned, pairs) = collection_parts();
        let sets: Vec<&DescriptorSet> = owned.iter().collect();
        let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
        let collection = Collection {
            sets: &sets,
            pairs: &pairs,
            blocks: blocks(&pairs, 1, |pair| matcher.matchable(&sets, pair)),
            matcher,
        };
        let prepared = Mutex::new(Vec::new());
        let result = run_workers(
            &[Backend::Cpu; 2],
            collection.blocks.len(),
            pairs.len(),
            |_, _, queue| {
                let mut lane = Recording {
                    prepared: &prepared,
                    fail_on: Some(4),
                };
                match_blocks(&mut lane, &collection, queue, &|_| {})
            },
        );
        // Whichever worker meets set 4 first fails, and its error is the pool's.
        match result {
            Err(Error::Worker { worker, source, .. }) => {
                assert!(worker < 2);
                assert!(
                    matches!(*source, Error::DeviceOutOfMemory { .. }),
                    "{source}"
                );
            }
            other => panic!("{other:?}"),
        }
    }
}
