// clatch-ptx-arch: compute_80
// Grouped matching on the tensor cores: the twins of kernels/match_pairs.cu's kNN kernels, for rows
// expanded to +-1 bytes (clatch_expand_signs of kernels/matching_tensor.cu). Reproduces, pair by pair,
// src/matching/cpu.rs::match_descriptors exactly (docs/numerics.md, section 5), as kernels/match_pairs.cu
// does: one block per task, exactly (CLATCH_PAIRS_BLOCK_QUERIES = CLATCH_TENSOR_QUERIES queries of one pair against
// the pair's whole gallery), the body knn_tensor_rows of kernels/knn_tensor.cuh unchanged (int8 MMA dot
// products B - 2 h, exact; lists by (distance, index); the fused reverse 1-NN for the cross-check), and
// each query's best-match record (pair_record.cuh) written where clatch_pairs_compact reads it.
// Rows of BYTES bytes: row r of a buffer starts at byte BYTES * r; sets start at multiples of
// CLATCH_PAIRS_ROW_ALIGN rows (16-byte cp.async sources) and CLATCH_MATCH_ROW_PAD rows follow the last.
#include "knn_tensor.cuh"
#include "pair_record.cuh"

namespace {

static_assert(CLATCH_TENSOR_QUERIES == CLATCH_PAIRS_BLOCK_QUERIES, "a task is one tensor query block");
static_assert(CLATCH_MATCH_ROW_PAD >= CLATCH_TENSOR_QUERIES && CLATCH_MATCH_ROW_PAD >= CLATCH_TENSOR_TILE,
              "the tail padding covers a whole query block and a whole tile past the last set");

template <int BYTES, int K, bool MUTUAL>
__device__ __forceinline__ void pairs_knn_tensor(const signed char* __restrict__ query_rows,
                                                 const signed char* __restrict__ train_rows,
                                                 const clatch_pair* __restrict__ pairs,
                                                 const clatch_pair_task* __restrict__ tasks, unsigned n_tasks,
                                                 int use_ratio, float ratio, int use_max_distance,
                                                 unsigned max_distance, clatch_match* __restrict__ best,
                                                 u64* __restrict__ reverse) {
    // One block per task (the host launches n_tasks blocks): a grid-stride loop over tasks here cost
    // the 512-bit kernels 8-52 bytes of spills at 255 registers; without it they need 241-248, none.
    {
        const unsigned t = blockIdx.x;
        if (t >= n_tasks) return;  // block-uniform, so every barrier of the body is reached by all
        const clatch_pair_task task = tasks[t];
        const clatch_pair pair = pairs[task.pair];
        knn_tensor_rows<BYTES, K, MUTUAL>(
            query_rows + pair.query_row * BYTES, pair.query_rows, train_rows + pair.train_row * BYTES, 0,
            pair.train_rows, task.query_block, 1, task.query_block + 1,
            MUTUAL ? reverse + pair.reverse_row : reverse,
            [&](u64 qi, const unsigned (&dist)[K], const unsigned (&index)[K]) {
                // Read again here, after the gallery loop, rather than held in registers through it
                // (the 512-bit bodies have none to spare).
                const u64 best_row = pairs[tasks[t].pair].best_row;
                best[best_row + qi] = best_record<K>(qi, dist, index, use_ratio, ratio, use_max_distance,
                                                     max_distance);
            });
    }
}

}  // namespace

// Names start with clatch_knn_tensor so that the host raises their dynamic shared memory limit as for
// the single-pair tensor kernels (src/cuda/matching_tensor/, configure).
#define CLATCH_PAIRS_TENSOR_KERNEL(NAME, BYTES, K, MUTUAL)                                                 \
    extern "C" __global__ void __launch_bounds__(CLATCH_TENSOR_WARPS * 32, 1)                               \
        NAME(const signed char* __restrict__ query_rows, const signed char* __restrict__ train_rows,        \
             const clatch_pair* __restrict__ pairs, const clatch_pair_task* __restrict__ tasks,             \
             unsigned n_tasks, int use_ratio, float ratio, int use_max_distance, unsigned max_distance,     \
             clatch_match* __restrict__ best, u64* __restrict__ reverse) {                                  \
        pairs_knn_tensor<BYTES, K, MUTUAL>(query_rows, train_rows, pairs, tasks, n_tasks, use_ratio, ratio, \
                                           use_max_distance, max_distance, best, reverse);                  \
    }
#define CLATCH_PAIRS_TENSOR_KERNELS(BITS)                                                   \
    CLATCH_PAIRS_TENSOR_KERNEL(clatch_knn_tensor_pairs_b##BITS##_k1, BITS, 1, false)        \
    CLATCH_PAIRS_TENSOR_KERNEL(clatch_knn_tensor_pairs_b##BITS##_k2, BITS, 2, false)        \
    CLATCH_PAIRS_TENSOR_KERNEL(clatch_knn_tensor_pairs_mutual_b##BITS##_k1, BITS, 1, true)  \
    CLATCH_PAIRS_TENSOR_KERNEL(clatch_knn_tensor_pairs_mutual_b##BITS##_k2, BITS, 2, true)

CLATCH_PAIRS_TENSOR_KERNELS(64)
CLATCH_PAIRS_TENSOR_KERNELS(128)
CLATCH_PAIRS_TENSOR_KERNELS(256)
CLATCH_PAIRS_TENSOR_KERNELS(512)
