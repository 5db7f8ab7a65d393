//! Keeping a device busy over many items: queue the next while earlier ones finish, hand results back
//! in input order.

use std::collections::VecDeque;

use crate::cuda::GpuStream;
use crate::error::Result;

/// Streams the CUDA paths keep busy, and the items queued on each before the oldest is waited for.
pub(super) const STREAMS: usize = 4;
pub(super) const IN_FLIGHT_PER_STREAM: usize = 2;

/// `STREAMS` streams of CUDA device `device`'s pool (warm from earlier calls; back in the pool after).
pub(super) fn streams(device: usize) -> Result<Vec<GpuStream>> {
    (0..STREAMS).map(|_| GpuStream::pooled(device)).collect()
}

/// One item after `queue`: work in flight, or a result without any.
pub(super) enum Queued<P, T> {
    Pending(P),
    Ready(T),
}

/// Runs `queue(item)` for each item as `items` yields it (items may be claimed from a shared queue as
/// they are needed), keeping at most `window` (at least one) queued, and `wait`s for them oldest
/// first; `finish(item, result)` takes each result, in the order the items came.
pub(super) fn run_window<I: Copy, P, T>(
    items: impl IntoIterator<Item = I>,
    window: usize,
    mut queue: impl FnMut(I) -> Result<Queued<P, T>>,
    mut wait: impl FnMut(P) -> Result<T>,
    mut finish: impl FnMut(I, T),
) -> Result<()> {
    let mut queued = VecDeque::new();
    let mut finish_oldest = |queued: &mut VecDeque<(I, Queued<P, T>)>| -> Result<()> {
        let (item, oldest) = queued.pop_front().expect("an item is queued");
        let result = match oldest {
            Queued::Pending(pending) => wait(pending)?,
            Queued::Ready(result) => result,
        };
        finish(item, result);
        Ok(())
    };
    for item in items {
        if queued.len() >= window.max(1) {
            finish_oldest(&mut queued)?;
        }
        queued.push_back((item, queue(item)?));
    }
    while !queued.is_empty() {
        finish_oldest(&mut queued)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// The window over `0..n`, results collected in input order (what the tests check): runs `queue(i)` for `i` in `0..n`, keeping at most `STREAMS * IN_FLIGHT_PER_STREAM` items queued,
    /// and `wait`s for them oldest first; `done(i)` follows each result. Results in input order.
    fn run_in_order<P, T>(
        n: usize,
        queue: impl FnMut(usize) -> Result<Queued<P, T>>,
        wait: impl FnMut(P) -> Result<T>,
        done: &(dyn Fn(usize) + Sync),
    ) -> Result<Vec<T>> {
        let mut results = Vec::with_capacity(n);
        run_window(
            0..n,
            STREAMS * IN_FLIGHT_PER_STREAM,
            queue,
            wait,
            |i, result| {
                results.push(result);
                done(i);
            },
        )?;
        Ok(results)
    }

    #[test]
    fn results_in_order_with_a_bounded_window() {
        let queued_now = Mutex::new(0usize);
        let most = Mutex::new(0usize);
        let done = Mutex::new(Vec::new());
        let results = run_in_order(
            20,
            |i| {
                let mut q = queued_now.lock().unwrap();
                *q += 1;
                let mut m = most.lock().unwrap();
                *m = (*m).max(*q);
                Ok(if i % 3 == 0 {
                    *q -= 1;
                    Queued::Ready(0)
                } else {
                    Queued::Pending(i * 10)
                })
            },
            |p| {
                *queued_now.lock().unwrap() -= 1;
                Ok(p + 1)
            },
            &|i| done.lock().unwrap().push(i),
        )
        .unwrap();
        let expected: Vec<usize> = (0..20)
            .map(|i| if i % 3 == 0 { 0 } else { i * 10 + 1 })
            .collect();
        assert_eq!(results, expected);
        assert_eq!(*done.lock().unwrap(), (0..20).collect::<Vec<_>>());
        assert!(*most.lock().unwrap() <= STREAMS * IN_FLIGHT_PER_STREAM);
    }

    #[test]
    fn an_error_stops_the_run() {
        let result: Result<Vec<usize>> = run_in_order::<usize, usize>(
            5,
            |i| {
                if i == 3 {
                    Err(crate::Error::EmptyGallery)
                } else {
                    Ok(Queued::Pending(i))
                }
            },
            Ok,
            &|_| {},
        );
        assert!(matches!(result, Err(crate::Error::EmptyGallery)));
    }
}
