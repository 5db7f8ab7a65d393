//! The devices of a process, one slot per ordinal: a device loads under its own slot's lock, so
//! that loads of different devices run side by side (a pool starts its GPUs in parallel) while
//! callers of one device wait for its single load instead of repeating it. A failed load leaves its
//! slot empty (the next call tries again) and the other devices untouched.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use crate::error::Result;

/// One lazily loaded value per device ordinal.
pub(crate) struct PerOrdinal<T> {
    slots: Mutex<BTreeMap<usize, Slot<T>>>,
}

/// One ordinal's value: empty until its load succeeds; locked while it loads.
type Slot<T> = Arc<Mutex<Option<Arc<T>>>>;

impl<T> PerOrdinal<T> {
    pub(crate) const fn new() -> Self {
        Self {
            slots: Mutex::new(BTreeMap::new()),
        }
    }

    /// The slot of `ordinal`; the map's lock is held only while finding it.
    fn slot(&self, ordinal: usize) -> Slot<T> {
        let mut slots = lock(&self.slots);
        slots.entry(ordinal).or_default().clone()
    }

    /// The value of `ordinal`, loaded by `load` on first use and shared afterwards. A caller arriving
    /// while another thread loads the same ordinal waits for that load.
    pub(crate) fn get_or_load(
        &self,
        ordinal: usize,
        load: impl FnOnce() -> Result<T>,
    ) -> Result<Arc<T>> {
        let slot = self.slot(ordinal);
        let mut value = lock(&slot);
        if let Some(loaded) = value.as_ref() {
            return Ok(loaded.clone());
        }
        let loaded = Arc::new(load()?);
        *value = Some(loaded.clone());
        Ok(loaded)
    }

    /// The value of `ordinal` if it has loaded (waiting for a load in progress); never loads it.
    pub(crate) fn get(&self, ordinal: usize) -> Option<Arc<T>> {
        let slot = lock(&self.slots).get(&ordinal)?.clone();
        lock(&slot).clone()
    }
}

/// A poisoned lock (a load that panicked) still guards a consistent map or slot: a slot is written
/// only after its load returned.
fn lock<V>(mutex: &Mutex<V>) -> MutexGuard<'_, V> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use std::sync::Condvar;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    /// Counts the loads inside their load at once; each waits (up to 20 s) until `expected` are.
    struct Rendezvous {
        inside: Mutex<usize>,
        all_in: Condvar,
    }

    impl Rendezvous {
        /// Whether all `expected` loads were inside together before the time ran out.
        fn arrive(&self, expected: usize) -> bool {
            let mut inside = lock(&self.inside);
            *inside += 1;
            self.all_in.notify_all();
            let (inside, timeout) = self
                .all_in
                .wait_timeout_while(inside, Duration::from_secs(20), |n| *n < expected)
                .unwrap();
            drop(inside);
            !timeout.timed_out()
        }
    }

    #[test]
    fn different_ordinals_load_side_by_side_and_one_failure_leaves_the_others() {
        const DEVICES: usize = 4;
        let registry = PerOrdinal::<usize>::new();
        let rendezvous = Rendezvous {
            inside: Mutex::new(0),
            all_in: Condvar::new(),
        };
        // Every load waits inside until all four are inside: were loads one after another (one lock
        // for all), none would ever see the others and each would time out.
        let results: Vec<Result<Arc<usize>>> = std::thread::scope(|s| {
            let loads: Vec<_> = (0..DEVICES)
                .map(|ordinal| {
                    let (registry, rendezvous) = (&registry, &rendezvous);
                    s.spawn(move || {
                        registry.get_or_load(ordinal, || {
                            let together = rendezvous.arrive(DEVICES);
                            match ordinal {
                                2 => Err(Error::BackendUnavailable {
                                    backend: "cuda:2".into(),
                                    reason: "a stand-in failure".into(),
                                }),
                                _ if together => Ok(ordinal * 10),
                                _ => Ok(usize::MAX),
                            }
                        })
                    })
                })
                .collect();
            loads.into_iter().map(|t| t.join().unwrap()).collect()
        });
        for (ordinal, result) in results.iter().enumerate() {
            match ordinal {
                2 => assert!(result.is_err()),
                _ => assert_eq!(**result.as_ref().unwrap(), ordinal * 10, "loaded together"),
            }
        }
        // The others stay usable; the failed one is not cached and loads on the next call.
        assert_eq!(registry.get(0).as_deref(), Some(&0));
        assert_eq!(registry.get(3).as_deref(), Some(&30));
        assert!(registry.get(2).is_none());
        assert_eq!(*registry.get_or_load(2, || Ok(20)).unwrap(), 20);
    }

    #[test]
    fn callers_of_one_ordinal_share_its_single_load() {
        let registry = PerOrdinal::<usize>::new();
        let loads = AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    let value = registry
                        .get_or_load(5, || {
                            loads.fetch_add(1, Ordering::SeqCst);
                            std::thread::sleep(Duration::from_millis(20));
                            Ok(55)
                        })
                        .unwrap();
                    assert_eq!(*value, 55);
                });
            }
        });
        assert_eq!(loads.load(Ordering::SeqCst), 1);
        assert!(registry.get(4).is_none(), "get never loads");
    }
}
