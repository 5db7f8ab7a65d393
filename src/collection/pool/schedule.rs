//! How a pool's work is cut and handed out: pairs grouped into blocks (tiles of the pair matrix),
//! blocks or images claimed one at a time by whichever worker is free, one thread per worker, and the
//! first error stopping every worker.

use std::collections::HashMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::backend::Backend;
use crate::error::{Error, Result};

/// The pairs of one tile of the pair matrix and of its mirror: every pair `(a, b)` whose tile row
/// and column, `a / tile` and `b / tile`, are the block's two (in either order), so that a worker on
/// the block reads the sets of two tiles at most.
#[derive(Debug, PartialEq, Eq)]
pub(super) struct Block {
    /// Indices into the pair list, increasing.
    pub(super) pairs: Vec<usize>,
    /// The sets the block's matchable pairs read, increasing, each once: what a worker holds
    /// resident while it works on the block.
    pub(super) sets: Vec<usize>,
}

/// `pairs` cut into blocks by tiles of `tile` x `tile` sets (at least 1), in the order of each
/// block's first pair. Only pairs for which `matchable` holds add their sets to a block's.
pub(super) fn blocks(
    pairs: &[(usize, usize)],
    tile: usize,
    matchable: impl Fn((usize, usize)) -> bool,
) -> Vec<Block> {
    let tile = tile.max(1);
    let mut slots = HashMap::new();
    let mut blocks: Vec<Block> = Vec::new();
    for (p, &(a, b)) in pairs.iter().enumerate() {
        let (row, column) = (a / tile, b / tile);
        let key = (row.min(column), row.max(column));
        let slot = *slots.entry(key).or_insert_with(|| {
            blocks.push(Block {
                pairs: Vec::new(),
                sets: Vec::new(),
            });
            blocks.len() - 1
        });
        let block = &mut blocks[slot];
        block.pairs.push(p);
        if matchable((a, b)) {
            block.sets.extend([a, b]);
        }
    }
    for block in &mut blocks {
        block.sets.sort_unstable();
        block.sets.dedup();
    }
    blocks
}

/// Items (blocks or images) handed out one at a time, to whichever worker asks next, and the first
/// error of any worker, which stops them all.
pub(super) struct WorkQueue {
    next: AtomicUsize,
    len: usize,
    stopped: AtomicBool,
    error: Mutex<Option<Error>>,
}

impl WorkQueue {
    fn new(len: usize) -> Self {
        Self {
            next: AtomicUsize::new(0),
            len,
            stopped: AtomicBool::new(false),
            error: Mutex::new(None),
        }
    }

    /// The next unclaimed item, or `None` once every item is claimed or a worker has failed.
    pub(super) fn claim(&self) -> Option<usize> {
        if self.stopped() {
            return None;
        }
        // Each worker claims at most once past the end, so the counter cannot wrap.
        let item = self.next.fetch_add(1, Ordering::Relaxed);
        (item < self.len).then_some(item)
    }

    /// Whether a worker has failed: the others stop at their next item.
    pub(super) fn stopped(&self) -> bool {
        self.stopped.load(Ordering::Relaxed)
    }

    /// Keeps `error` if it is the first, and stops every worker.
    fn fail(&self, error: Error) {
        let mut first = self.error.lock().unwrap_or_else(|p| p.into_inner());
        first.get_or_insert(error);
        self.stopped.store(true, Ordering::Relaxed);
    }
}

/// Runs `work(worker, backend, queue)` on a thread of its own for every worker, over one queue of
/// `claims` items, and puts the `(index, result)`s they return in place: a vector of `results`
/// results, each given exactly once. The first worker to fail stops the others (they see it at their
/// next item) and its error is returned as [`Error::Worker`].
pub(super) fn run_workers<T: Send>(
    workers: &[Backend],
    claims: usize,
    results: usize,
    work: impl Fn(usize, Backend, &WorkQueue) -> Result<Vec<(usize, T)>> + Sync,
) -> Result<Vec<T>> {
    let queue = WorkQueue::new(claims);
    let finished: Vec<Vec<(usize, T)>> = std::thread::scope(|scope| {
        let (queue, work) = (&queue, &work);
        let threads: Vec<_> = workers
            .iter()
            .enumerate()
            .map(|(worker, &backend)| {
                scope.spawn(move || {
                    let _stop_on_panic = StopOnPanic(queue);
                    work(worker, backend, queue).unwrap_or_else(|error| {
                        queue.fail(Error::Worker {
                            worker,
                            backend: backend.to_string(),
                            source: Box::new(error),
                        });
                        Vec::new()
                    })
                })
            })
            .collect();
        threads
            .into_iter()
            .map(|thread| {
                // A panic (the caller's `done`, say) goes on in the caller's thread, as it would
                // without the pool.
                thread
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
            .collect()
    });
    if let Some(error) = queue.error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(error);
    }
    let mut slots: Vec<Option<T>> = std::iter::repeat_with(|| None).take(results).collect();
    for (index, result) in finished.into_iter().flatten() {
        match slots.get_mut(index) {
            Some(slot @ None) => *slot = Some(result),
            _ => {
                return Err(missing(format!(
                    "result {index} given twice or out of range"
                )));
            }
        }
    }
    slots
        .into_iter()
        .enumerate()
        .map(|(index, slot)| slot.ok_or_else(|| missing(format!("no worker gave result {index}"))))
        .collect()
}

/// Stops every worker when the thread holding it unwinds (a panic in the caller's `done`, say), so
/// that the panic reaches the caller without the others finishing the whole run first.
struct StopOnPanic<'q>(&'q WorkQueue);

impl Drop for StopOnPanic<'_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.stopped.store(true, Ordering::Relaxed);
        }
    }
}

fn missing(message: String) -> Error {
    Error::Internal {
        operation: "device pool",
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_are_tiles_of_the_pair_matrix_and_their_mirrors() {
        let pairs = [
            (0, 1),
            (5, 0),
            (2, 3),
            (0, 5),
            (4, 4),
            (1, 0),
            (2, 3),
            (3, 6),
        ];
        let got = blocks(&pairs, 2, |(a, _)| a != 4);
        // Tiles of two sets: (0, 1) -> (0, 0); (5, 0) and (0, 5) -> (0, 2); (2, 3) -> (1, 1);
        // (4, 4) -> (2, 2); (3, 6) -> (1, 3).
        let expected = [
            (vec![0, 5], vec![0, 1]),
            (vec![1, 3], vec![0, 5]),
            (vec![2, 6], vec![2, 3]),
            (vec![4], vec![]),
            (vec![7], vec![3, 6]),
        ];
        assert_eq!(got.len(), expected.len());
        for (block, (pairs, sets)) in got.iter().zip(expected) {
            assert_eq!((&block.pairs, &block.sets), (&pairs, &sets));
        }
        // Every pair in exactly one block, whatever the tile.
        for tile in [0, 1, 3, 100] {
            let mut all: Vec<usize> = blocks(&pairs, tile, |_| true)
                .into_iter()
                .flat_map(|b| b.pairs)
                .collect();
            all.sort_unstable();
            assert_eq!(all, (0..pairs.len()).collect::<Vec<_>>(), "tile {tile}");
        }
        assert_eq!(blocks(&pairs, 100, |_| true).len(), 1);
        assert!(blocks(&[], 4, |_| true).is_empty());
    }

    #[test]
    fn every_result_in_place_and_the_first_error_stops_the_others() {
        let workers = [Backend::Cpu; 3];
        let squares = run_workers(&workers, 50, 50, |_, _, queue| {
            Ok(std::iter::from_fn(|| queue.claim())
                .map(|i| (i, i * i))
                .collect())
        })
        .unwrap();
        assert_eq!(squares, (0..50).map(|i| i * i).collect::<Vec<_>>());

        // Worker 1 fails at once; the others, one item every 2 ms, stop at their next item.
        let claimed = AtomicUsize::new(0);
        let result: Result<Vec<usize>> = run_workers(&workers, 2000, 2000, |worker, _, queue| {
            let mut mine = Vec::new();
            while let Some(i) = queue.claim() {
                claimed.fetch_add(1, Ordering::Relaxed);
                if worker == 1 {
                    return Err(Error::EmptyGallery);
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
                mine.push((i, i));
            }
            Ok(mine)
        });
        match result {
            Err(Error::Worker {
                worker: 1,
                backend,
                source,
            }) => {
                assert_eq!(backend, Backend::Cpu.to_string());
                assert_eq!(*source, Error::EmptyGallery);
            }
            other => panic!("{other:?}"),
        }
        let claimed = claimed.into_inner();
        assert!(
            claimed < 1000,
            "{claimed} of 2000 items claimed after the error"
        );
    }

    #[test]
    fn a_panic_stops_the_others_and_reaches_the_caller() {
        let claimed = AtomicUsize::new(0);
        let run = std::panic::catch_unwind(|| {
            run_workers(&[Backend::Cpu; 3], 2000, 2000, |worker, _, queue| {
                let mut mine = Vec::new();
                while let Some(i) = queue.claim() {
                    claimed.fetch_add(1, Ordering::Relaxed);
                    assert!(worker != 2, "a panicking progress callback");
                    std::thread::sleep(std::time::Duration::from_millis(2));
                    mine.push((i, ()));
                }
                Ok(mine)
            })
        });
        assert!(run.is_err(), "the panic reaches the caller");
        let claimed = claimed.into_inner();
        assert!(
            claimed < 1000,
            "{claimed} of 2000 items claimed after the panic"
        );
    }

    #[test]
    fn a_lost_or_doubled_result_is_an_internal_error() {
        let twice = run_workers(&[Backend::Cpu], 1, 2, |_, _, _| Ok(vec![(0, 0), (0, 0)]));
        assert!(matches!(twice, Err(Error::Internal { .. })), "{twice:?}");
        let lost = run_workers(&[Backend::Cpu], 1, 2, |_, _, _| Ok(vec![(1, 0)]));
        assert!(matches!(lost, Err(Error::Internal { .. })), "{lost:?}");
    }
}
