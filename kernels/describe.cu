// CLATCH description on the GPU. Reproduces src/describe/cpu/ bit for bit (docs/numerics.md, section 4).
//
// Two kernels with one signature; the host picks one by the patch weights:
// - clatch_describe (any weights): one block of CLATCH_DESCRIBE_WARPS warps describes keypoints
//   blockIdx.x, blockIdx.x + gridDim.x, ...; all threads sample the 64x64 window through the texture unit
//   (point filtering, integer reads, clamp addressing; the bilinear weights are our own integers, never the
//   texture unit's) into one of two shared-memory windows, so sampling keypoint i+1 overlaps with warps still
//   comparing keypoint i; warp w computes descriptor word w (triplets 64w .. 64w+63), four triplets at a
//   time: lanes 8g..8g+7 take triplet 4j+g, lane 8g+r sums row r of its three 8x8 patches, a 3-step shuffle
//   butterfly adds the eight rows, and one ballot collects the four signs.
// - clatch_describe_binary (every weight 0 or 1, e.g. the default 7x7 mask): the same sampling, but the
//   window is kept as bytes and each lane computes whole triplets with dp4a, using
//   SSD(a,b) - SSD(c,b) = sum w a^2 - sum w c^2 - 2 (sum (w b) a - sum (w b) c), where w x is x & mask.
//   Exact integer arithmetic either way, so both give the same bits.
#include "clatch.h"

typedef long long i64;
typedef unsigned long long u64;

// Int window rows are 65 ints apart. In one step the lanes of a warp read, for a fixed column s, rows
// y_g + r (r = 0..7) of four patches g: with a row stride of 65 = 1 (mod 32) the bank is
// (y_g + r + x_g + s) mod 32, so the eight lanes of a patch always hit eight distinct, consecutive banks
// (a stride of 64 would put all eight in one bank). Lanes of different patches may still meet.
#define WINDOW_STRIDE (CLATCH_WINDOW + 1)

// Byte windows: four copies, copy k holding at byte j the sample of column j + k, so the 8 bytes of any
// patch row (column x) are the two aligned words at byte x - (x & 3) of copy x & 3. Rows are 68 bytes =
// 17 words apart: 17 is odd, so the rows of one patch (consecutive) fall in distinct banks.
#define BYTE_STRIDE 68
#define BYTE_COPY (CLATCH_WINDOW * BYTE_STRIDE)

__device__ __forceinline__ int angle_bin(float angle) {
    double reduced = fmod((double)angle, 360.0);
    if (reduced < 0.0) reduced += 360.0;
    return (int)(__double2ll_rn(reduced * (double)CLATCH_BINS_PER_DEGREE) % CLATCH_ANGLE_BINS);
}

// The keypoint's sampling frame: the 16.16 origin split into whole pixels (ix, iy) and 16-bit fractions
// (lx, ly), and the 16.16 step along window rows (ux, uy; the step down window columns is (-uy, ux)).
// Every sample offset fits in 32 bits (|32 * step| < 2^26 for sizes up to 1024), and
// floor((65536 ix + l + off) / 256) = 256 ix + floor((l + off) / 256), so the inner loop needs no 64-bit
// arithmetic yet gives exactly the CPU's 64-bit positions.
struct Frame {
    int ix, iy, lx, ly, ux, uy;
};

__device__ __forceinline__ Frame frame_of(const clatch_keypoint& kp, const int2* __restrict__ rotation) {
    const int2 cs = rotation[angle_bin(kp.angle)];
    const i64 q = __float2ll_rn(kp.size * 256.0f);
    const i64 ox = __float2ll_rn(kp.x * 65536.0f);
    const i64 oy = __float2ll_rn(kp.y * 65536.0f);
    Frame f;
    f.ux = (int)((q * cs.x + (1 << 13)) >> 14);
    f.uy = (int)((q * cs.y + (1 << 13)) >> 14);
    f.ix = (int)(ox >> 16);
    f.iy = (int)(oy >> 16);
    f.lx = (int)(ox & 0xffff);
    f.ly = (int)(oy & 0xffff);
    return f;
}

// Window sample (u, v): the bilinear value of docs/numerics.md, section 4, steps 2 and 4. The four
// neighbours come from one texel of the quad texture (clatch_build_quads): one fetch instead of four.
__device__ __forceinline__ int sample(cudaTextureObject_t quads, const Frame& f, int u, int v) {
    const int du = u - CLATCH_WINDOW / 2;
    const int dv = v - CLATCH_WINDOW / 2;
    const int rx = (f.lx + du * f.ux - dv * f.uy + 128) >> 8;  // 24.8, relative to 256 ix
    const int ry = (f.ly + du * f.uy + dv * f.ux + 128) >> 8;
    const int x0 = f.ix + (rx >> 8), y0 = f.iy + (ry >> 8);
    const int fx = rx & 255, fy = ry & 255;
    const uchar4 q = tex2D<uchar4>(quads, x0 + 1.5f, y0 + 1.5f);
    const int upper = q.x * (256 - fx) + q.y * fx;
    const int lower = q.z * (256 - fx) + q.w * fx;
    return (upper * (256 - fy) + lower * fy + (1 << 15)) >> 16;
}

// The quad texture of an image: texel (X, Y), X in [0, width], Y in [0, height], holds the pixels
// (X - 1, Y - 1), (X, Y - 1), (X - 1, Y), (X, Y), each coordinate clamped to the image, so the four
// bilinear neighbours of pixel (x0, y0) are one texel, at (x0 + 1, y0 + 1). With clamp addressing on this
// (width + 1) x (height + 1) texture, a read past an edge gets the edge pixel for both neighbours, exactly
// what four clamped reads of the image give (x0 < 0: pixel 0 twice; x0 >= width - 1: pixel width - 1
// twice), so the samples are unchanged to the bit. quad_pitch: texels per row of `quads`.
extern "C" __global__ void clatch_build_quads(const unsigned char* __restrict__ pixels, int pitch, int width,
                                              int height, uchar4* __restrict__ quads, int quad_pitch) {
    const int X = blockIdx.x * blockDim.x + threadIdx.x;
    const int Y = blockIdx.y * blockDim.y + threadIdx.y;
    if (X > width || Y > height) return;
    const int xa = max(X - 1, 0), xb = min(X, width - 1);
    const int ya = max(Y - 1, 0), yb = min(Y, height - 1);
    uchar4 q;
    q.x = pixels[(size_t)ya * pitch + xa];
    q.y = pixels[(size_t)ya * pitch + xb];
    q.z = pixels[(size_t)yb * pitch + xa];
    q.w = pixels[(size_t)yb * pitch + xb];
    quads[(size_t)Y * quad_pitch + X] = q;
}

// Smoothing before description: reproduces src/describe/cpu/smooth.rs::smooth bit for bit
// (docs/numerics.md, section 4, step 0). With the binomial taps k of radius R ([1 2 1] or [1 4 6 4 1]),
// dst(x, y) = (sum_{i,j} k[i] k[j] src(clamp(x + j - R), clamp(y + i - R)) + 2^(4R - 1)) >> 4R: exact
// integer sums (below 2^16), one rounding. A block of CLATCH_SMOOTH_TILE_X x CLATCH_SMOOTH_TILE_Y threads
// loads its tile and an R-pixel apron (coordinates clamped to the image, which is the border rule) into
// shared memory, sums each apron column over 2R + 1 rows, then each output pixel over 2R + 1 column sums.
__device__ __forceinline__ constexpr unsigned int binomial_tap(int radius, int k) {
    return radius == 1 ? (k == 1 ? 2u : 1u) : (k == 2 ? 6u : ((k & 1) ? 4u : 1u));
}

template <int R>
__device__ __forceinline__ void smooth_tile(const unsigned char* __restrict__ src, int src_pitch, int width,
                                            int height, unsigned char* __restrict__ dst, int dst_pitch) {
    constexpr int TX = CLATCH_SMOOTH_TILE_X, TY = CLATCH_SMOOTH_TILE_Y;
    constexpr int AW = TX + 2 * R, AH = TY + 2 * R;  // the tile with its apron
    __shared__ unsigned char tile[AH][AW];
    __shared__ unsigned int columns[TY][AW];
    const int left = (int)blockIdx.x * TX - R, top = (int)blockIdx.y * TY - R;
    const int t = threadIdx.y * TX + threadIdx.x;
    for (int i = t; i < AW * AH; i += TX * TY) {
        const int ax = i % AW, ay = i / AW;
        const int sx = min(max(left + ax, 0), width - 1);
        const int sy = min(max(top + ay, 0), height - 1);
        tile[ay][ax] = src[(size_t)sy * src_pitch + sx];
    }
    __syncthreads();
    for (int i = t; i < AW * TY; i += TX * TY) {
        const int ax = i % AW, ty = i / AW;
        unsigned int sum = 0;
#pragma unroll
        for (int k = 0; k <= 2 * R; ++k) sum += binomial_tap(R, k) * tile[ty + k][ax];
        columns[ty][ax] = sum;
    }
    __syncthreads();
    const int x = (int)blockIdx.x * TX + threadIdx.x, y = (int)blockIdx.y * TY + threadIdx.y;
    if (x >= width || y >= height) return;
    unsigned int sum = 0;
#pragma unroll
    for (int k = 0; k <= 2 * R; ++k) sum += binomial_tap(R, k) * columns[threadIdx.y][threadIdx.x + k];
    dst[(size_t)y * dst_pitch + x] = (unsigned char)((sum + (1u << (4 * R - 1))) >> (4 * R));
}

// Smoothing::Binomial3: [1 2 1] on both axes.
extern "C" __global__ void clatch_smooth_binomial3(const unsigned char* __restrict__ src, int src_pitch,
                                                   int width, int height, unsigned char* __restrict__ dst,
                                                   int dst_pitch) {
    smooth_tile<1>(src, src_pitch, width, height, dst, dst_pitch);
}

// Smoothing::Binomial5: [1 4 6 4 1] on both axes.
extern "C" __global__ void clatch_smooth_binomial5(const unsigned char* __restrict__ src, int src_pitch,
                                                   int width, int height, unsigned char* __restrict__ dst,
                                                   int dst_pitch) {
    smooth_tile<2>(src, src_pitch, width, height, dst, dst_pitch);
}

// The count may come from a kernel queued earlier on the same stream (GPU detection), so it is read on
// the device rather than passed by the host: no round trip between detection and description.
__device__ __forceinline__ int keypoint_count(const unsigned int* __restrict__ total, int capacity) {
    return (int)min(*total, (unsigned int)capacity);
}

#define DESCRIBE_PARAMS                                                                                    \
    cudaTextureObject_t image, /* the quad texture of clatch_build_quads */                               \
        int width, int height,                                                                             \
        const clatch_keypoint* __restrict__ keypoints, /* capacity records */                             \
        const unsigned int* __restrict__ total,        /* keypoints available (e.g. detection's count) */ \
        int capacity,                                                                                      \
        const int2* __restrict__ rotation,         /* CLATCH_ANGLE_BINS (cos, sin), 16 fraction bits */   \
        const unsigned char* __restrict__ triplets, /* CLATCH_TRIPLETS x 6 window coordinates */          \
        const int* __restrict__ weights,            /* 8x8, row-major */                                  \
        int bits,                                   /* 8..512, a multiple of 8 */                         \
        u64* __restrict__ out                       /* capacity x ceil(bits / 64) words */

extern "C" __global__ void __launch_bounds__(CLATCH_DESCRIBE_WARPS * 32) clatch_describe(DESCRIBE_PARAMS) {
    const int count = keypoint_count(total, capacity);
    __shared__ int window[2][CLATCH_WINDOW * WINDOW_STRIDE];

    const unsigned full = 0xffffffffu;
    const int lane = threadIdx.x & 31;
    const int warp = threadIdx.x >> 5;
    const int group = lane >> 3;  // which of the four triplets of a step
    const int row = lane & 7;     // which patch row this lane sums
    const int words = (bits + 63) >> 6;

    int w[CLATCH_PATCH];
#pragma unroll
    for (int s = 0; s < CLATCH_PATCH; ++s) w[s] = weights[row * CLATCH_PATCH + s];

    // Steps of four triplets in this warp's word; bits is a multiple of 8, so every step is whole.
    const int first = warp * 64;
    const int steps = max(0, min(16, (bits - first) >> 2));

    int buffer = 0;
    for (int k = blockIdx.x; k < count; k += gridDim.x, buffer ^= 1) {
        const Frame f = frame_of(keypoints[k], rotation);
        int* win = window[buffer];
        for (int i = threadIdx.x; i < CLATCH_WINDOW * CLATCH_WINDOW; i += blockDim.x) {
            const int u = i & (CLATCH_WINDOW - 1), v = i >> 6;
            win[v * WINDOW_STRIDE + u] = sample(image, f, u, v);
        }
        // One barrier per keypoint is enough: the next keypoint writes the other window, and the one
        // after it cannot start before every warp has passed the next barrier, i.e. finished reading.
        __syncthreads();

        u64 word = 0;
        for (int j = 0; j < steps; ++j) {
            const unsigned char* t = triplets + 6 * (first + 4 * j + group);
            const int* a = win + (t[1] + row) * WINDOW_STRIDE + t[0];
            const int* b = win + (t[3] + row) * WINDOW_STRIDE + t[2];
            const int* c = win + (t[5] + row) * WINDOW_STRIDE + t[4];
            int d = 0;
#pragma unroll
            for (int s = 0; s < CLATCH_PATCH; ++s) {
                const int da = a[s] - b[s];
                const int dc = c[s] - b[s];
                d += w[s] * (da * da - dc * dc);
            }
            d += __shfl_xor_sync(full, d, 1);
            d += __shfl_xor_sync(full, d, 2);
            d += __shfl_xor_sync(full, d, 4);
            const unsigned negative = __ballot_sync(full, d < 0);
            const unsigned nibble = (negative & 1u) | ((negative >> 7) & 2u) | ((negative >> 14) & 4u) |
                                    ((negative >> 21) & 8u);
            word |= (u64)nibble << (4 * j);
        }
        if (lane == 0 && warp < words) out[(size_t)k * words + warp] = word;
    }
}

// The 8 bytes of the patch row at window column x, row y, as two words (little-endian: byte i = column
// x + i). Both loads are 4-byte aligned (copy offsets, row strides and x - copy are multiples of 4).
__device__ __forceinline__ uint2 patch_row(const unsigned char* win, int x, int y) {
    const int copy = x & 3;
    const unsigned* p = reinterpret_cast<const unsigned*>(win + copy * BYTE_COPY + y * BYTE_STRIDE + (x - copy));
    return make_uint2(p[0], p[1]);
}

extern "C" __global__ void __launch_bounds__(CLATCH_DESCRIBE_WARPS * 32)
    clatch_describe_binary(DESCRIBE_PARAMS) {
    const int count = keypoint_count(total, capacity);
    __shared__ __align__(16) unsigned char window[2][4 * BYTE_COPY];

    const int lane = threadIdx.x & 31;
    const int warp = threadIdx.x >> 5;
    const int words = (bits + 63) >> 6;

    // Byte masks of the weights (0 or 1): row r, bytes 0..3 and 4..7.
    unsigned mask[CLATCH_PATCH][2];
#pragma unroll
    for (int r = 0; r < CLATCH_PATCH; ++r) {
#pragma unroll
        for (int h = 0; h < 2; ++h) {
            unsigned m = 0;
#pragma unroll
            for (int i = 0; i < 4; ++i) m |= (weights[r * CLATCH_PATCH + 4 * h + i] ? 0xffu : 0u) << (8 * i);
            mask[r][h] = m;
        }
    }

    const int first = warp * 64;  // this warp's word: lane l takes triplets first + l and first + 32 + l
    int buffer = 0;
    for (int k = blockIdx.x; k < count; k += gridDim.x, buffer ^= 1) {
        const Frame f = frame_of(keypoints[k], rotation);
        unsigned char* win = window[buffer];
        for (int i = threadIdx.x; i < CLATCH_WINDOW * CLATCH_WINDOW; i += blockDim.x) {
            const int u = i & (CLATCH_WINDOW - 1), v = i >> 6;
            const unsigned char s = (unsigned char)sample(image, f, u, v);
#pragma unroll
            for (int copy = 0; copy < 4; ++copy) {
                if (u >= copy) win[copy * BYTE_COPY + v * BYTE_STRIDE + u - copy] = s;
            }
        }
        __syncthreads();  // as in clatch_describe: one barrier per keypoint with two windows

        if (warp < words) {  // warp-uniform
            unsigned half[2];
#pragma unroll
            for (int h = 0; h < 2; ++h) {
                const unsigned char* t = triplets + 6 * (first + 32 * h + lane);
                const int ax = t[0], ay = t[1], bx = t[2], by = t[3], cx = t[4], cy = t[5];
                unsigned ea = 0, ec = 0, xa = 0, xc = 0;
#pragma unroll
                for (int r = 0; r < CLATCH_PATCH; ++r) {
                    const uint2 a = patch_row(win, ax, ay + r);
                    const uint2 b = patch_row(win, bx, by + r);
                    const uint2 c = patch_row(win, cx, cy + r);
                    const unsigned bm0 = b.x & mask[r][0], bm1 = b.y & mask[r][1];
                    ea = __dp4a(a.x & mask[r][0], a.x, ea);
                    ea = __dp4a(a.y & mask[r][1], a.y, ea);
                    ec = __dp4a(c.x & mask[r][0], c.x, ec);
                    ec = __dp4a(c.y & mask[r][1], c.y, ec);
                    xa = __dp4a(bm0, a.x, xa);
                    xa = __dp4a(bm1, a.y, xa);
                    xc = __dp4a(bm0, c.x, xc);
                    xc = __dp4a(bm1, c.y, xc);
                }
                const int d = (int)ea - (int)ec - 2 * ((int)xa - (int)xc);
                half[h] = __ballot_sync(0xffffffffu, d < 0);
            }
            // Triplets past the width are computed (the table has all 512) but masked off here.
            const int valid = bits - first;
            u64 word = (u64)half[0] | ((u64)half[1] << 32);
            if (valid < 64) word &= (1ull << valid) - 1;
            if (lane == 0) out[(size_t)k * words + warp] = word;
        }
    }
}

// Descriptor rows put in another order: dst row r = src row source_row[r], for r < rows (rows of
// `words` words). A pyramid's descriptors come out level by level; src/cuda/pyramid/ gathers them
// into the reported keypoint order straight into a device-resident collection (no host round trip),
// the order crate::pyramid::assemble gives on the host. A copy: no bit is computed here.
extern "C" __global__ void __launch_bounds__(CLATCH_GATHER_THREADS)
    clatch_gather_rows(const u64* __restrict__ src, const int* __restrict__ source_row, int rows, int words,
                       u64* __restrict__ dst) {
    const long long total = (long long)rows * words;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < total;
         i += (long long)gridDim.x * blockDim.x) {
        const long long r = i / words, w = i - r * words;
        dst[i] = src[(long long)source_row[r] * words + w];
    }
}
