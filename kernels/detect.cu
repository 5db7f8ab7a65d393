// FAST-9 detection on the GPU. Reproduces src/detect/cpu.rs exactly (docs/numerics.md, section 3),
// ties included, with no host round trip between the stages (all launched on one stream):
//
// 1. clatch_detect_nms: one thread per pixel of a 32x16 tile (CLATCH_DETECT_TILE_X/Y). The block
//    loads the tile plus a 4-pixel border through the texture into shared memory, scores the tile
//    plus a 1-pixel border (FAST-9; 0 outside the margin and for non-corners), and applies the 3x3
//    suppression with the raster-order rule to its own pixels. It writes the kept map (the score of each survivor, 0 elsewhere; rows
//    CLATCH_DETECT_ROW_ALIGN-aligned) and counts survivors per (score, row) with atomicAdd: counts are
//    order-independent, so the atomics cannot change a result. A launch may cover a band of tile rows
//    (`first_tile_row`, the grid's height): the host launches one band per uploaded band of the image
//    while the rest is still being copied; every pixel is scored and kept exactly as by one launch.
// 2. clatch_scan_reduce / clatch_scan_partials / clatch_scan_apply: exclusive prefix sum of the counts,
//    laid out score-major with scores descending (index (255 - s) * height + y). The sum at (s, y) is the
//    number of survivors that sort before every survivor of score s in row y under
//    (score desc, y asc, x asc): its first output position. The grand total (all survivors) is written
//    to *total.
// 3. clatch_detect_scatter: one warp per row walks the kept map left to right, 32 pixels per step.
//    Survivors of equal score in a step are ranked by __match_any_sync + popc of the lower lanes, added
//    to the row's running offset for that score (kept in the scanned array itself, only ever touched by
//    the warp that owns the row). Positions below `capacity` get a keypoint record (angle still 0).
// 4. clatch_detect_orient: one warp per output keypoint, n = min(*total, capacity): integer moments over
//    the radius-15 disc (lane = dx, loop over dy), a shuffle reduction, then the bin by exact quadrant
//    turns and a binary search over the host's 720 half-bin directions with 64-bit cross products.
//    The pyramid skips it and orients only what its selection kept (clatch_orient_refine).
//
// clatch_orient_refine (after a pyramid's selection, for the kept keypoints of every level at once): one
// warp per keypoint, its orientation as step 4 and, with Subpixel::Score, the parabola through the FAST
// scores of the keypoint and its 4 neighbours, as src/detect/cpu.rs::subpixel_offset.
#include "clatch.h"

typedef long long i64;
typedef unsigned int u32;

#define TILE_X CLATCH_DETECT_TILE_X
#define TILE_Y CLATCH_DETECT_TILE_Y
// Image tile: the pixel tile, 1 pixel for the suppression's neighbours, 3 for the FAST circle.
#define IMAGE_W (TILE_X + 8)
#define IMAGE_H (TILE_Y + 8)
// Score tile: the pixel tile and its 8-neighbourhood border.
#define SCORE_W (TILE_X + 2)
#define SCORE_H (TILE_Y + 2)
#define RADIUS CLATCH_ORIENTATION_RADIUS
#define QUADRANT_BINS (CLATCH_ANGLE_BINS / 4)

// Nine contiguous set bits (circularly) in the 16-bit circle mask `m`?
__device__ __forceinline__ bool nine_in_a_row(unsigned m) {
    m |= m << 16;                  // unroll the circle: bit k + 16 = bit k
    unsigned r = m & (m >> 1);     // bit k: k, k+1 set
    r &= r >> 2;                   // k .. k+3
    r &= r >> 4;                   // k .. k+7
    r &= m >> 8;                   // k .. k+8
    return (r & 0xffffu) != 0u;
}

// The largest t >= lo such that nine contiguous circle differences are all >= t (sign = 1) or all
// <= -t (sign = -1), or 0 if there is none: max over k of min_{j<9} (sign * d[k+j]), when it is >= lo.
// A binary search over t with bit-mask tests instead of a min/max network: the score is decided by
// comparisons alone. Do not "simplify" this back: the obvious network (2-, 4-, 8-, 9-wide sliding
// minima) compiled to correct PTX (checked by simulating the PTX) but returned max(d) instead of
// max_k min9(d) on the H100 (driver 580.159, PTX JIT-compiled for sm_90); ptxas 13.0 turns that
// network into 3-input VIMNMX3 instructions for sm_90, the likely culprit.
__device__ __forceinline__ int arc_score(const int d[16], int sign, int lo) {
    unsigned mask = 0;
#pragma unroll
    for (int i = 0; i < 16; ++i) mask |= (unsigned)(sign * d[i] >= lo) << i;
    if (!nine_in_a_row(mask)) return 0;
    int yes = lo, no = 256;  // sign * d <= 255, so no arc reaches 256
    while (no - yes > 1) {
        const int t = (yes + no) >> 1;
        mask = 0;
#pragma unroll
        for (int i = 0; i < 16; ++i) mask |= (unsigned)(sign * d[i] >= t) << i;
        if (nine_in_a_row(mask))
            yes = t;
        else
            no = t;
    }
    return yes;
}

// FAST-9 score of tile pixel (cx, cy) (at least 3 from the tile's edges) if it is above `threshold`,
// else 0. Circle as detect::FAST_CIRCLE: clockwise from the top. The CPU's score is
// max(max_k min9(d), max_k min9(-d)); when it is above the threshold, the side that reaches it has an
// arc at threshold + 1 and arc_score finds its exact value, while the other side gives less or 0.
__device__ __forceinline__ int fast_score(const unsigned char (*tile)[IMAGE_W], int cx, int cy,
                                          int threshold) {
    const int p = tile[cy][cx];
    // Necessary condition (as the CPU's may_be_corner, which only skips work): nine contiguous circle
    // pixels always include two adjacent compass pixels beyond the threshold on the same side.
    const int c0 = tile[cy - 3][cx] - p, c4 = tile[cy][cx + 3] - p;
    const int c8 = tile[cy + 3][cx] - p, c12 = tile[cy][cx - 3] - p;
    const bool b0 = c0 > threshold, b4 = c4 > threshold, b8 = c8 > threshold, b12 = c12 > threshold;
    const bool k0 = -c0 > threshold, k4 = -c4 > threshold, k8 = -c8 > threshold,
               k12 = -c12 > threshold;
    const bool bright = (b0 && b4) || (b4 && b8) || (b8 && b12) || (b12 && b0);
    const bool dark = (k0 && k4) || (k4 && k8) || (k8 && k12) || (k12 && k0);
    if (!bright && !dark) return 0;
    int d[16];
    d[0] = c0;
    d[1] = tile[cy - 3][cx + 1] - p;
    d[2] = tile[cy - 2][cx + 2] - p;
    d[3] = tile[cy - 1][cx + 3] - p;
    d[4] = c4;
    d[5] = tile[cy + 1][cx + 3] - p;
    d[6] = tile[cy + 2][cx + 2] - p;
    d[7] = tile[cy + 3][cx + 1] - p;
    d[8] = c8;
    d[9] = tile[cy + 3][cx - 1] - p;
    d[10] = tile[cy + 2][cx - 2] - p;
    d[11] = tile[cy + 1][cx - 3] - p;
    d[12] = c12;
    d[13] = tile[cy - 1][cx - 3] - p;
    d[14] = tile[cy - 2][cx - 2] - p;
    d[15] = tile[cy - 3][cx - 1] - p;
    // Both sides cannot reach the threshold at once (nine of sixteen on each side would overlap), so
    // at most one of these is non-zero.
    const int brighter = bright ? arc_score(d, 1, threshold + 1) : 0;
    const int darker = dark ? arc_score(d, -1, threshold + 1) : 0;
    return brighter + darker;
}

extern "C" __global__ void __launch_bounds__(TILE_X * TILE_Y)
clatch_detect_nms(cudaTextureObject_t image, int width, int height, int margin, int threshold,
                  unsigned char* __restrict__ kept,  // pitch x height, pitch a multiple of 128
                  int pitch,
                  u32* __restrict__ counts,          // 255 x height, zeroed: [(255 - s) * height + y]
                  int first_tile_row)                // block row 0 is this tile row (bands of rows)
{
    __shared__ unsigned char tile[IMAGE_H][IMAGE_W];
    __shared__ unsigned char scores[SCORE_H][SCORE_W];

    const int tid = threadIdx.y * TILE_X + threadIdx.x;
    const int x0 = blockIdx.x * TILE_X, y0 = (blockIdx.y + first_tile_row) * TILE_Y;

    // Clamp addressing makes reads past the border safe; those pixels only feed scores outside the
    // margin, which are 0.
    for (int i = tid; i < IMAGE_W * IMAGE_H; i += TILE_X * TILE_Y) {
        const int ix = i % IMAGE_W, iy = i / IMAGE_W;
        tile[iy][ix] = tex2D<unsigned char>(image, (float)(x0 - 4 + ix) + 0.5f,
                                            (float)(y0 - 4 + iy) + 0.5f);
    }
    __syncthreads();

    for (int i = tid; i < SCORE_W * SCORE_H; i += TILE_X * TILE_Y) {
        const int sx = i % SCORE_W, sy = i / SCORE_W;
        const int gx = x0 - 1 + sx, gy = y0 - 1 + sy;
        int s = 0;
        if (gx >= margin && gx < width - margin && gy >= margin && gy < height - margin)
            s = fast_score(tile, sx + 3, sy + 3, threshold);
        scores[sy][sx] = (unsigned char)s;
    }
    __syncthreads();

    const int tx = threadIdx.x, ty = threadIdx.y;
    const int gx = x0 + tx, gy = y0 + ty;
    if (gy >= height) return;
    const int s = scores[ty + 1][tx + 1];
    // Raster-order ties: strictly above the row above and the left neighbour, at least the others.
    const bool keep = s > 0 && s > scores[ty][tx] && s > scores[ty][tx + 1] && s > scores[ty][tx + 2] &&
                      s > scores[ty + 1][tx] && s >= scores[ty + 1][tx + 2] &&
                      s >= scores[ty + 2][tx] && s >= scores[ty + 2][tx + 1] &&
                      s >= scores[ty + 2][tx + 2];
    kept[(size_t)gy * pitch + gx] = keep ? (unsigned char)s : 0;
    if (keep) atomicAdd(&counts[(size_t)(255 - s) * height + gy], 1u);
}

// Exclusive scan of one value per thread over the block; *total gets the block's sum. Every thread of
// the block must call it (it has barriers).
__device__ __forceinline__ u32 block_exclusive_scan(u32 value, u32* total) {
    __shared__ u32 warp_sums[32];
    const unsigned full = 0xffffffffu;
    const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, warps = blockDim.x >> 5;
    u32 inclusive = value;
#pragma unroll
    for (int o = 1; o < 32; o <<= 1) {
        const u32 n = __shfl_up_sync(full, inclusive, o);
        if (lane >= o) inclusive += n;
    }
    if (lane == 31) warp_sums[warp] = inclusive;
    __syncthreads();
    if (warp == 0) {
        u32 w = lane < warps ? warp_sums[lane] : 0;
#pragma unroll
        for (int o = 1; o < 32; o <<= 1) {
            const u32 n = __shfl_up_sync(full, w, o);
            if (lane >= o) w += n;
        }
        warp_sums[lane] = w;
    }
    __syncthreads();
    const u32 base = warp > 0 ? warp_sums[warp - 1] : 0;
    *total = warp_sums[warps - 1];
    __syncthreads();  // warp_sums is reused by the next call
    return base + inclusive - value;
}

#define SCAN_ITEMS (CLATCH_SCAN_CHUNK / CLATCH_SCAN_THREADS)

// partials[b] = the sum of counts[b * CHUNK .. (b + 1) * CHUNK).
extern "C" __global__ void __launch_bounds__(CLATCH_SCAN_THREADS)
clatch_scan_reduce(const u32* __restrict__ counts, u32 n, u32* __restrict__ partials) {
    const size_t base = (size_t)blockIdx.x * CLATCH_SCAN_CHUNK;
    u32 sum = 0;
#pragma unroll
    for (int k = 0; k < SCAN_ITEMS; ++k) {
        const size_t i = base + k * CLATCH_SCAN_THREADS + threadIdx.x;
        if (i < n) sum += counts[i];
    }
    u32 total;
    block_exclusive_scan(sum, &total);
    if (threadIdx.x == 0) partials[blockIdx.x] = total;
}

// One block: partials become their exclusive prefix sums; *total = the sum of all.
extern "C" __global__ void __launch_bounds__(CLATCH_SCAN_TOP_THREADS)
clatch_scan_partials(u32* __restrict__ partials, u32 blocks, u32* __restrict__ total) {
    u32 carry = 0;
    for (u32 start = 0; start < blocks; start += blockDim.x) {
        const u32 i = start + threadIdx.x;
        const u32 v = i < blocks ? partials[i] : 0;
        u32 sum;
        const u32 before = block_exclusive_scan(v, &sum);
        if (i < blocks) partials[i] = carry + before;
        carry += sum;
    }
    if (threadIdx.x == 0) *total = carry;
}

// Shared-memory index with one padding word per 32, so thread t reading its 16 consecutive items
// (stride 16) hits distinct banks.
#define PADDED(j) ((j) + ((j) >> 5))

// counts[b * CHUNK ..] become their exclusive prefix sums plus partials[b].
extern "C" __global__ void __launch_bounds__(CLATCH_SCAN_THREADS)
clatch_scan_apply(u32* __restrict__ counts, u32 n, const u32* __restrict__ partials) {
    __shared__ u32 buffer[PADDED(CLATCH_SCAN_CHUNK)];
    const size_t base = (size_t)blockIdx.x * CLATCH_SCAN_CHUNK;
#pragma unroll
    for (int k = 0; k < SCAN_ITEMS; ++k) {
        const int j = k * CLATCH_SCAN_THREADS + threadIdx.x;
        buffer[PADDED(j)] = base + j < n ? counts[base + j] : 0;
    }
    __syncthreads();
    u32 items[SCAN_ITEMS];
    u32 sum = 0;
#pragma unroll
    for (int k = 0; k < SCAN_ITEMS; ++k) {
        items[k] = buffer[PADDED(threadIdx.x * SCAN_ITEMS + k)];
        sum += items[k];
    }
    u32 total;
    u32 running = block_exclusive_scan(sum, &total) + partials[blockIdx.x];
#pragma unroll
    for (int k = 0; k < SCAN_ITEMS; ++k) {
        buffer[PADDED(threadIdx.x * SCAN_ITEMS + k)] = running;
        running += items[k];
    }
    __syncthreads();
#pragma unroll
    for (int k = 0; k < SCAN_ITEMS; ++k) {
        const int j = k * CLATCH_SCAN_THREADS + threadIdx.x;
        if (base + j < n) counts[base + j] = buffer[PADDED(j)];
    }
}

// Chunks of 128 pixels a warp loads before ranking them (independent loads in flight).
#define SCATTER_UNROLL 4

extern "C" __global__ void __launch_bounds__(CLATCH_DETECT_WARPS * 32)
clatch_detect_scatter(const unsigned char* __restrict__ kept, int pitch, int height, int margin,
                      u32* __restrict__ offsets,  // the scanned counts; used up as running offsets
                      u32 capacity, float size,
                      clatch_keypoint* __restrict__ out)  // capacity records
{
    const unsigned full = 0xffffffffu;
    const int lane = threadIdx.x & 31;
    // Only rows inside the margin can hold survivors. The whole warp shares `row`.
    const int row = margin + blockIdx.x * CLATCH_DETECT_WARPS + (threadIdx.x >> 5);
    if (row >= height - margin) return;
    const u32* line = (const u32*)(kept + (size_t)row * pitch);
    const int chunks = pitch / CLATCH_DETECT_ROW_ALIGN;
    const unsigned lower = (1u << lane) - 1u;
    for (int c0 = 0; c0 < chunks; c0 += SCATTER_UNROLL) {
        u32 words[SCATTER_UNROLL];
#pragma unroll
        for (int u = 0; u < SCATTER_UNROLL; ++u)
            words[u] = c0 + u < chunks ? line[(c0 + u) * 32 + lane] : 0u;
#pragma unroll
        for (int u = 0; u < SCATTER_UNROLL; ++u) {
            if (__ballot_sync(full, words[u] != 0u) == 0u) continue;  // the usual case: no survivor
#pragma unroll
            for (int j = 0; j < 4; ++j) {
                // Pixel 32j + lane of the chunk: byte (lane & 3) of lane 8j + lane / 4's word.
                const u32 word = __shfl_sync(full, words[u], 8 * j + (lane >> 2));
                const int s = (word >> (8 * (lane & 3))) & 255u;
                const unsigned present = __ballot_sync(full, s != 0);
                if (s != 0) {
                    const unsigned peers = __match_any_sync(present, s);
                    const int leader = __ffs(peers) - 1;
                    u32* slot = offsets + (size_t)(255 - s) * height + row;
                    u32 first = 0;
                    if (lane == leader) first = *slot;
                    first = __shfl_sync(present, first, leader);
                    const u32 position = first + __popc(peers & lower);
                    if (lane == leader) *slot = first + __popc(peers);
                    if (position < capacity) {
                        clatch_keypoint kp;
                        kp.x = (float)((c0 + u) * CLATCH_DETECT_ROW_ALIGN + 32 * j + lane);
                        kp.y = (float)row;
                        kp.size = size;
                        kp.angle = 0.0f;
                        kp.response = (float)s;
                        kp.octave = 0;
                        out[position] = kp;
                    }
                }
                __syncwarp();  // the leaders' slot updates are seen by the next step's leaders
            }
        }
    }
}

// The bin of the direction (dx, dy), as crate::angle::direction_bin: exact quarter turns into
// x > 0, y >= 0, then the number of half-bin directions b with b.x * y - b.y * x > 0 (binary search).
// |dx|, |dy| < 2^23 and |b| <= 2^30, so the products fit in 64 bits.
__device__ __forceinline__ int direction_bin(i64 dx, i64 dy, const i64* __restrict__ bounds) {
    if (dx == 0 && dy == 0) return 0;
    i64 x = dx, y = dy;
    int quadrant = 0;
    while (!(x > 0 && y >= 0)) {
        const i64 t = x;
        x = y;
        y = -t;
        ++quadrant;
    }
    int lo = 0, hi = QUADRANT_BINS;
    while (lo < hi) {
        const int mid = (lo + hi) >> 1;
        const i64 bx = bounds[2 * mid], by = bounds[2 * mid + 1];
        if (bx * y - by * x > 0)
            lo = mid + 1;
        else
            hi = mid;
    }
    return (quadrant * QUADRANT_BINS + lo) % CLATCH_ANGLE_BINS;
}

// The orientation bin of the keypoint at whole position (x, y) of `image`, in lane 0 (every lane of
// the warp calls it, for the shuffles; the other lanes get an unspecified value).
__device__ __forceinline__ int orientation_bin(cudaTextureObject_t image, int x, int y,
                                               const i64* __restrict__ bounds) {
    const unsigned full = 0xffffffffu;
    const int lane = threadIdx.x & 31;
    const int dx = lane - RADIUS;  // lane 31 reads nothing
    // |m10|, |m01| <= 15 * 255 * 709 < 2^22: 32-bit sums are exact.
    int m10 = 0, m01 = 0;
    if (lane < 2 * RADIUS + 1) {
        for (int dy = -RADIUS; dy <= RADIUS; ++dy) {
            if (dx * dx + dy * dy <= RADIUS * RADIUS) {
                const int v =
                    tex2D<unsigned char>(image, (float)(x + dx) + 0.5f, (float)(y + dy) + 0.5f);
                m10 += dx * v;
                m01 += dy * v;
            }
        }
    }
#pragma unroll
    for (int o = 16; o > 0; o >>= 1) {
        m10 += __shfl_xor_sync(full, m10, o);
        m01 += __shfl_xor_sync(full, m01, o);
    }
    return lane == 0 ? direction_bin(m10, m01, bounds) : 0;
}

// One warp per keypoint k < n of `out` (grid-stride): its angle, and with `bins` its bin too.
__device__ __forceinline__ void orient_keypoints(cudaTextureObject_t image, u32 n,
                                                 const i64* __restrict__ bounds,
                                                 clatch_keypoint* __restrict__ out,
                                                 int* __restrict__ bins) {
    const int lane = threadIdx.x & 31;
    const u32 stride = gridDim.x * CLATCH_DETECT_WARPS;
    for (u32 k = blockIdx.x * CLATCH_DETECT_WARPS + (threadIdx.x >> 5); k < n; k += stride) {
        const int bin = orientation_bin(image, (int)out[k].x, (int)out[k].y, bounds);
        if (lane == 0) {
            out[k].angle = (float)bin / (float)CLATCH_BINS_PER_DEGREE;
            if (bins != nullptr) bins[k] = bin;
        }
    }
}

extern "C" __global__ void __launch_bounds__(CLATCH_DETECT_WARPS * 32)
clatch_detect_orient(cudaTextureObject_t image, const u32* __restrict__ total, u32 capacity,
                     const i64* __restrict__ bounds,  // QUADRANT_BINS (x, y), 2.30 fixed point
                     clatch_keypoint* __restrict__ out) {
    orient_keypoints(image, min(*total, capacity), bounds, out, nullptr);
}

// Texel (x, y) of `image` (inside the image: callers check).
__device__ __forceinline__ int texel(cudaTextureObject_t image, int x, int y) {
    return tex2D<unsigned char>(image, (float)x + 0.5f, (float)y + 0.5f);
}

// The FAST-9 score of pixel (x, y) whatever its value, as crate::detect::cpu::fast_score (at or below
// any threshold, possibly negative): max(max_k min9(d), max_k min9(-d)), each side by arc_score from
// -255, where every arc qualifies (|d| <= 255). (x, y) must be at least 3 pixels from every border.
// Circle as detect::FAST_CIRCLE: clockwise from the top.
__device__ __forceinline__ int full_fast_score(cudaTextureObject_t image, int x, int y) {
    const int cx[16] = {0, 1, 2, 3, 3, 3, 2, 1, 0, -1, -2, -3, -3, -3, -2, -1};
    const int cy[16] = {-3, -3, -2, -1, 0, 1, 2, 3, 3, 3, 2, 1, 0, -1, -2, -3};
    const int p = texel(image, x, y);
    int d[16];
#pragma unroll
    for (int i = 0; i < 16; ++i) d[i] = texel(image, x + cx[i], y + cy[i]) - p;
    return max(arc_score(d, 1, -255), arc_score(d, -1, -255));
}

// As crate::detect::cpu::parabola_offset: the peak of the parabola through (-1, l), (0, c), (1, r) in
// 1/65536 pixel, (a - b) 2^15 / (a + b) with a = c - l, b = c - r, rounded half away from zero by
// integer division; 0 unless c > l and c > r. |values| < 2^26: 32-bit arithmetic is exact.
__device__ __forceinline__ int parabola_offset(int l, int c, int r) {
    if (c <= l || c <= r) return 0;
    const int a = c - l, b = c - r;
    const int numerator = (a - b) * (1 << (CLATCH_SUBPIXEL_FRAC_BITS - 1));
    const int denominator = a + b;
    const int magnitude = (2 * abs(numerator) + denominator) / (2 * denominator);
    return numerator < 0 ? -magnitude : magnitude;
}

// Every selected keypoint of every level of a pyramid in one launch: the pyramid orients and refines
// only what its selection kept, as src/pyramid/cpu.rs. One warp per keypoint k < levels.starts[count]
// (grid-stride), on its level. Its angle goes into its record (the describe kernel reads it) and its
// bin into bins[k] (for the host), as crate::detect::cpu::orientation. With `offsets` (else null), lanes
// 0..4 then score the keypoint and its left, right, upper and lower neighbours side by side and lane 0
// writes offsets[2k], offsets[2k + 1], the sub-pixel offset (dx, dy) as
// crate::detect::cpu::subpixel_offset: 0 for both when a neighbour's circle would leave the image.
extern "C" __global__ void __launch_bounds__(CLATCH_DETECT_WARPS * 32)
clatch_orient_refine(const __grid_constant__ clatch_levels levels,
                     const i64* __restrict__ bounds,  // QUADRANT_BINS (x, y), 2.30 fixed point
                     clatch_keypoint* __restrict__ keypoints, int* __restrict__ bins,
                     int* __restrict__ offsets) {
    const unsigned full = 0xffffffffu;
    const int lane = threadIdx.x & 31;
    const u32 n = levels.starts[levels.count];
    const u32 stride = gridDim.x * CLATCH_DETECT_WARPS;
    for (u32 k = blockIdx.x * CLATCH_DETECT_WARPS + (threadIdx.x >> 5); k < n; k += stride) {
        // The keypoint's level: the last whose first record is at or before k (empty levels skipped).
        int l = 0;
        while (l + 1 < levels.count && levels.starts[l + 1] <= k) ++l;
        const cudaTextureObject_t image = levels.textures[l];
        const int x = (int)keypoints[k].x, y = (int)keypoints[k].y;
        const int bin = orientation_bin(image, x, y, bounds);
        if (lane == 0) {
            keypoints[k].angle = (float)bin / (float)CLATCH_BINS_PER_DEGREE;
            bins[k] = bin;
        }
        if (offsets == nullptr) continue;
        const int width = levels.widths[l], height = levels.heights[l];
        const bool inside = x >= 4 && y >= 4 && x + 4 < width && y + 4 < height;
        // Lane j scores (x, y) + step[j]: centre, left, right, up, down.
        const int step_x[5] = {0, -1, 1, 0, 0}, step_y[5] = {0, 0, 0, -1, 1};
        int score = 0;
        if (inside && lane < 5) score = full_fast_score(image, x + step_x[lane], y + step_y[lane]);
        const int c = __shfl_sync(full, score, 0);
        const int left = __shfl_sync(full, score, 1);
        const int right = __shfl_sync(full, score, 2);
        const int up = __shfl_sync(full, score, 3);
        const int down = __shfl_sync(full, score, 4);
        if (lane == 0) {
            offsets[2 * (size_t)k] = inside ? parabola_offset(left, c, right) : 0;
            offsets[2 * (size_t)k + 1] = inside ? parabola_offset(up, c, down) : 0;
        }
    }
}
