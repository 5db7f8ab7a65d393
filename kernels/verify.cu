/* verify.cu: two-view verification of many pairs per launch, the CUDA twin of
 * clatch::verify::two_view::estimate_two_view (src/verify/two_view.rs). The arithmetic is in
 * verify_math.cuh, shared with a host C++ build that is compared with the Rust reference without a GPU.
 *
 * One warp per pair (CLATCH_VERIFY_WARPS pairs per block). Each lane draws the sample of one trial
 * and runs its minimal solver (32 trials at once: a trial's sample and models depend only on its
 * index); then all 32 lanes compute residuals and count each model's support, in the trials' order,
 * an integer (inliers, score), so the reduction order does not matter; local optimisation runs on
 * lane 0. The inlier lists are written in index order by a ballot prefix (the local solver reads them
 * in that order, as the CPU). Built with --fmad=false: no contraction anywhere. */
#include "verify_math.cuh"

#define CV_FULL_MASK 0xffffffffu

/* The warp as a verification team: lane 0 leads, ballots count and rank, shuffles sum. */
struct cv_warp_team {
    enum { SIZE = 32 };
    unsigned int lane_id;
    __device__ unsigned int lane() const { return lane_id; }
    __device__ bool leader() const { return lane_id == 0; }
    __device__ void sync() const { __syncwarp(CV_FULL_MASK); }
    __device__ unsigned int count(bool flag) const { return __popc(__ballot_sync(CV_FULL_MASK, flag)); }
    __device__ unsigned int rank(bool flag) const {
        return __popc(__ballot_sync(CV_FULL_MASK, flag) & ((1u << lane_id) - 1u));
    }
    __device__ unsigned long long sum(unsigned long long x) const {
        for (int offset = 16; offset > 0; offset >>= 1) x += __shfl_xor_sync(CV_FULL_MASK, x, offset);
        return x;
    }
};

/* The body of both entry points: pair blockIdx.x * CLATCH_VERIFY_WARPS + warp. */
__device__ __forceinline__ void verify_pairs_body(const clatch_verify_settings* __restrict__ settings,
                                                  const clatch_verify_pair* __restrict__ pairs, unsigned int pair_count,
                                                  const clatch_verify_point* __restrict__ points,
                                                  unsigned int* __restrict__ scratch, unsigned int* __restrict__ inliers,
                                                  clatch_verify_result* __restrict__ results) {
    __shared__ cv_model_buffers buffers[CLATCH_VERIFY_WARPS];
    unsigned int warp = threadIdx.x / 32;
    unsigned int index = blockIdx.x * CLATCH_VERIFY_WARPS + warp;
    if (index >= pair_count) return; /* the whole warp leaves together */
    cv_warp_team team;
    team.lane_id = threadIdx.x % 32;
    const clatch_verify_pair pair = pairs[index];
    unsigned long long first = pair.first;
    unsigned int* lists = scratch + (unsigned long long)CLATCH_VERIFY_LISTS * first;
    cv_pair_lists l = {lists, lists + pair.count, lists + 2ull * pair.count, lists + 3ull * pair.count};
    const clatch_verify_settings s = *settings;
    cv_estimate_two_view(team, s, pair, points + first, l, inliers + first, &buffers[warp], &results[index]);
}

/* Registers as the compiler likes (255 on sm_90: 8 warps per SM). A build in at most 128 registers
 * (16 warps per SM) was measured at 0.94-1.01x this one's rate and doubled ptxas's time (BENCHMARKS.md,
 * "Verification on the GPU"), so there is one. */
extern "C" __global__ void __launch_bounds__(32 * CLATCH_VERIFY_WARPS)
    clatch_verify_pairs(const clatch_verify_settings* __restrict__ settings, const clatch_verify_pair* __restrict__ pairs,
                        unsigned int pair_count, const clatch_verify_point* __restrict__ points,
                        unsigned int* __restrict__ scratch, unsigned int* __restrict__ inliers,
                        clatch_verify_result* __restrict__ results) {
    verify_pairs_body(settings, pairs, pair_count, points, scratch, inliers, results);
}
