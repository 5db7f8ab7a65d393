//! The CPU thread pool: rayon's global pool, as `RAYON_NUM_THREADS` asks, but never more than a few
//! threads a core. Thousands of threads only cost memory and time (each call wakes every one), and a
//! mistyped value should not turn a 70 ms run into minutes.

/// The most threads the tool runs a core.
pub const MAX_THREADS_PER_CORE: usize = 4;

/// Caps the pool before any work; returns a warning to print when `RAYON_NUM_THREADS` asked for more.
pub fn cap_pool() -> Option<String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cap = cores.saturating_mul(MAX_THREADS_PER_CORE);
    let asked: usize = std::env::var("RAYON_NUM_THREADS")
        .ok()?
        .trim()
        .parse()
        .ok()?;
    if asked <= cap {
        return None;
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(cap)
        .build_global()
        .ok()?;
    Some(format!(
        "RAYON_NUM_THREADS={asked} is more than {MAX_THREADS_PER_CORE} threads for each of the \
         {cores} cores; using {cap}"
    ))
}
