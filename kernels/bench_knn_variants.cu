// The alternatives to the production kNN kernel that benches/gpu_match.rs times (512-bit descriptors,
// k = 2): queries per thread (1 or 2) x popcount scheme (plain POPC, or carry-save trees of 3, 7 or 15
// words), and the production choice (2 queries, 7-word trees) with the gallery loop unrolled twice. Same
// template and arguments as clatch_knn_w8_k2.
#include "clatch.h"
#include "knn.cuh"

using clatch_knn::u64;

#define CLATCH_KNN_VARIANT(QPT, G, U)                                                             \
    extern "C" __global__ void __launch_bounds__(CLATCH_MATCH_THREADS)                             \
        clatch_knn_variant_q##QPT##_g##G##_u##U(const u64* __restrict__ query, unsigned nq,        \
                                                const u64* __restrict__ train, unsigned nt,        \
                                                unsigned segment, unsigned k,                      \
                                                clatch_match* __restrict__ out,                    \
                                                u64* __restrict__ partial,                         \
                                                u64* __restrict__ reverse) {                       \
        clatch_knn::knn<8, 2, QPT, G, U, false>(query, nq, train, nt, segment, k, out, partial,   \
                                                reverse);                                          \
    }

CLATCH_KNN_VARIANT(1, 1, 1)
CLATCH_KNN_VARIANT(1, 3, 1)
CLATCH_KNN_VARIANT(1, 7, 1)
CLATCH_KNN_VARIANT(1, 15, 1)
CLATCH_KNN_VARIANT(2, 1, 1)
CLATCH_KNN_VARIANT(2, 3, 1)
CLATCH_KNN_VARIANT(2, 7, 1)
CLATCH_KNN_VARIANT(2, 15, 1)
CLATCH_KNN_VARIANT(2, 7, 2)
