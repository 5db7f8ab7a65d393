// Grouped matching: many (query set, gallery set) pairs per launch, for collections. Reproduces, pair by
// pair, src/matching/cpu.rs::match_descriptors exactly (docs/numerics.md, section 5):
// - clatch_pairs_knn_w{W}_k{K}[_mutual]: one block per task, a task being one query block of one pair
//   (CLATCH_PAIRS_BLOCK_QUERIES queries against the pair's whole gallery), so a launch covers a list of
//   pairs of any sizes with no host round trip and no per-pair launch. The body is knn.cuh's, unchanged
//   (QueryBlock::load and QueryBlock::scan: one thread per two queries, the gallery broadcast from
//   double-buffered shared-memory tiles, strict inserts in increasing gallery index, so ties go to the
//   lowest index). Each block scans its pair's whole gallery (no segments), so its k-list is final: the
//   ratio test and the distance limit are decided here and each query leaves one record, its best
//   match, with query = CLATCH_PAIRS_REJECTED when either test refuses it. MUTUAL (the cross-check) folds
//   the reverse 1-NN into the pair's slice of the reverse arena exactly as the single-pair kernels do
//   (warp minimum of (distance, query) keys, atomic maximum of complemented keys: order-independent).
// - The tensor-core twins of the kNN kernels are in kernels/match_pairs_tensor.cu; they leave the same
//   records, so this compaction serves both.
// - clatch_pairs_compact: one block per pair (grid-stride over pairs) keeps the queries whose record
//   survived and, with the cross-check, whose best gallery row names them as its nearest query; writes
//   the kept matches in query order to the pair's own slice of `kept` (starting at best_row, room for
//   every query) and their number to counts[pair]. The host copies both back.
#include "clatch.h"
#include "knn.cuh"
#include "pair_record.cuh"

using clatch_knn::u64;

namespace {

constexpr int THREADS = CLATCH_MATCH_THREADS;
constexpr int QPT = CLATCH_MATCH_QUERIES_PER_THREAD;
constexpr int SELECT_THREADS = CLATCH_MATCH_SELECT_THREADS;
static_assert(THREADS * QPT == CLATCH_PAIRS_BLOCK_QUERIES, "a task is one query block");
static_assert(CLATCH_PAIRS_ROW_ALIGN % 2 == 0, "every set starts on a 16-byte boundary for any width");
static_assert(CLATCH_MATCH_ROW_PAD >= CLATCH_PAIRS_BLOCK_QUERIES && CLATCH_MATCH_ROW_PAD >= CLATCH_MATCH_TILE,
              "the buffers' tail padding covers a whole query block and a whole tile past the last set");

// Same popcount scheme and register budget as the single-pair kernels (kernels/matching.cu).
constexpr int POPC_GROUP = 7;
constexpr int UNROLL = 1;

// The grouped kNN body. query_rows / train_rows: the query and gallery buffers (the same buffer for
// pairs among a collection's sets); every set in them starts at a multiple of CLATCH_PAIRS_ROW_ALIGN rows
// and the buffers hold CLATCH_MATCH_ROW_PAD zeroed rows past their last set, so whole query blocks and
// whole tiles read from any set's start stay in bounds. Every pair has query_rows >= 1 and train_rows >= 1
// (>= 2 with the ratio test). best: one record per query of every pair (at the pair's best_row).
// reverse (MUTUAL only): one complemented key per gallery row of every pair (at reverse_row), zeroed by
// the host before the launch.
template <int WORDS, int K, bool MUTUAL>
__device__ __forceinline__ void pairs_knn(const u64* __restrict__ query_rows, const u64* __restrict__ train_rows,
                                          const clatch_pair* __restrict__ pairs,
                                          const clatch_pair_task* __restrict__ tasks, unsigned n_tasks,
                                          int use_ratio, float ratio, int use_max_distance, unsigned max_distance,
                                          clatch_match* __restrict__ best, u64* __restrict__ reverse) {
    __shared__ uint4 tiles[2][clatch_knn::Stage<WORDS>::CHUNKS];
    for (unsigned t = blockIdx.x; t < n_tasks; t += gridDim.x) {
        // Block-uniform: every thread reads the same task, so every barrier below is reached by all.
        const clatch_pair_task task = tasks[t];
        const clatch_pair pair = pairs[task.pair];
        const u64* query = query_rows + pair.query_row * WORDS;
        const u64* train = train_rows + pair.train_row * WORDS;
        const u64 first = (u64)task.query_block * CLATCH_PAIRS_BLOCK_QUERIES;

        clatch_knn::QueryBlock<WORDS, K, QPT> block;
        block.load(query, pair.query_rows, first);
        block.template scan<POPC_GROUP, UNROLL, MUTUAL>(train, 0, pair.train_rows, tiles,
                                                        MUTUAL ? reverse + pair.reverse_row : reverse);

#pragma unroll
        for (int p = 0; p < QPT; ++p) {
            const u64 qi = first + p * THREADS + threadIdx.x;
            if (qi >= pair.query_rows) continue;
            best[pair.best_row + qi] = best_record<K>(qi, block.dist[p], block.index[p], use_ratio, ratio,
                                                      use_max_distance, max_distance);
        }
    }
}

}  // namespace

#define CLATCH_PAIRS_KNN_KERNEL(NAME, W, K, MUTUAL)                                                         \
    extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_THREADS, 5)                                   \
        NAME(const u64* __restrict__ query_rows, const u64* __restrict__ train_rows,                        \
             const clatch_pair* __restrict__ pairs, const clatch_pair_task* __restrict__ tasks,             \
             unsigned n_tasks, int use_ratio, float ratio, int use_max_distance, unsigned max_distance,     \
             clatch_match* __restrict__ best, u64* __restrict__ reverse) {                                  \
        pairs_knn<W, K, MUTUAL>(query_rows, train_rows, pairs, tasks, n_tasks, use_ratio, ratio,            \
                                use_max_distance, max_distance, best, reverse);                             \
    }
// k = 1 without the ratio test, 2 with it; the _mutual kernels also fold the reverse 1-NN.
#define CLATCH_PAIRS_KNN_KERNELS(W)                                               \
    CLATCH_PAIRS_KNN_KERNEL(clatch_pairs_knn_w##W##_k1, W, 1, false)              \
    CLATCH_PAIRS_KNN_KERNEL(clatch_pairs_knn_w##W##_k2, W, 2, false)              \
    CLATCH_PAIRS_KNN_KERNEL(clatch_pairs_knn_mutual_w##W##_k1, W, 1, true)        \
    CLATCH_PAIRS_KNN_KERNEL(clatch_pairs_knn_mutual_w##W##_k2, W, 2, true)

CLATCH_PAIRS_KNN_KERNELS(1)
CLATCH_PAIRS_KNN_KERNELS(2)
CLATCH_PAIRS_KNN_KERNELS(3)
CLATCH_PAIRS_KNN_KERNELS(4)
CLATCH_PAIRS_KNN_KERNELS(5)
CLATCH_PAIRS_KNN_KERNELS(6)
CLATCH_PAIRS_KNN_KERNELS(7)
CLATCH_PAIRS_KNN_KERNELS(8)

// Keeps, per pair, the queries whose best match passed the kNN kernel's tests and, with the cross-check,
// is mutual (its gallery row's nearest query, lowest index on ties, is this query); writes them in query
// order to kept[best_row ..] and their number to counts[pair]. blockDim.x = CLATCH_MATCH_SELECT_THREADS.
extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_SELECT_THREADS)
clatch_pairs_compact(const clatch_pair* __restrict__ pairs, unsigned n_pairs, const clatch_match* __restrict__ best,
                     int cross_check, const u64* __restrict__ reverse, clatch_match* __restrict__ kept,
                     unsigned* __restrict__ counts) {
    __shared__ unsigned warp_kept[SELECT_THREADS / 32];
    const unsigned lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
    for (unsigned p = blockIdx.x; p < n_pairs; p += gridDim.x) {
        const clatch_pair pair = pairs[p];
        const clatch_match* records = best + pair.best_row;
        clatch_match* out = kept + pair.best_row;
        unsigned carry = 0;  // kept queries before this chunk (the same in every thread)
        for (unsigned base = 0; base < pair.query_rows; base += SELECT_THREADS) {
            const unsigned q = base + threadIdx.x;
            bool keep = false;
            clatch_match m = {0u, 0u, 0u};
            if (q < pair.query_rows) {
                m = records[q];
                keep = m.query != CLATCH_PAIRS_REJECTED;
                if (keep && cross_check) keep = (unsigned)~reverse[pair.reverse_row + m.train] == q;
            }
            const unsigned bits = __ballot_sync(0xffffffffu, keep);
            if (lane == 0) warp_kept[warp] = __popc(bits);
            __syncthreads();
            unsigned before = carry, chunk = 0;
#pragma unroll
            for (int w = 0; w < SELECT_THREADS / 32; ++w) {
                const unsigned c = warp_kept[w];
                before += (unsigned)w < warp ? c : 0;
                chunk += c;
            }
            if (keep) out[before + __popc(bits & ((1u << lane) - 1))] = m;
            carry += chunk;
            __syncthreads();  // warp_kept is rewritten by the next chunk
        }
        if (threadIdx.x == 0) counts[p] = carry;
    }
}
