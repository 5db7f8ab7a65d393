//! Producing items ahead on worker threads (decoding photos) while the caller consumes them in order
//! (extracting features): the decoders never wait for the extractor unless they are `ahead` items in
//! front of it, and the extractor waits only when the next item is not decoded yet.

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// Shared between the workers and the consumer.
struct State<T> {
    /// The next index a worker claims.
    next: usize,
    /// Items handed to the consumer so far.
    consumed: usize,
    /// Produced and not yet consumed, by index.
    ready: BTreeMap<usize, T>,
    /// The consumer is done (finished or stopped early): workers claim nothing more.
    stop: bool,
}

/// What the consumer learns about the producers.
#[derive(Clone, Copy, Debug, Default)]
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
/// returns and the timings.
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
    });
    let changed = Condvar::new();
    let produced = Mutex::new(Duration::ZERO);
    let lock = || state.lock().unwrap_or_else(|p| p.into_inner());
    let (result, waited) = std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
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
        let mut items = InOrder {
            n,
            index: 0,
            state: &state,
            changed: &changed,
            waited: Duration::ZERO,
        };
        let result = consume(&mut items);
        let waited = items.waited;
        lock().stop = true;
        changed.notify_all();
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
    fn nothing_to_do() {
        let (v, _) = ordered(0, 4, 4, |i| i, |items| items.count());
        assert_eq!(v, 0);
    }
}
