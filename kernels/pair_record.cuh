// The record a grouped kNN kernel leaves per query (kernels/match_pairs.cu, kernels/match_pairs_tensor.cu):
// its best match, with query = CLATCH_PAIRS_REJECTED when the ratio test or the distance limit refuses it
// (src/matching/cpu.rs::match_descriptors decides both from the query's k-list alone).
#ifndef CLATCH_PAIR_RECORD_CUH
#define CLATCH_PAIR_RECORD_CUH

#include "clatch.h"

template <int K>
__device__ __forceinline__ clatch_match best_record(unsigned long long qi, const unsigned (&dist)[K],
                                                    const unsigned (&index)[K], int use_ratio, float ratio,
                                                    int use_max_distance, unsigned max_distance) {
    bool keep = true;
    if constexpr (K >= 2) {
        // (d1 as f32) < ratio * (d2 as f32): exact conversions, one correctly rounded product.
        if (use_ratio) keep = __uint2float_rn(dist[0]) < __fmul_rn(ratio, __uint2float_rn(dist[1]));
    }
    if (use_max_distance) keep = keep && dist[0] <= max_distance;
    clatch_match m;
    m.query = keep ? (unsigned)qi : CLATCH_PAIRS_REJECTED;
    m.train = index[0];
    m.distance = dist[0];
    return m;
}

#endif  // CLATCH_PAIR_RECORD_CUH
