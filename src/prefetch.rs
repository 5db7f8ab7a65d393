//! Producing items ahead on worker threads (decoding photos) while the caller consumes them in order
//! (extracting features): the decoders never wait for the extractor unless they are `ahead` items in
//! front of it, and the extractor waits only when the next item is not decoded yet.
//!
//! [`extract_decoded`] is the common case: files decoded on worker threads and handed to
//! [`Extractor::detect_and_describe_stream`] in order, as `clatch extract` and
//! `clatch::colmap::extract_photos` do. [`ordered`] is the general form.
//!
//! ```
//! use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
//!
//! let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
//! // "Decoding" image i: here synthetic pixels, in practice a file read on a worker thread.
//! let mut counts = Vec::new();
//! let timings = clatch::prefetch::extract_decoded(
//!     &extractor,
//!     4,
//!     |i| clatch::synthetic::rectangles(160, 120, i as u64).map(|pixels| Frame(pixels)),
//!     |i, _frame, features| {
//!         counts.push((i, features.keypoints.len()));
//!         Ok::<(), clatch::Error>(())
//!     },
//! )?;
//! assert_eq!(counts.len(), 4);
//! assert!(timings.threads >= 1);
//! # struct Frame(Vec<u8>);
//! # impl clatch::AsGrayView for Frame {
//! #     fn gray_view(&self) -> clatch::Result<GrayView<'_>> {
//! #         GrayView::new(&self.0, 160, 120, 160)
//! #     }
//! # }
//! # Ok::<(), clatch::Error>(())
//! ```

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use crate::backend::Backend;
use crate::error::Error;
use crate::extract::Extractor;
use crate::features::Features;
use crate::gray_view::AsGrayView;

/// Shared between the workers and the consumer.
struct State<T> {
    /// The next index a worker claims.
    next: usize,
    /// Items handed to the consumer so far.
    consumed: usize,
    /// Produced and not yet consumed, by index.
    ready: BTreeMap<usize, T>,
    /// The consumer is done (finished, stopped early or panicking): workers claim nothing more.
    stop: bool,
    /// A worker panicked: the consumer would wait for its item forever, so it panics too.
    producer_panicked: bool,
}

/// Dropped on the way out of a worker (or of the consumer): a panic there is told to the other side,
/// which would otherwise wait for it forever (and `std::thread::scope` for them).
struct OnExit<'a, T> {
    state: &'a Mutex<State<T>>,
    changed: &'a Condvar,
    /// The consumer's: the workers stop, whether it panics or returns.
    consumer: bool,
}

impl<T> Drop for OnExit<'_, T> {
    fn drop(&mut self) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if self.consumer {
            s.stop = true;
        } else if std::thread::panicking() {
            s.stop = true;
            s.producer_panicked = true;
        }
        drop(s);
        self.changed.notify_all();
    }
}

/// What the consumer learns about the producers (`#[non_exhaustive]`: timings may be added).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct Prefetched {
    /// Time spent producing, summed over the workers.
    pub produce: Duration,
    /// Time the consumer waited for the next item.
    pub waited: Duration,
    /// Worker threads.
    pub threads: usize,
}

/// Runs `produce(i)` for `i` in `0..n` on `threads` worker threads (at least one), at most `ahead`
/// (at least one) items beyond the last one consumed, and gives `consume` the results in index order.
/// `consume` may stop early (workers then finish the item they hold and stop). Returns what `consume`
/// returns and the timings. A panic of `produce` or `consume` reaches the caller (after every worker
/// has ended).
pub fn ordered<T: Send, R>(
    n: usize,
    threads: usize,
    ahead: usize,
    produce: impl Fn(usize) -> T + Sync,
    consume: impl FnOnce(&mut dyn Iterator<Item = T>) -> R,
) -> (R, Prefetched) {
    let (threads, ahead) = (threads.clamp(1, n.max(1)), ahead.max(1));
    let state = Mutex::new(State {
        next: 0,
        consumed: 0,
        ready: BTreeMap::new(),
        stop: false,
        producer_panicked: false,
    });
    let changed = Condvar::new();
    let produced = Mutex::new(Duration::ZERO);
    let lock = || state.lock().unwrap_or_else(|p| p.into_inner());
    let (result, waited) = std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                let _exit = OnExit {
                    state: &state,
                    changed: &changed,
                    consumer: false,
                };
                loop {
                    let i = {
                        let mut s = lock();
                        while !s.stop && s.next < n && s.next >= s.consumed + ahead {
                            s = changed.wait(s).unwrap_or_else(|p| p.into_inner());
                        }
                        if s.stop || s.next >= n {
                            return;
                        }
                        s.next += 1;
                        s.next - 1
                    };
                    let start = Instant::now();
                    let item = produce(i);
                    *produced.lock().unwrap_or_else(|p| p.into_inner()) += start.elapsed();
                    lock().ready.insert(i, item);
                    changed.notify_all();
                }
            });
        }
        let exit = OnExit {
            state: &state,
            changed: &changed,
            consumer: true,
        };
        let mut items = InOrder {
            n,
            index: 0,
            state: &state,
            changed: &changed,
            waited: Duration::ZERO,
        };
        let result = consume(&mut items);
        let waited = items.waited;
        drop(exit);
        (result, waited)
    });
    let produce = *produced.lock().unwrap_or_else(|p| p.into_inner());
    (
        result,
        Prefetched {
            produce,
            waited,
            threads,
        },
    )
}

/// Decoding threads for an extractor on `backend`, and how many decoded images they may hold ahead
/// of it. The GPU: every core (decoding is then the CPU's only work), as many ahead as there are
/// decoders plus the 8 images the GPU keeps in flight. The CPU backend: half the cores (its
/// extraction uses every core itself), a whole next group of images ahead (it extracts one image per
/// thread at once).
pub fn decoding(backend: Backend) -> (usize, usize) {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    match backend {
        Backend::Cpu => ((cores / 2).max(1), 2 * crate::parallel::threads().max(1)),
        Backend::Cuda { .. } => (cores, cores + 8),
    }
}

/// Decodes items `0..n` with `decode` on worker threads ([`decoding`]: at most a few ahead of the
/// extractor) and hands each with its features to `each`, in order
/// ([`Extractor::detect_and_describe_stream`]: on the GPU several images in flight on several
/// streams). The first error, of `decode`, of an image or of `each`, stops it and is returned.
/// Returns the decoders' timings: their summed time, and how long the extractor waited for them
/// (about zero when extraction, not decoding, is the bound).
pub fn extract_decoded<T, E>(
    extractor: &Extractor,
    n: usize,
    decode: impl Fn(usize) -> Result<T, E> + Sync,
    each: impl FnMut(usize, T, Features) -> Result<(), E>,
) -> Result<Prefetched, E>
where
    T: AsGrayView + Send + Sync,
    E: From<Error> + Send,
{
    let (threads, ahead) = decoding(extractor.backend());
    let (result, stats) = ordered(n, threads, ahead, decode, |decoded| {
        extractor.detect_and_describe_stream(decoded, each)
    });
    result?;
    Ok(stats)
}

/// The consumer's side: the items in index order.
struct InOrder<'a, T> {
    n: usize,
    index: usize,
    state: &'a Mutex<State<T>>,
    changed: &'a Condvar,
    waited: Duration,
}

impl<T> Iterator for InOrder<'_, T> {
    type Item = T;

    fn next(&mut self) -> Option<T> {
        if self.index >= self.n {
            return None;
        }
        let start = Instant::now();
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let item = loop {
            if let Some(item) = s.ready.remove(&self.index) {
                break item;
            }
            if s.producer_panicked {
                drop(s);
                panic!("a producer of item {} panicked", self.index);
            }
            s = self.changed.wait(s).unwrap_or_else(|p| p.into_inner());
        };
        self.index += 1;
        s.consumed = self.index;
        drop(s);
        self.changed.notify_all();
        self.waited += start.elapsed();
        Some(item)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn items_come_in_order_and_never_too_far_ahead() {
        let most_ahead = AtomicUsize::new(0);
        let consumed = AtomicUsize::new(0);
        let (got, stats) = ordered(
            200,
            6,
            5,
            |i| {
                let ahead = i - consumed.load(Ordering::SeqCst).min(i);
                most_ahead.fetch_max(ahead, Ordering::SeqCst);
                // Uneven work, so that items finish out of order.
                std::thread::sleep(Duration::from_micros(((i * 7919) % 13) as u64 * 50));
                i * 3
            },
            |items| {
                let mut got = Vec::new();
                for item in items {
                    got.push(item);
                    consumed.fetch_add(1, Ordering::SeqCst);
                }
                got
            },
        );
        assert_eq!(got, (0..200).map(|i| i * 3).collect::<Vec<_>>());
        // An item is claimed only while fewer than `ahead` wait beyond the consumed ones (the counter
        // here lags the consumer by one item).
        assert!(most_ahead.load(Ordering::SeqCst) <= 5, "{most_ahead:?}");
        assert_eq!(stats.threads, 6);
    }

    #[test]
    fn stopping_early_ends_the_workers() {
        let produced = AtomicUsize::new(0);
        let (first, _) = ordered(
            1000,
            4,
            3,
            |i| {
                produced.fetch_add(1, Ordering::SeqCst);
                i
            },
            |items| items.take(10).collect::<Vec<_>>(),
        );
        assert_eq!(first, (0..10).collect::<Vec<_>>());
        // At most `ahead` beyond the consumed ones, plus one per thread already claimed.
        assert!(produced.load(Ordering::SeqCst) <= 10 + 3 + 4);
    }

    #[test]
    fn a_panic_on_either_side_reaches_the_caller() {
        let producer = std::panic::catch_unwind(|| {
            ordered(
                100,
                3,
                4,
                |i| {
                    if i == 7 {
                        panic!("producer (on purpose)");
                    }
                    i
                },
                |items| items.count(),
            )
        });
        assert!(producer.is_err());
        let consumer = std::panic::catch_unwind(|| {
            ordered(
                100,
                3,
                4,
                |i| i,
                |items| {
                    for i in items {
                        if i == 5 {
                            panic!("consumer (on purpose)");
                        }
                    }
                },
            )
        });
        assert!(consumer.is_err());
    }

    #[test]
    fn nothing_to_do() {
        let (v, _) = ordered(0, 4, 4, |i| i, |items| items.count());
        assert_eq!(v, 0);
    }
}
