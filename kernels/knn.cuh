// Brute-force Hamming kNN: the kernel template shared by kernels/matching.cu (the production instantiations)
// and kernels/bench_knn_variants.cu (the alternatives the bench measures). Reproduces
// src/matching/cpu.rs::knn exactly (docs/numerics.md, section 5): the k smallest (distance, train index)
// pairs, nearest first, ties to the lowest train index.
//
// Scheme: one thread per query (QPT queries per thread), the gallery streamed through shared memory.
// - The CLATCH paper spreads one comparison over a warp: each lane XORs and counts a slice of the words and
//   a 5-step shuffle tree adds the lanes' counts, two distances packed in the 16-bit halves of a register
//   so that one tree serves two. Here every thread owns whole queries in registers instead and the gallery
//   descriptor it compares against is *broadcast* from shared memory (all lanes read the same address): a
//   distance costs no shuffle at all, no lane idles on descriptors narrower than a warp's worth of words
//   (8..512 bits), and the top-k list of a query lives in the registers of the one thread that owns it (no
//   cross-lane merging). One 16-byte shared load of two words serves 32 x QPT distances.
// - Gallery tiles are double-buffered in shared memory with a register-staged prefetch: the global loads of
//   tile t+1 are issued before comparing tile t, and their values are stored into the other buffer after
//   it, so their latency hides behind tile t's arithmetic. (cp.async would skip the registers, but the PTX
//   targets compute_75, which lacks it.) One barrier per tile suffices: tile t+1's buffer was last read in
//   iteration t-1, which every thread has left at the barrier closing t-1.
// - Banks: when comparing, all lanes of a warp read the same 16 (or 8) bytes, a broadcast, so no layout
//   has conflicts and the tile needs no padding. When staging, thread i writes the i-th 16-byte chunk of
//   the (contiguous) tile: a quarter warp's 8 chunks cover all 32 banks once, again conflict-free.
// - Popcount: each XORed 32-bit word goes either straight to POPC (G = 1) or through a carry-save adder
//   tree first (G = 3, 7, 15: Harley-Seal style), which turns G words into ceil(log2(G + 1)) words of
//   weights 1, 2, 4, 8 with 2 LOP3 per adder. POPC issues at a quarter of LOP3's rate (16 vs 64 per SM and
//   clock on Hopper), so trading POPCs for LOP3s pays until the ALU pipe saturates.
// - Cross-check (MUTUAL): the reverse 1-NN (the nearest query of every gallery descriptor, lowest query
//   index on ties) comes out of the same distances. After each gallery row a warp takes the minimum of its
//   queries' keys (distance << 6 | p << 5 | lane: 5 shuffles for 32 x QPT pairs; within a warp the query
//   index grows with (p, lane), so the smallest key is the nearest query with the lowest index), and lane
//   0 folds (distance << 32 | query) into that row's slot with an atomic minimum (stored complemented, as
//   an atomic maximum over a zeroed buffer). A minimum does not depend on the order of the updates, so the
//   result is deterministic. Measured on an H100 (512 bits, 64k x 64k, ratio test): 15.4 ms with the
//   cross-check against 11.8 ms without, where a second, role-swapped pass would add about 11.8 ms.
// - Ties: a thread scans its gallery segment in increasing train index and inserts only on a strictly
//   smaller distance, so among equal distances the earlier (lower) index stays first, as in the CPU
//   reference. Segments of one query (blocks along grid y) are merged by clatch_knn_merge comparing
//   (distance, index) lexicographically.
#ifndef CLATCH_KNN_CUH
#define CLATCH_KNN_CUH

#include "clatch.h"
#include "knn_output.cuh"

namespace clatch_knn {

typedef unsigned long long u64;

constexpr int THREADS = CLATCH_MATCH_THREADS;
constexpr int TILE = CLATCH_MATCH_TILE;
constexpr unsigned NONE = 0xffffffffu;  // empty list slot: distance and index both past any real value

__device__ __forceinline__ unsigned xor3(unsigned a, unsigned b, unsigned c) {
    unsigned r;
    asm("lop3.b32 %0, %1, %2, %3, 0x96;" : "=r"(r) : "r"(a), "r"(b), "r"(c));
    return r;
}

__device__ __forceinline__ unsigned majority(unsigned a, unsigned b, unsigned c) {
    unsigned r;
    asm("lop3.b32 %0, %1, %2, %3, 0xe8;" : "=r"(r) : "r"(a), "r"(b), "r"(c));
    return r;
}

// Carry-save adder: three bits of weight w become sum (weight w) and carry (weight 2w).
__device__ __forceinline__ void csa(unsigned& carry, unsigned& sum, unsigned a, unsigned b, unsigned c) {
    sum = xor3(a, b, c);
    carry = majority(a, b, c);
}

// Number of set bits in x[0..G).
template <int G>
__device__ __forceinline__ unsigned group_popcount(const unsigned* x);

template <>
__device__ __forceinline__ unsigned group_popcount<1>(const unsigned* x) {
    return __popc(x[0]);
}

template <>
__device__ __forceinline__ unsigned group_popcount<3>(const unsigned* x) {
    unsigned twos, ones;
    csa(twos, ones, x[0], x[1], x[2]);
    return __popc(ones) + 2 * __popc(twos);
}

template <>
__device__ __forceinline__ unsigned group_popcount<7>(const unsigned* x) {
    unsigned a1, s1, a2, s2, a3, ones, twos, fours;
    csa(a1, s1, x[0], x[1], x[2]);
    csa(a2, s2, x[3], x[4], x[5]);
    csa(a3, ones, s1, s2, x[6]);
    csa(fours, twos, a1, a2, a3);
    return __popc(ones) + 2 * __popc(twos) + 4 * __popc(fours);
}

template <>
__device__ __forceinline__ unsigned group_popcount<15>(const unsigned* x) {
    unsigned a1, a2, a3, a4, a5, a6, a7, s1, s2, s3, s4, s5, s6, ones;
    csa(a1, s1, x[0], x[1], x[2]);
    csa(a2, s2, x[3], x[4], x[5]);
    csa(a3, s3, x[6], x[7], x[8]);
    csa(a4, s4, x[9], x[10], x[11]);
    csa(a5, s5, x[12], x[13], x[14]);
    csa(a6, s6, s1, s2, s3);
    csa(a7, ones, s6, s4, s5);
    unsigned b1, t1, b2, t2, b3, twos, eights, fours;
    csa(b1, t1, a1, a2, a3);
    csa(b2, t2, a4, a5, a6);
    csa(b3, twos, t1, t2, a7);
    csa(eights, fours, b1, b2, b3);
    return __popc(ones) + 2 * __popc(twos) + 4 * __popc(fours) + 8 * __popc(eights);
}

// Set bits in x[0..N): groups of G words through an adder tree, the rest in smaller groups.
template <int N, int G>
__device__ __forceinline__ unsigned popcount(const unsigned* x) {
    if constexpr (N == 0) {
        return 0;
    } else if constexpr (N >= G) {
        return group_popcount<G>(x) + popcount<N - G, G>(x + G);
    } else {
        return popcount<N, (G == 15 ? 7 : G == 7 ? 3 : 1)>(x);
    }
}

// Inserts (d, i) into a list sorted by distance, given d < dist[K - 1]. Strict comparisons keep an
// earlier entry of equal distance first.
template <int K>
__device__ __forceinline__ void insert(unsigned (&dist)[K], unsigned (&index)[K], unsigned d, unsigned i) {
#pragma unroll
    for (int s = K - 1; s > 0; --s) {
        if (d < dist[s - 1]) {
            dist[s] = dist[s - 1];
            index[s] = index[s - 1];
        } else if (d < dist[s]) {
            dist[s] = d;
            index[s] = i;
        }
    }
    if (d < dist[0]) {
        dist[0] = d;
        index[0] = i;
    }
}

// Compares the QPT queries of this thread with rows [0, count) of a shared-memory tile whose first row is
// gallery descriptor `first`. FULL: count == TILE, known at compile time, and the loop is unrolled
// UNROLL times (the partial last tile of a segment runs rolled: it is rare and keeps the code small).
template <int WORDS, int K, int QPT, int G, int UNROLL, bool MUTUAL, bool FULL>
__device__ __forceinline__ void scan_tile(const uint4* __restrict__ tile, unsigned count, unsigned first,
                                          const unsigned (&q)[QPT][2 * WORDS], unsigned (&dist)[QPT][K],
                                          unsigned (&index)[QPT][K], unsigned warp_query,
                                          const unsigned (&tag)[QPT], u64* __restrict__ reverse) {
    constexpr int L = 2 * WORDS;
    const unsigned n = FULL ? TILE : count;
#pragma unroll(FULL ? UNROLL : 1)
    for (unsigned j = 0; j < n; ++j) {
        unsigned t[L];
        if constexpr (WORDS % 2 == 0) {
            const uint4* row = tile + j * (WORDS / 2);
#pragma unroll
            for (int c = 0; c < WORDS / 2; ++c) {
                const uint4 v = row[c];
                t[4 * c] = v.x;
                t[4 * c + 1] = v.y;
                t[4 * c + 2] = v.z;
                t[4 * c + 3] = v.w;
            }
        } else {
            const uint2* row = reinterpret_cast<const uint2*>(tile) + j * WORDS;
#pragma unroll
            for (int c = 0; c < WORDS; ++c) {
                const uint2 v = row[c];
                t[2 * c] = v.x;
                t[2 * c + 1] = v.y;
            }
        }
        unsigned d[QPT];
#pragma unroll
        for (int p = 0; p < QPT; ++p) {
            unsigned x[L];
#pragma unroll
            for (int w = 0; w < L; ++w) x[w] = q[p][w] ^ t[w];
            d[p] = popcount<L, G>(x);
        }
#pragma unroll
        for (int p = 0; p < QPT; ++p) {
            if (d[p] < dist[p][K - 1]) insert<K>(dist[p], index[p], d[p], first + j);
        }
        if constexpr (MUTUAL) {
            static_assert(QPT <= 2, "one bit of p in the reverse key");
            unsigned m = NONE;
#pragma unroll
            for (int p = 0; p < QPT; ++p) m = min(m, (d[p] << 6) | tag[p]);
#pragma unroll
            for (int o = 16; o > 0; o >>= 1) m = min(m, __shfl_xor_sync(0xffffffffu, m, o));
            if ((threadIdx.x & 31) == 0 && m != NONE) {
                const unsigned winner = warp_query + ((m >> 5) & 1) * THREADS + (m & 31);
                atomicMax(reverse + first + j, ~(((u64)(m >> 6) << 32) | winner));
            }
        }
    }
}

// Global -> registers part of the staged copy of one tile (TILE rows starting at `row`).
template <int WORDS>
struct Stage {
    static constexpr int CHUNKS = TILE * WORDS / 2;  // 16-byte chunks in a tile
    static constexpr int PER_THREAD = (CHUNKS + THREADS - 1) / THREADS;
    uint4 v[PER_THREAD];

    __device__ __forceinline__ void load(const u64* __restrict__ train, unsigned row) {
        const uint4* src = reinterpret_cast<const uint4*>(train + (size_t)row * WORDS);
#pragma unroll
        for (int i = 0; i < PER_THREAD; ++i) {
            const int c = i * THREADS + threadIdx.x;
            if (CHUNKS % THREADS == 0 || c < CHUNKS) v[i] = src[c];
        }
    }

    __device__ __forceinline__ void store(uint4* tile) const {
#pragma unroll
        for (int i = 0; i < PER_THREAD; ++i) {
            const int c = i * THREADS + threadIdx.x;
            if (CHUNKS % THREADS == 0 || c < CHUNKS) tile[c] = v[i];
        }
    }
};

// One block's QPT * THREADS queries in registers, with their k-lists and reverse-key tags: what the
// kNN body (below) and the grouped pair kernel (kernels/match_pairs.cu) keep per query block.
template <int WORDS, int K, int QPT>
struct QueryBlock {
    static constexpr int L = 2 * WORDS;
    unsigned q[QPT][L];
    unsigned dist[QPT][K], index[QPT][K];
    // Reverse-key tags: p << 5 | lane, or NONE for the padded query rows past nq (they never win).
    unsigned tag[QPT];
    unsigned warp_query;

    // Loads queries first + p * THREADS + threadIdx.x (p < QPT) of `query` (nq real rows; the rows past
    // them up to the whole block must be readable) and clears their lists.
    __device__ __forceinline__ void load(const u64* __restrict__ query, unsigned nq, u64 first) {
        warp_query = (unsigned)(first + (threadIdx.x & ~31u));
#pragma unroll
        for (int p = 0; p < QPT; ++p) {
            const u64 row = first + p * THREADS + threadIdx.x;
            tag[p] = row < nq ? (unsigned)(p << 5) | (threadIdx.x & 31) : NONE;
            const uint2* src = reinterpret_cast<const uint2*>(query + row * WORDS);
#pragma unroll
            for (int w = 0; w < WORDS; ++w) {
                const uint2 v = src[w];
                q[p][2 * w] = v.x;
                q[p][2 * w + 1] = v.y;
            }
#pragma unroll
            for (int s = 0; s < K; ++s) {
                dist[p][s] = NONE;
                index[p][s] = NONE;
            }
        }
    }

    // Compares the block's queries with gallery rows [first_row, end_row) of `train` (at least one row;
    // whole tiles from first_row on must be readable, first_row * WORDS even for 16-byte loads), tile by
    // tile through the double buffer `tiles`. Ends with a barrier, so `tiles` is free again on return.
    template <int G, int UNROLL, bool MUTUAL>
    __device__ __forceinline__ void scan(const u64* __restrict__ train, unsigned first_row, unsigned end_row,
                                         uint4 (&tiles)[2][Stage<WORDS>::CHUNKS], u64* __restrict__ reverse) {
        const unsigned tiles_in_segment = (end_row - first_row + TILE - 1) / TILE;
        Stage<WORDS> stage;
        stage.load(train, first_row);
        stage.store(tiles[0]);
        __syncthreads();
        for (unsigned t = 0; t < tiles_in_segment; ++t) {
            const unsigned tile_row = first_row + t * TILE;
            const bool more = t + 1 < tiles_in_segment;
            if (more) stage.load(train, tile_row + TILE);
            const unsigned count = min((unsigned)TILE, end_row - tile_row);
            if (count == TILE) {
                scan_tile<WORDS, K, QPT, G, UNROLL, MUTUAL, true>(tiles[t & 1], TILE, tile_row, q, dist, index,
                                                                  warp_query, tag, reverse);
            } else {
                scan_tile<WORDS, K, QPT, G, UNROLL, MUTUAL, false>(tiles[t & 1], count, tile_row, q, dist,
                                                                   index, warp_query, tag, reverse);
            }
            if (more) stage.store(tiles[(t + 1) & 1]);
            __syncthreads();
        }
    }
};

// The kNN kernel body. Grid: x over blocks of THREADS * QPT queries (grid-stride), y over gallery
// segments of `segment` rows (a multiple of TILE; the host makes every segment non-empty). Both descriptor
// buffers hold a whole number of CLATCH_MATCH_ROW_PAD rows (zero padding), so whole tiles and whole query
// blocks are always in bounds; padded gallery rows are never compared and padded queries never written.
// With one segment the k neighbours go straight to `out` (query-major, as KnnMatches); otherwise each
// segment writes its k best as (distance << 32 | index) keys to `partial[(segment * nq + query) * k + j]`.
//
// MUTUAL: also fold every (distance, query) pair into reverse[train index] (nt slots, zeroed by the host,
// complemented keys; see the cross-check note at the top).
template <int WORDS, int K, int QPT, int G, int UNROLL, bool MUTUAL>
__device__ __forceinline__ void knn(const u64* __restrict__ query, unsigned nq, const u64* __restrict__ train,
                                    unsigned nt, unsigned segment, unsigned k, clatch_match* __restrict__ out,
                                    u64* __restrict__ partial, u64* __restrict__ reverse) {
    static_assert(TILE % 2 == 0 && CLATCH_MATCH_ROW_PAD % TILE == 0, "whole 16-byte chunks, whole tiles");
    static_assert(CLATCH_MATCH_ROW_PAD % (THREADS * QPT) == 0, "whole query blocks");
    __shared__ uint4 tiles[2][Stage<WORDS>::CHUNKS];

    const u64 seg_begin = (u64)blockIdx.y * segment;
    const unsigned first_row = (unsigned)seg_begin;
    const unsigned end_row = (unsigned)min((u64)nt, seg_begin + segment);
    const unsigned query_blocks = (nq + THREADS * QPT - 1) / (THREADS * QPT);

    for (unsigned qb = blockIdx.x; qb < query_blocks; qb += gridDim.x) {
        QueryBlock<WORDS, K, QPT> block;
        block.load(query, nq, (u64)qb * (THREADS * QPT));
        block.template scan<G, UNROLL, MUTUAL>(train, first_row, end_row, tiles, reverse);

#pragma unroll
        for (int p = 0; p < QPT; ++p) {
            const u64 qi = (u64)qb * (THREADS * QPT) + p * THREADS + threadIdx.x;
            if (qi >= nq) continue;
            write_knn_list<K>(qi, nq, k, block.dist[p], block.index[p], out, partial);
        }
    }
}

}  // namespace clatch_knn

#endif  // CLATCH_KNN_CUH
