//! How much work the GPU suites do. `CLATCH_TEST_SCALE=sanitizer` shrinks the workload of every GPU
//! test binary so that each runs whole under compute-sanitizer's racecheck (which tracks every shared
//! memory access, and costs a lot per launch) in a few minutes: fewer random trials, seeds and
//! configurations, smaller images, fewer keypoints and descriptor pairs, fewer launches. Every kernel,
//! every descriptor width class, odd sizes, borders, pyramid levels, both match kernel families,
//! multi-stream cases and every allocation site are still exercised, and everything that runs is still
//! compared bit for bit with the CPU. Unset (or `full`): the normal workload, unchanged.
//! Any other value is refused, so that a typo never passes as a full run.

use std::sync::OnceLock;

/// The environment variable that selects the workload.
pub const VAR: &str = "CLATCH_TEST_SCALE";

/// Whether the reduced workload for sanitizers was asked for.
pub fn sanitizer() -> bool {
    static REDUCED: OnceLock<bool> = OnceLock::new();
    *REDUCED.get_or_init(|| match std::env::var(VAR) {
        Err(std::env::VarError::NotPresent) => false,
        Ok(v) if v.is_empty() || v == "full" => false,
        Ok(v) if v == "sanitizer" => true,
        other => panic!("{VAR} must be `full` or `sanitizer`, not {other:?}"),
    })
}

/// `full` in a normal run, `reduced` under `CLATCH_TEST_SCALE=sanitizer`.
pub fn pick<T>(full: T, reduced: T) -> T {
    if sanitizer() { reduced } else { full }
}

/// All of `items` in a normal run; under `CLATCH_TEST_SCALE=sanitizer` every `n`-th one (the first
/// included) and the last, so the extremes of a list stay covered.
pub fn thin<T>(items: impl IntoIterator<Item = T>, n: usize) -> Vec<T> {
    let items: Vec<T> = items.into_iter().collect();
    if !sanitizer() {
        return items;
    }
    let last = items.len().saturating_sub(1);
    items
        .into_iter()
        .enumerate()
        .filter(|&(i, _)| i % n.max(1) == 0 || i == last)
        .map(|(_, item)| item)
        .collect()
}

/// Whether the process runs under a sanitizer: the reduced workload was asked for, or
/// compute-sanitizer's libraries are loaded (they are injected into the process once CUDA starts).
/// Device-wide free memory means nothing there: the sanitizer's own allocations come and go.
pub fn under_sanitizer() -> bool {
    sanitizer()
        || std::env::var("CUDA_INJECTION64_PATH").is_ok_and(|p| p.contains("sanitizer"))
        || std::fs::read_to_string("/proc/self/maps").is_ok_and(|maps| {
            maps.lines().any(|l| {
                l.rsplit('/')
                    .next()
                    .is_some_and(|f| f.contains("sanitizer"))
            })
        })
}

/// A line for the test output when the workload is reduced; `None` for a normal run.
pub fn banner() -> Option<String> {
    sanitizer()
        .then(|| format!("{VAR}=sanitizer: reduced workload (every path, fewer and smaller cases)"))
}

/// The keypoint budget of an extraction under `CLATCH_TEST_SCALE=sanitizer`: enough for the
/// selection to cut (level shares, grid, the top-N over levels) on every test image, small enough
/// that racecheck, which pays for each shared-memory access of the describe kernel's 64x64 window,
/// finishes the trial in a minute or two.
pub const SANITIZER_KEYPOINTS: usize = 300;

/// `config` in a normal run; under `CLATCH_TEST_SCALE=sanitizer` the same settings with the
/// keypoint budget capped at [`SANITIZER_KEYPOINTS`] on images of every size (the budget's growth
/// with the image area, `DetectorConfig::budget_pixels`, turned off). Give the CPU and the GPU the
/// same result.
pub fn budget(mut config: clatch::ExtractorConfig) -> clatch::ExtractorConfig {
    if sanitizer() {
        config.detector.max_keypoints = config.detector.max_keypoints.min(SANITIZER_KEYPOINTS);
        config.detector.budget_pixels = None;
    }
    config
}
