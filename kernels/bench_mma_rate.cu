// clatch-ptx-arch: compute_80
// Bench kernel, compiled and loaded only with the `internals` feature (benches/gpu_match.rs), never by
// the library itself.
#include "clatch.h"
#include "mma_s8.cuh"

// Bench only: the int8 mma.sync rate of this GPU with nothing else in the way (no memory, no
// selection): each warp runs `iterations` rounds of 8 independent m16n8k32 chains; `sink` keeps the
// results alive. The host launches blocks of 8 warps, several per SM, and counts multiply-adds.
extern "C" __global__ void __launch_bounds__(CLATCH_TENSOR_WARPS * 32, 1) clatch_mma_s8_rate(unsigned iterations, int* sink) {
    unsigned a[4] = {threadIdx.x, threadIdx.x * 3u, threadIdx.x * 5u, threadIdx.x * 7u};
    const unsigned b0 = threadIdx.x * 11u, b1 = threadIdx.x * 13u;
    int acc[8][4] = {};
    for (unsigned i = 0; i < iterations; ++i) {
#pragma unroll
        for (int c = 0; c < 8; ++c) mma_s8(acc[c], a, b0 + c, b1);
    }
    int total = 0;
#pragma unroll
    for (int c = 0; c < 8; ++c) total += acc[c][0] + acc[c][1] + acc[c][2] + acc[c][3];
    if (total == 0x7fffffff) sink[threadIdx.x] = total;
}
