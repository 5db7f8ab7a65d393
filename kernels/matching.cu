// Hamming matching on the GPU. Reproduces src/matching/cpu.rs exactly (docs/numerics.md, section 5):
// - clatch_knn_w{W}_k{K}: the k nearest neighbours of every query (see knn.cuh for the scheme), one kernel
//   per descriptor width in 64-bit words W (1..8) and list length K (1, 2, 4, 8: k is rounded up to one of
//   these; the first k entries of a sorted top-K list are the top k); clatch_knn_mutual_w{W}_k{K} (K = 1,
//   2) also computes the nearest query of every gallery descriptor, for the cross-check;
// - clatch_knn_merge: the top k of the per-segment lists, when the gallery was split across blocks;
// - clatch_match_filter / clatch_match_scan / clatch_match_compact: ratio test, cross-check and distance
//   limit per query, then an order-preserving compaction of the kept best matches (per-block counts, one
//   exclusive scan, ballot ranks), so the result is deterministic and in query order.
#include "clatch.h"
#include "knn.cuh"

using clatch_knn::u64;

// Popcount scheme, queries per thread and unrolling, chosen by measurement on an H100 (512 bits, k = 2,
// 16k x 16k and 64k x 64k, CUDA events, medians; benches/gpu_match.rs times the alternatives of
// kernels/bench_knn_variants.cu): the 7-word carry-save tree with 2 queries per thread ran at 346 and
// 362 G pairs/s, plain POPC at 236 and 244 (its bound: 16 POPC per pair, 261), trees of 3 and 15 words at
// 325-343, 1 query per thread 2-4% slower; unrolling the gallery loop twice changed nothing (within 1%).
// The SASS of the 7-word tree has 8 POPC and 32 LOP3 per pair: it is bound by the integer ALU pipe.
#define CLATCH_MATCH_POPC_GROUP 7
#define CLATCH_MATCH_UNROLL 1
// Resident blocks asked of ptxas for the kernels with lists of 1 or 2: 5 blocks of 128 threads fit 96
// registers a thread, which the 512-bit kernels need without spilling (the fused reverse 1-NN would
// otherwise take 117 and drop to 4 blocks per SM). Longer lists keep what they need.
#define CLATCH_MATCH_MIN_BLOCKS 5

#define CLATCH_KNN_KERNEL(NAME, W, K, MUTUAL, MIN_BLOCKS)                                          \
    extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_THREADS, MIN_BLOCKS)                  \
        NAME(const u64* __restrict__ query, unsigned nq, const u64* __restrict__ train, unsigned nt, \
             unsigned segment, unsigned k, clatch_match* __restrict__ out,                         \
             u64* __restrict__ partial, u64* __restrict__ reverse) {                               \
        clatch_knn::knn<W, K, CLATCH_MATCH_QUERIES_PER_THREAD, CLATCH_MATCH_POPC_GROUP,            \
                        CLATCH_MATCH_UNROLL, MUTUAL>(query, nq, train, nt, segment, k, out,        \
                                                     partial, reverse);                            \
    }
// kNN alone for k up to 8; kNN with the fused reverse 1-NN for match_descriptors (k = 1 or 2).
#define CLATCH_KNN_KERNELS(W)                                                              \
    CLATCH_KNN_KERNEL(clatch_knn_w##W##_k1, W, 1, false, CLATCH_MATCH_MIN_BLOCKS)          \
    CLATCH_KNN_KERNEL(clatch_knn_w##W##_k2, W, 2, false, CLATCH_MATCH_MIN_BLOCKS)          \
    CLATCH_KNN_KERNEL(clatch_knn_w##W##_k4, W, 4, false, 1)                                \
    CLATCH_KNN_KERNEL(clatch_knn_w##W##_k8, W, 8, false, 1)                                \
    CLATCH_KNN_KERNEL(clatch_knn_mutual_w##W##_k1, W, 1, true, CLATCH_MATCH_MIN_BLOCKS)    \
    CLATCH_KNN_KERNEL(clatch_knn_mutual_w##W##_k2, W, 2, true, CLATCH_MATCH_MIN_BLOCKS)

CLATCH_KNN_KERNELS(1)
CLATCH_KNN_KERNELS(2)
CLATCH_KNN_KERNELS(3)
CLATCH_KNN_KERNELS(4)
CLATCH_KNN_KERNELS(5)
CLATCH_KNN_KERNELS(6)
CLATCH_KNN_KERNELS(7)
CLATCH_KNN_KERNELS(8)

// The k smallest (distance, index) keys of each query over all `segments` partial lists, written as
// matches. One thread per query; a key list of CLATCH_MATCH_MAX_K, of which the first k are used.
extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_SELECT_THREADS)
clatch_knn_merge(const u64* __restrict__ partial, unsigned nq, unsigned segments, unsigned k,
                 clatch_match* __restrict__ out) {
    constexpr int K = CLATCH_MATCH_MAX_K;
    for (u64 q = (u64)blockIdx.x * blockDim.x + threadIdx.x; q < nq; q += (u64)gridDim.x * blockDim.x) {
        u64 best[K];
#pragma unroll
        for (int s = 0; s < K; ++s) best[s] = ~0ull;
        for (unsigned g = 0; g < segments; ++g) {
            const u64* list = partial + ((u64)g * nq + q) * k;
            for (unsigned j = 0; j < k; ++j) {
                const u64 key = list[j];
                if (key >= best[K - 1]) break;  // each list is sorted
#pragma unroll
                for (int s = K - 1; s > 0; --s) {
                    if (key < best[s - 1]) {
                        best[s] = best[s - 1];
                    } else if (key < best[s]) {
                        best[s] = key;
                    }
                }
                if (key < best[0]) best[0] = key;
            }
        }
        clatch_match* o = out + q * k;
#pragma unroll
        for (int s = 0; s < K; ++s) {
            if ((unsigned)s < k) {
                clatch_match m;
                m.query = (unsigned)q;
                m.train = (unsigned)best[s];
                m.distance = (unsigned)(best[s] >> 32);
                o[s] = m;
            }
        }
    }
}

// Decides for every query whether its best match is kept (the CPU's match_descriptors filter) and counts
// the kept ones per block. knn: n x k neighbours (k = 2 with the ratio test, else 1). reverse: per gallery
// descriptor, the complemented key (distance << 32 | query) of its nearest query (read only when
// cross_check != 0).
// keep_bits: bit (q mod 32) of word q / 32; sized for whole blocks. counts: one per block.
extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_SELECT_THREADS)
clatch_match_filter(const clatch_match* __restrict__ knn, unsigned n, unsigned k, int use_ratio, float ratio,
                    int cross_check, const u64* __restrict__ reverse, int use_max_distance,
                    unsigned max_distance, unsigned* __restrict__ keep_bits, unsigned* __restrict__ counts) {
    const u64 q = (u64)blockIdx.x * CLATCH_MATCH_SELECT_THREADS + threadIdx.x;
    bool keep = false;
    if (q < n) {
        const clatch_match best = knn[q * k];
        keep = true;
        if (use_ratio) {
            // (d1 as f32) < ratio * (d2 as f32): exact conversions, one correctly rounded product.
            const float d1 = __uint2float_rn(best.distance);
            const float d2 = __uint2float_rn(knn[q * k + 1].distance);
            keep = d1 < __fmul_rn(ratio, d2);
        }
        if (keep && cross_check) keep = (unsigned)~reverse[best.train] == (unsigned)q;
        if (keep && use_max_distance) keep = best.distance <= max_distance;
    }
    const unsigned bits = __ballot_sync(0xffffffffu, keep);
    if ((threadIdx.x & 31) == 0) keep_bits[q >> 5] = bits;
    const int kept = __syncthreads_count(keep);
    if (threadIdx.x == 0) counts[blockIdx.x] = (unsigned)kept;
}

// Inclusive sum of v over the block (blockDim.x = CLATCH_MATCH_SCAN_THREADS); *total gets the block's
// sum. Uses warp_sums[32].
__device__ __forceinline__ unsigned block_inclusive_scan(unsigned v, unsigned* warp_sums, unsigned* total) {
    const unsigned lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
#pragma unroll
    for (int o = 1; o < 32; o <<= 1) {
        const unsigned u = __shfl_up_sync(0xffffffffu, v, o);
        if (lane >= (unsigned)o) v += u;
    }
    if (lane == 31) warp_sums[warp] = v;
    __syncthreads();
    if (warp == 0) {
        unsigned w = lane < blockDim.x / 32 ? warp_sums[lane] : 0;
#pragma unroll
        for (int o = 1; o < 32; o <<= 1) {
            const unsigned u = __shfl_up_sync(0xffffffffu, w, o);
            if (lane >= (unsigned)o) w += u;
        }
        warp_sums[lane] = w;
    }
    __syncthreads();
    const unsigned result = v + (warp > 0 ? warp_sums[warp - 1] : 0);
    *total = warp_sums[blockDim.x / 32 - 1];
    __syncthreads();  // warp_sums is reused by the next call
    return result;
}

// Exclusive prefix sum of counts[0..blocks), in place, by one block; *total gets the sum.
extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_SCAN_THREADS)
clatch_match_scan(unsigned* __restrict__ counts, unsigned blocks, unsigned* __restrict__ total) {
    __shared__ unsigned warp_sums[32];
    unsigned carry = 0;
    for (unsigned base = 0; base < blocks; base += CLATCH_MATCH_SCAN_THREADS) {
        const unsigned i = base + threadIdx.x;
        const unsigned v = i < blocks ? counts[i] : 0;
        unsigned sum;
        const unsigned inclusive = block_inclusive_scan(v, warp_sums, &sum);
        if (i < blocks) counts[i] = carry + inclusive - v;
        carry += sum;
    }
    if (threadIdx.x == 0) *total = carry;
}

// Writes the best match of every kept query to out[offset of its block + rank among the block's kept
// queries], so the kept matches come out in query order.
extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_SELECT_THREADS)
clatch_match_compact(const clatch_match* __restrict__ knn, unsigned n, unsigned k,
                     const unsigned* __restrict__ keep_bits, const unsigned* __restrict__ offsets,
                     clatch_match* __restrict__ out) {
    __shared__ unsigned warp_offsets[CLATCH_MATCH_SELECT_THREADS / 32];
    const u64 q = (u64)blockIdx.x * CLATCH_MATCH_SELECT_THREADS + threadIdx.x;
    const unsigned lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
    const unsigned bits = keep_bits[q >> 5];
    if (lane == 0) warp_offsets[warp] = __popc(bits);
    __syncthreads();
    if (threadIdx.x == 0) {
        unsigned sum = offsets[blockIdx.x];
        for (int w = 0; w < CLATCH_MATCH_SELECT_THREADS / 32; ++w) {
            const unsigned c = warp_offsets[w];
            warp_offsets[w] = sum;
            sum += c;
        }
    }
    __syncthreads();
    if ((bits >> lane) & 1) {
        const unsigned rank = __popc(bits & ((1u << lane) - 1));
        out[warp_offsets[warp] + rank] = knn[q * k];
    }
}
