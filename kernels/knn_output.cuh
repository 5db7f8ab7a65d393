// Where a kNN kernel puts one query's list: shared by kernels/knn.cuh (popcount) and
// kernels/matching_tensor.cu (tensor cores), so both write the layout the host and clatch_knn_merge read.
#ifndef CLATCH_KNN_OUTPUT_CUH
#define CLATCH_KNN_OUTPUT_CUH

#include "clatch.h"

// Writes the first k entries of query qi's sorted K-list (distance, train index): with one gallery
// segment (gridDim.y == 1) as matches to out[qi * k ..], otherwise as (distance << 32 | index) keys to
// this segment's partial list, partial[(blockIdx.y * nq + qi) * k ..].
template <int K>
__device__ __forceinline__ void write_knn_list(unsigned long long qi, unsigned nq, unsigned k,
                                               const unsigned (&dist)[K], const unsigned (&index)[K],
                                               clatch_match* __restrict__ out,
                                               unsigned long long* __restrict__ partial) {
    if (gridDim.y == 1) {
        clatch_match* o = out + qi * k;
#pragma unroll
        for (int s = 0; s < K; ++s) {
            if ((unsigned)s < k) {
                clatch_match m;
                m.query = (unsigned)qi;
                m.train = index[s];
                m.distance = dist[s];
                o[s] = m;
            }
        }
    } else {
        unsigned long long* o = partial + ((unsigned long long)blockIdx.y * nq + qi) * k;
#pragma unroll
        for (int s = 0; s < K; ++s) {
            if ((unsigned)s < k) o[s] = ((unsigned long long)dist[s] << 32) | index[s];
        }
    }
}

#endif  // CLATCH_KNN_OUTPUT_CUH
