//! The arithmetic of clatch's CUDA verification kernel (`kernels/verify_math.cuh`, the code
//! `kernels/verify.cu` runs one warp per pair) built as host C++ and run on one thread per pair, so
//! that a machine without a GPU checks the kernel's translation of the CPU reference
//! (`clatch::verify`) bit for bit: `tests/verify.rs` compares the two on generated pairs.
//!
//! Not published; a workspace member so that `cargo test` at the top runs it (it needs a C++
//! compiler, which `cc` finds as it finds the C compiler of the bundled SQLite).

use clatch::verify::packed::{
    LISTS, PackedPairs, PairRecord, PointRecord, ResultRecord, SettingsRecord, kept_matches,
};
use clatch::verify::{TwoViewGeometry, VerifyConfig, ViewPair};

/// The C++ entry points: one thread per pair, or 32 threads per pair standing in for the kernel's warp.
type Entry = unsafe extern "C" fn(
    *const SettingsRecord,
    *const PairRecord,
    u32,
    *const PointRecord,
    *mut u32,
    *mut u32,
    *mut ResultRecord,
);

unsafe extern "C" {
    fn clatch_twin_verify_pairs_warp(
        settings: *const SettingsRecord,
        pairs: *const PairRecord,
        pair_count: u32,
        points: *const PointRecord,
        scratch: *mut u32,
        inliers: *mut u32,
        results: *mut ResultRecord,
    );
    fn clatch_twin_verify_pairs(
        settings: *const SettingsRecord,
        pairs: *const PairRecord,
        pair_count: u32,
        points: *const PointRecord,
        scratch: *mut u32,
        inliers: *mut u32,
        results: *mut ResultRecord,
    );
}

/// The geometry of every pair by the kernel's arithmetic on the host, in input order. The pairs must
/// be valid (`clatch::verify::verify_pairs` succeeds on them): this is a test instrument, which
/// packs them as the CUDA backend does after its checks.
pub fn verify_pairs(pairs: &[ViewPair<'_>], config: &VerifyConfig) -> Vec<TwoViewGeometry> {
    run(clatch_twin_verify_pairs, pairs, config)
}

/// [`verify_pairs`] with each pair on a team of 32 threads that stands in for the kernel's warp
/// (ballots, ranks and sums through barriers): the kernel's division of the work between lanes, and
/// its collectives, which every lane must reach together (a lane that skipped one would deadlock
/// here). Slow: for small pairs.
pub fn verify_pairs_on_warp(pairs: &[ViewPair<'_>], config: &VerifyConfig) -> Vec<TwoViewGeometry> {
    run(clatch_twin_verify_pairs_warp, pairs, config)
}

fn run(entry: Entry, pairs: &[ViewPair<'_>], config: &VerifyConfig) -> Vec<TwoViewGeometry> {
    let kept = pairs.iter().map(|p| kept_matches(p, config)).collect();
    let packed = PackedPairs::new(pairs, kept, config);
    let n = packed.points.len();
    let mut scratch = vec![0u32; LISTS * n];
    let mut inliers = vec![0u32; n];
    let mut results = vec![ResultRecord::default(); packed.pairs.len()];
    let count = u32::try_from(packed.pairs.len()).expect("fewer than 2^32 pairs");
    // SAFETY: every pointer is to a live buffer of the length the C++ reads: one settings record,
    // `count` pair records and results, and for the correspondences `n` points, `LISTS * n` scratch
    // entries and `n` inliers, indexed by each pair's `first .. first + count` (PackedPairs lays
    // them back to back). The records are #[repr(C)] mirrors of clatch.h's structs.
    unsafe {
        entry(
            &packed.settings,
            packed.pairs.as_ptr(),
            count,
            packed.points.as_ptr(),
            scratch.as_mut_ptr(),
            inliers.as_mut_ptr(),
            results.as_mut_ptr(),
        );
    }
    results
        .iter()
        .enumerate()
        .map(|(i, result)| {
            let first = packed.pairs[i].first as usize;
            packed.geometry(i, result, &inliers[first..])
        })
        .collect()
}
