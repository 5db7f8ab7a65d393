// clatch-ptx-arch: compute_80
// Brute-force Hamming kNN on the tensor cores. Reproduces src/matching/cpu.rs::knn exactly for k <= 2
// (docs/numerics.md, section 5): the k smallest (distance, train index) pairs, ties to the lower index.
//
// Exactness strategy: a descriptor of B bits becomes B signed bytes, +1 for a 0 bit and -1 for a 1 bit
// (clatch_expand_signs). The int8 dot product of two such rows is (B - h) - h = B - 2h, where h is their
// Hamming distance, so h = (B - dot) / 2, exactly: the tensor cores add small integers in int32. Rows are
// padded to a power-of-two number of 64-bit words with zero bits on both sides (+1 * +1 per padded
// position: the same constant for every pair, taken out with B). No rounding anywhere.
//
// Scheme (mma.sync.m16n8k32.s8, sm_80 and later; the host keeps the popcount kernels of matching.cu for
// older GPUs and for k > 2):
// - A block owns 256 queries: each of its 8 warps keeps 32 of them (two m16 tiles) in registers as MMA
//   A-fragments for the whole run, so queries never touch shared memory.
// - The gallery streams through shared memory in tiles of 64 rows, three stages deep (cp.async). Rows
//   are stored in 16-byte chunks XOR-swizzled by the row number, so the eight row addresses of each
//   ldmatrix land in eight different bank groups (no conflicts), and cp.async writes whole chunks.
// - Per tile a warp computes its 32 x 64 dot products in two halves of 32 columns (32 int32
//   accumulators a thread), then folds them into running top-k lists (k = 1, 2) kept per query row in
//   "dot" form (larger dot = smaller distance). A column only takes the slow insert path when it beats
//   the row's current k-th best, which after the first tiles is rare.
// - Each thread sees the columns 2t, 2t + 1 (mod 8) of its rows and scans them in increasing gallery
//   index, inserting on a strictly larger dot, so its list is ordered by (distance, index). The four
//   threads that share a row merge their lists by (distance, index) at the end (two shuffles).
// - MUTUAL (the cross-check): the same dot products also give every gallery row its nearest query,
//   lowest query index on ties. Per tile column a thread takes the best of its four rows (in increasing
//   row order, strictly better only), the eight row groups of a warp combine by shuffles, the eight warps
//   by a shared-memory atomic maximum of a packed key ((dot + 1024) << 8 | 255 - row in block), and one
//   thread per column folds the block's winner into reverse[column] as a complemented
//   (distance << 32 | query) key with a global atomic maximum, the form matching.cu's fused reverse 1-NN
//   fills. Maxima do not depend on the order of the updates: deterministic.
#include "knn_tensor.cuh"

// Writes each row of `words` 64-bit words as `bytes` signed bytes (+1 for a 0 bit, -1 for a 1 bit, bit j
// of byte i to byte 8 i + j), zero bits (+1) past the row's words. rows: rows of both buffers.
extern "C" __global__ void __launch_bounds__(CLATCH_EXPAND_THREADS)
clatch_expand_signs(const u64* __restrict__ bits, unsigned rows, unsigned words, unsigned bytes,
                    uint2* __restrict__ out) {
    const u64 per_row = bytes / 8;  // output uint2 (8 bytes) per row = input bytes per row, padded
    const u64 total = (u64)rows * per_row;
    for (u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x; i < total; i += (u64)gridDim.x * blockDim.x) {
        const u64 row = i / per_row;
        const unsigned byte_in_row = (unsigned)(i % per_row);
        unsigned v = 0;
        if (byte_in_row < words * 8) {
            const u64 word = bits[row * words + byte_in_row / 8];
            v = (unsigned)(word >> (8 * (byte_in_row % 8))) & 0xffu;
        }
        out[i] = make_uint2(expand_nibble(v & 15u), expand_nibble(v >> 4));
    }
}

#define CLATCH_TENSOR_KERNEL(NAME, BYTES, K, MUTUAL)                                                    \
    extern "C" __global__ void __launch_bounds__(THREADS, 1)                                             \
        NAME(const signed char* __restrict__ query, unsigned nq, const signed char* __restrict__ train, \
             unsigned nt, unsigned segment, unsigned k, clatch_match* __restrict__ out,                \
             u64* __restrict__ partial, u64* __restrict__ reverse) {                                   \
        knn_tensor<BYTES, K, MUTUAL>(query, nq, train, nt, segment, k, out, partial, reverse);         \
    }
#define CLATCH_TENSOR_KERNELS(BITS)                                              \
    CLATCH_TENSOR_KERNEL(clatch_knn_tensor_b##BITS##_k1, BITS, 1, false)         \
    CLATCH_TENSOR_KERNEL(clatch_knn_tensor_b##BITS##_k2, BITS, 2, false)         \
    CLATCH_TENSOR_KERNEL(clatch_knn_tensor_mutual_b##BITS##_k1, BITS, 1, true)   \
    CLATCH_TENSOR_KERNEL(clatch_knn_tensor_mutual_b##BITS##_k2, BITS, 2, true)

CLATCH_TENSOR_KERNELS(64)
CLATCH_TENSOR_KERNELS(128)
CLATCH_TENSOR_KERNELS(256)
CLATCH_TENSOR_KERNELS(512)
