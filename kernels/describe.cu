// CLATCH description on the GPU. Reproduces src/describe/cpu.rs bit for bit (docs/numerics.md, section 4).
//
// One block of CLATCH_DESCRIBE_WARPS warps describes keypoints blockIdx.x, blockIdx.x + gridDim.x, ...:
// - all threads sample the 64x64 window through the texture unit (point filtering, integer reads,
//   clamp addressing; the bilinear weights are our own integers, never the texture unit's) into one of two
//   shared-memory windows, so sampling keypoint i+1 overlaps with warps still comparing keypoint i;
// - warp w computes descriptor word w (triplets 64w .. 64w+63), four triplets at a time: lanes 8g..8g+7
//   take triplet 4j+g, lane 8g+r sums row r of its three 8x8 patches, a 3-step shuffle butterfly adds the
//   eight rows, and one ballot collects the four signs.
#include "clatch.h"

typedef long long i64;
typedef unsigned long long u64;

// Window rows are 65 ints apart. In one step the lanes of a warp read, for a fixed column s, rows
// y_g + r (r = 0..7) of four patches g: with a row stride of 65 = 1 (mod 32) the bank is
// (y_g + r + x_g + s) mod 32, so the eight lanes of a patch always hit eight distinct, consecutive banks
// (a stride of 64 would put all eight in one bank). Lanes of different patches may still meet.
#define WINDOW_STRIDE (CLATCH_WINDOW + 1)

__device__ __forceinline__ int angle_bin(float angle) {
    double reduced = fmod((double)angle, 360.0);
    if (reduced < 0.0) reduced += 360.0;
    return (int)(__double2ll_rn(reduced * (double)CLATCH_BINS_PER_DEGREE) % CLATCH_ANGLE_BINS);
}

extern "C" __global__ void __launch_bounds__(CLATCH_DESCRIBE_WARPS * 32)
clatch_describe(cudaTextureObject_t image, int width, int height,
                const clatch_keypoint* __restrict__ keypoints,
                const unsigned int* __restrict__ total,     // keypoints available (e.g. detection's count)
                int capacity,                               // records in `keypoints` (and rows of `out`)
                const int2* __restrict__ rotation,         // CLATCH_ANGLE_BINS (cos, sin), 16 fraction bits
                const unsigned char* __restrict__ triplets, // CLATCH_TRIPLETS x 6 window coordinates
                const int* __restrict__ weights,            // 8x8, row-major
                int bits,                                   // 8..512, a multiple of 8
                u64* __restrict__ out)                      // capacity x ceil(bits / 64) words
{
    // The count may come from a kernel queued earlier on the same stream (GPU detection), so it is read
    // here rather than passed by the host: no round trip between detection and description.
    const int count = min((int)min(*total, (unsigned int)capacity), capacity);
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
        const clatch_keypoint kp = keypoints[k];
        const int2 cs = rotation[angle_bin(kp.angle)];
        const i64 q = __float2ll_rn(kp.size * 256.0f);
        const i64 ux = (q * cs.x + (1 << 13)) >> 14;
        const i64 uy = (q * cs.y + (1 << 13)) >> 14;
        const i64 ox = __float2ll_rn(kp.x * 65536.0f);
        const i64 oy = __float2ll_rn(kp.y * 65536.0f);

        int* win = window[buffer];
        for (int i = threadIdx.x; i < CLATCH_WINDOW * CLATCH_WINDOW; i += blockDim.x) {
            const int u = i & (CLATCH_WINDOW - 1);
            const int v = i >> 6;
            const i64 du = u - CLATCH_WINDOW / 2;
            const i64 dv = v - CLATCH_WINDOW / 2;
            const i64 px = (ox + du * ux - dv * uy + 128) >> 8;
            const i64 py = (oy + du * uy + dv * ux + 128) >> 8;
            const int x0 = (int)(px >> 8), y0 = (int)(py >> 8);
            const int fx = (int)(px & 255), fy = (int)(py & 255);
            const int x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
            const int p00 = tex2D<unsigned char>(image, x0 + 0.5f, y0 + 0.5f);
            const int p01 = tex2D<unsigned char>(image, x1 + 0.5f, y0 + 0.5f);
            const int p10 = tex2D<unsigned char>(image, x0 + 0.5f, y1 + 0.5f);
            const int p11 = tex2D<unsigned char>(image, x1 + 0.5f, y1 + 0.5f);
            const int upper = p00 * (256 - fx) + p01 * fx;
            const int lower = p10 * (256 - fx) + p11 * fx;
            win[v * WINDOW_STRIDE + u] = (upper * (256 - fy) + lower * fy + (1 << 15)) >> 16;
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
