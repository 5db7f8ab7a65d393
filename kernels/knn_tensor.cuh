// Brute-force Hamming kNN on the tensor cores: the body shared by kernels/matching_tensor.cu (single
// pairs, see its notes for the scheme and the exactness strategy) and kernels/match_pairs_tensor.cu (many
// pairs per launch). Needs sm_80 (int8 mma.sync, cp.async, ldmatrix). Internal linkage: each kernel
// file gets its own copy.
#ifndef CLATCH_KNN_TENSOR_CUH
#define CLATCH_KNN_TENSOR_CUH

#include "clatch.h"
#include "knn_output.cuh"
#include "mma_s8.cuh"

typedef unsigned long long u64;

namespace {

constexpr int WARPS = CLATCH_TENSOR_WARPS;
constexpr int THREADS = WARPS * 32;
constexpr int BLOCK_QUERIES = CLATCH_TENSOR_QUERIES;
constexpr int TILE = CLATCH_TENSOR_TILE;
constexpr int STAGES = CLATCH_TENSOR_STAGES;
constexpr unsigned NONE = 0xffffffffu;
constexpr int WORST = -0x7fffffff - 1;  // below every real dot product (>= -512)

static_assert(BLOCK_QUERIES == WARPS * 32, "32 queries per warp");
static_assert(CLATCH_MATCH_ROW_PAD % BLOCK_QUERIES == 0 && CLATCH_MATCH_ROW_PAD % TILE == 0,
              "padded buffers hold whole query blocks and whole tiles");

// Expands 4 bits into 4 bytes: +1 for 0, -1 (0xff) for 1, bit j into byte j.
__device__ __forceinline__ unsigned expand_nibble(unsigned n) {
    const unsigned ones = (n * 0x00204081u) & 0x01010101u;  // bit j -> bit 0 of byte j (no overlaps)
    return 0x01010101u + ones * 0xfeu;                       // 0x01 or 0xff per byte, no carries
}

__device__ __forceinline__ void cp_async16(void* smem, const void* global) {
    const unsigned dst = (unsigned)__cvta_generic_to_shared(smem);
    asm volatile("cp.async.cg.shared.global [%0], [%1], 16;" ::"r"(dst), "l"(global));
}

__device__ __forceinline__ void cp_async_commit() { asm volatile("cp.async.commit_group;"); }

template <int N>
__device__ __forceinline__ void cp_async_wait() {
    asm volatile("cp.async.wait_group %0;" ::"n"(N));
}

__device__ __forceinline__ void ldmatrix_x4(unsigned (&r)[4], const void* smem) {
    const unsigned a = (unsigned)__cvta_generic_to_shared(smem);
    asm volatile("ldmatrix.sync.aligned.m8n8.x4.shared.b16 {%0, %1, %2, %3}, [%4];"
                 : "=r"(r[0]), "=r"(r[1]), "=r"(r[2]), "=r"(r[3])
                 : "r"(a));
}

// Where 16-byte chunk c of tile row r lives: rows of CHUNKS chunks, chunk index XORed with the row so
// that 8 consecutive rows at one chunk index fill all 32 banks.
template <int CHUNKS>
__device__ __forceinline__ int swizzled(int r, int c) {
    if constexpr (CHUNKS >= 8) {
        return r * CHUNKS + (c ^ (r & 7));
    } else {
        static_assert(CHUNKS == 4, "rows of 64 bytes or a multiple of 128");
        return r * CHUNKS + (c ^ ((r >> 1) & 3));
    }
}

// A k-list in dot form: dot[0] >= dot[1], ties in increasing index (dot WORST = empty).
template <int K>
struct TopK {
    int dot[K];
    unsigned index[K];

    __device__ __forceinline__ void clear() {
#pragma unroll
        for (int s = 0; s < K; ++s) {
            dot[s] = WORST;
            index[s] = NONE;
        }
    }

    // For candidates met in increasing index order: strictly larger dots only.
    __device__ __forceinline__ void insert(int v, unsigned i) {
        if (v > dot[K - 1]) {
            if constexpr (K == 2) {
                if (v > dot[0]) {
                    dot[1] = dot[0];
                    index[1] = index[0];
                    dot[0] = v;
                    index[0] = i;
                } else {
                    dot[1] = v;
                    index[1] = i;
                }
            } else {
                dot[0] = v;
                index[0] = i;
            }
        }
    }

    // Merges the list of the lane `mask` away, by (distance, index) = (dot descending, index ascending).
    __device__ __forceinline__ void merge_lane(int mask) {
        int od[K];
        unsigned oi[K];
#pragma unroll
        for (int s = 0; s < K; ++s) {
            od[s] = __shfl_xor_sync(0xffffffffu, dot[s], mask);
            oi[s] = __shfl_xor_sync(0xffffffffu, index[s], mask);
        }
        const auto better = [](int d0, unsigned i0, int d1, unsigned i1) {
            return d0 > d1 || (d0 == d1 && i0 < i1);
        };
        if constexpr (K == 1) {
            if (better(od[0], oi[0], dot[0], index[0])) {
                dot[0] = od[0];
                index[0] = oi[0];
            }
        } else {
            int d0, d1;
            unsigned i0, i1;
            if (better(dot[0], index[0], od[0], oi[0])) {
                d0 = dot[0];
                i0 = index[0];
                const bool mine = better(dot[1], index[1], od[0], oi[0]);
                d1 = mine ? dot[1] : od[0];
                i1 = mine ? index[1] : oi[0];
            } else {
                d0 = od[0];
                i0 = oi[0];
                const bool mine = better(dot[0], index[0], od[1], oi[1]);
                d1 = mine ? dot[0] : od[1];
                i1 = mine ? index[0] : oi[1];
            }
            dot[0] = d0;
            index[0] = i0;
            dot[1] = d1;
            index[1] = i1;
        }
    }
};

// The kNN body for rows of BYTES signed bytes (BYTES = 64 * power-of-two words, BITS = BYTES): query
// blocks qb = qb_first, qb_first + qb_step, ... below qb_end (256 queries each, nq real ones; the
// query buffer holds whole blocks) against gallery rows [first_row, end_row) (non-empty; whole tiles
// from first_row on readable, first_row * BYTES a multiple of 16). emit(qi, dist, index) takes each real
// query's sorted k-list (distance NONE for an empty slot), from the lane that holds it. MUTUAL folds each
// gallery row's nearest query (its index among the nq) into reverse[row] (complemented keys, zeroed by
// the host). Shared by knn_tensor (below) and the grouped kernels of kernels/match_pairs_tensor.cu.
template <int BYTES, int K, bool MUTUAL, class Emit>
__device__ __forceinline__ void knn_tensor_rows(const signed char* __restrict__ query, unsigned nq,
                                                const signed char* __restrict__ train, unsigned first_row,
                                                unsigned end_row, unsigned qb_first, unsigned qb_step,
                                                unsigned qb_end, u64* __restrict__ reverse, Emit emit) {
    constexpr int CHUNKS = BYTES / 16;           // 16-byte chunks per row
    constexpr int KSTEPS = BYTES / 32;           // k32 MMA steps per row
    constexpr int TILE_CHUNKS = TILE * CHUNKS;  // chunks per stage
    static_assert(TILE_CHUNKS % THREADS == 0, "whole chunks per thread");
    extern __shared__ uint4 stages[];
    // MUTUAL: per tile column, the best packed (dot, row) key of the block, two tiles in flight.
    __shared__ unsigned column_keys[2][TILE];

    const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
    const int group = lane >> 2, quad = lane & 3;

    const unsigned tiles = (end_row - first_row + TILE - 1) / TILE;

    const auto load_tile = [&](unsigned t) {
        uint4* stage = stages + (t % STAGES) * TILE_CHUNKS;
        const uint4* src = reinterpret_cast<const uint4*>(train + (u64)(first_row + t * TILE) * BYTES);
#pragma unroll
        for (int i = 0; i < TILE_CHUNKS / THREADS; ++i) {
            const int c = i * THREADS + threadIdx.x;
            cp_async16(stage + swizzled<CHUNKS>(c / CHUNKS, c % CHUNKS), src + c);
        }
    };

    // MUTUAL: folds the block's winners of tile t's columns into `reverse` and clears their slots
    // (threads 0..TILE-1; between the barrier after tile t and the one closing tile t + 1).
    const auto flush_columns = [&](unsigned t, unsigned qb) {
        if (threadIdx.x < TILE) {
            unsigned& slot = column_keys[t & 1][threadIdx.x];
            const unsigned key = slot;
            const unsigned col = first_row + t * TILE + threadIdx.x;
            if (key != 0 && col < end_row) {
                const int dot = (int)(key >> 8) - 1024;
                const unsigned q = qb * BLOCK_QUERIES + (255u - (key & 255u));
                const unsigned dist = (unsigned)(BYTES - dot) >> 1;
                atomicMax(reverse + col, ~(((u64)dist << 32) | q));
            }
            slot = 0;
        }
    };
    if (MUTUAL && threadIdx.x < TILE) {
        column_keys[0][threadIdx.x] = 0;
        column_keys[1][threadIdx.x] = 0;
    }

    for (unsigned qb = qb_first; qb < qb_end; qb += qb_step) {
        // A-fragments of this warp's 32 queries (m16 tiles mt = 0, 1), all k-steps: row group (+8),
        // bytes 4 * quad (+16) of each 32-byte step.
        const u64 warp_row = (u64)qb * BLOCK_QUERIES + warp * 32;
        unsigned a[2][KSTEPS][4];
#pragma unroll
        for (int mt = 0; mt < 2; ++mt) {
#pragma unroll
            for (int i = 0; i < 4; ++i) {
                const u64 row = warp_row + mt * 16 + group + (i & 1) * 8;
                const unsigned* src = reinterpret_cast<const unsigned*>(query + row * BYTES) + quad + (i >> 1) * 4;
#pragma unroll
                for (int s = 0; s < KSTEPS; ++s) a[mt][s][i] = src[s * 8];
            }
        }
        // Lists of this thread's four rows: (mt, half) -> row mt * 16 + group + half * 8.
        TopK<K> best[2][2];
        // MUTUAL: row (mt, h)'s packed column key is dot * scale + offset = (dot + 1024) << 8 | 255 - row,
        // one multiply-add; padded rows past nq get 0 * dot + 0, which never wins a column.
        int scale[2][2], offset[2][2];
#pragma unroll
        for (int mt = 0; mt < 2; ++mt) {
            best[mt][0].clear();
            best[mt][1].clear();
#pragma unroll
            for (int h = 0; h < 2; ++h) {
                const unsigned r = warp * 32 + mt * 16 + group + h * 8;
                const bool real = (u64)qb * BLOCK_QUERIES + r < nq;
                scale[mt][h] = real ? 256 : 0;
                offset[mt][h] = real ? (1024 << 8) | (255 - (int)r) : 0;
            }
        }

        __syncthreads();  // the previous query block is done with every stage
#pragma unroll
        for (int p = 0; p < STAGES - 1; ++p) {
            if ((unsigned)p < tiles) load_tile(p);
            cp_async_commit();
        }
        for (unsigned t = 0; t < tiles; ++t) {
            cp_async_wait<STAGES - 2>();
            __syncthreads();  // tile t is in; every warp has left tile t - 1, whose stage is reloaded next
            if (t + STAGES - 1 < tiles) load_tile(t + STAGES - 1);
            cp_async_commit();
            if (MUTUAL && t > 0) flush_columns(t - 1, qb);

            const uint4* stage = stages + (t % STAGES) * TILE_CHUNKS;
            const unsigned tile_row = first_row + t * TILE;
            const bool partial_tile = tile_row + TILE > end_row;
#pragma unroll
            for (int half = 0; half < TILE / 32; ++half) {
                int acc[2][4][4];
#pragma unroll
                for (int mt = 0; mt < 2; ++mt)
#pragma unroll
                    for (int nt = 0; nt < 4; ++nt)
#pragma unroll
                        for (int e = 0; e < 4; ++e) acc[mt][nt][e] = 0;
#pragma unroll
                for (int s = 0; s < KSTEPS; ++s) {
                    unsigned b[4][2];
#pragma unroll
                    for (int pair = 0; pair < 2; ++pair) {
                        // Matrices: (n-tile 2 pair, low 16 bytes), (same, high), (n-tile 2 pair + 1, low), (same, high).
                        const int m = lane >> 3;
                        const int r = half * 32 + (2 * pair + (m >> 1)) * 8 + (lane & 7);
                        unsigned v[4];
                        ldmatrix_x4(v, stage + swizzled<CHUNKS>(r, 2 * s + (m & 1)));
                        b[2 * pair][0] = v[0];
                        b[2 * pair][1] = v[1];
                        b[2 * pair + 1][0] = v[2];
                        b[2 * pair + 1][1] = v[3];
                    }
#pragma unroll
                    for (int mt = 0; mt < 2; ++mt)
#pragma unroll
                        for (int nt = 0; nt < 4; ++nt) mma_s8(acc[mt][nt], a[mt][s], b[nt][0], b[nt][1]);
                }
                // Columns 2 quad, 2 quad + 1 of each n-tile, in increasing gallery index.
                const unsigned col0 = tile_row + half * 32 + 2 * quad;
#pragma unroll
                for (int mt = 0; mt < 2; ++mt) {
#pragma unroll
                    for (int h = 0; h < 2; ++h) {
                        TopK<K>& list = best[mt][h];
#pragma unroll
                        for (int nt = 0; nt < 4; ++nt) {
                            const unsigned c = col0 + nt * 8;
                            int v0 = acc[mt][nt][2 * h], v1 = acc[mt][nt][2 * h + 1];
                            if (partial_tile) {
                                v0 = c < end_row ? v0 : WORST;
                                v1 = c + 1 < end_row ? v1 : WORST;
                            }
                            if (max(v0, v1) > list.dot[K - 1]) {
                                list.insert(v0, c);
                                list.insert(v1, c + 1);
                            }
                        }
                    }
                }
                if constexpr (MUTUAL) {
                    // Each thread packs its four rows' keys of its eight columns j = 2 nt + e, then the
                    // eight row groups (lanes 4 apart) reduce by halves: at each step a lane keeps the
                    // half of its columns selected by its group bit and takes the other lane's maxima of
                    // it, so after 4 + 2 + 1 shuffles lane (group, quad) holds column j = group's maximum
                    // over the warp's 32 rows, and one shared atomic per lane folds the 32 columns in.
                    // Max is associative and commutative: the same keys win as in any order.
                    int key[8];
#pragma unroll
                    for (int nt = 0; nt < 4; ++nt) {
#pragma unroll
                        for (int e = 0; e < 2; ++e) {
                            int k = 0;
#pragma unroll
                            for (int mt = 0; mt < 2; ++mt) {
#pragma unroll
                                for (int h = 0; h < 2; ++h)
                                    k = max(k, acc[mt][nt][2 * h + e] * scale[mt][h] + offset[mt][h]);
                            }
                            key[2 * nt + e] = k;
                        }
                    }
#pragma unroll
                    for (int step = 0; step < 3; ++step) {
                        const int width = 4 >> step;             // columns kept: 4, 2, 1
                        const bool upper = (group >> (2 - step)) & 1;  // group bits 2, 1, 0
#pragma unroll
                        for (int i = 0; i < width; ++i) {
                            const int send = upper ? key[i] : key[i + width];
                            const int keep = upper ? key[i + width] : key[i];
                            key[i] = max(keep, __shfl_xor_sync(0xffffffffu, send, 16 >> step));
                        }
                    }
                    // Column j = group: n-tile j / 2, column 2 quad + j % 2 within it.
                    if (key[0] != 0)
                        atomicMax(&column_keys[t & 1][half * 32 + (group >> 1) * 8 + 2 * quad + (group & 1)],
                                  (unsigned)key[0]);
                }
            }
        }
        cp_async_wait<0>();
        if constexpr (MUTUAL) {
            __syncthreads();  // every warp's keys of the last tile are in
            if (tiles > 0) flush_columns(tiles - 1, qb);
            __syncthreads();  // slots cleared before the next query block
        }

        // Merge the four lanes of each row group, then lane quad 0 writes.
#pragma unroll
        for (int mt = 0; mt < 2; ++mt) {
#pragma unroll
            for (int h = 0; h < 2; ++h) {
                TopK<K>& list = best[mt][h];
                list.merge_lane(1);
                list.merge_lane(2);
                const u64 qi = warp_row + mt * 16 + group + h * 8;
                if (quad != 0 || qi >= nq) continue;
                unsigned dist[K];
#pragma unroll
                for (int s = 0; s < K; ++s)
                    dist[s] = list.dot[s] == WORST ? NONE : (unsigned)(BYTES - list.dot[s]) >> 1;
                emit(qi, dist, list.index);
            }
        }
    }
}

// The single-pair kNN body. Grid: x over blocks of 256 queries (grid-stride), y over gallery segments
// of `segment` rows (a multiple of TILE, every segment non-empty). Both buffers hold whole padded
// blocks of rows. With one segment the lists go to `out` (query-major, k per query); otherwise as
// (distance << 32 | index) keys to partial[(segment * nq + query) * k + j]. MUTUAL folds each gallery
// row's nearest query into reverse[row] (nt complemented keys, zeroed by the host).
template <int BYTES, int K, bool MUTUAL>
__device__ __forceinline__ void knn_tensor(const signed char* __restrict__ query, unsigned nq,
                                           const signed char* __restrict__ train, unsigned nt,
                                           unsigned segment, unsigned k, clatch_match* __restrict__ out,
                                           u64* __restrict__ partial, u64* __restrict__ reverse) {
    const u64 seg_begin = (u64)blockIdx.y * segment;
    const unsigned first_row = (unsigned)seg_begin;
    const unsigned end_row = (unsigned)min((u64)nt, seg_begin + segment);
    const unsigned query_blocks = (nq + BLOCK_QUERIES - 1) / BLOCK_QUERIES;
    knn_tensor_rows<BYTES, K, MUTUAL>(
        query, nq, train, first_row, end_row, blockIdx.x, gridDim.x, query_blocks, reverse,
        [&](u64 qi, const unsigned (&dist)[K], const unsigned (&index)[K]) {
            write_knn_list<K>(qi, nq, k, dist, index, out, partial);
        });
}

}  // namespace

#endif  // CLATCH_KNN_TENSOR_CUH
