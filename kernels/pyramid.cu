// Pyramid levels on the GPU. Reproduces src/pyramid/cpu.rs::downscale bit for bit (docs/numerics.md,
// section 6): one thread per output pixel, integer arithmetic only.
#include "clatch.h"

typedef long long i64;

// Where output coordinate `i` reads the previous level: lower neighbour, upper neighbour (clamped to
// the last pixel) and the upper one's 8-bit weight. Source position ((2i + 1) step - 2^16) >> 1
// (16.16; >> on a non-negative value), then the 24.8 rounding of description.
__device__ __forceinline__ void tap(int i, int source, i64 step, int* low, int* high, int* weight) {
    const i64 p = ((2 * (i64)i + 1) * step - (1 << CLATCH_PYRAMID_STEP_FRAC_BITS)) >> 1;
    const int p8 = (int)((p + 128) >> 8);
    *low = p8 >> 8;
    *high = min(*low + 1, source - 1);
    *weight = p8 & 255;
}

// dst (dst_width x dst_height, rows dst_pitch bytes apart) = the bilinear downscale of src by the 16.16
// factor `step` (2^16 < step <= 2^17).
extern "C" __global__ void clatch_downscale(const unsigned char* __restrict__ src, int src_pitch,
                                            int src_width, int src_height,
                                            unsigned char* __restrict__ dst, int dst_pitch,
                                            int dst_width, int dst_height, i64 step) {
    const int x = blockIdx.x * blockDim.x + threadIdx.x;
    const int y = blockIdx.y * blockDim.y + threadIdx.y;
    if (x >= dst_width || y >= dst_height) return;
    int x0, x1, fx, y0, y1, fy;
    tap(x, src_width, step, &x0, &x1, &fx);
    tap(y, src_height, step, &y0, &y1, &fy);
    const unsigned char* top = src + (size_t)y0 * src_pitch;
    const unsigned char* bottom = src + (size_t)y1 * src_pitch;
    const int upper = top[x0] * (256 - fx) + top[x1] * fx;
    const int lower = bottom[x0] * (256 - fx) + bottom[x1] * fx;
    dst[(size_t)y * dst_pitch + x] = (unsigned char)((upper * (256 - fy) + lower * fy + (1 << 15)) >> 16);
}
