// OpenCV-compatible LATCH on the GPU. Reproduces src/describe/opencv/cpu.rs bit for bit (the numeric
// contract is in src/describe/opencv/mod.rs).
//
// The host does every step where a float or a rule could decide a bit differently: it blurs the image
// with the CPU's fixed-point blur, applies the border rule, and computes each keypoint's rounded position
// and cos/sin (f64 cos/sin rounded to f32: no device transcendental). This kernel rotates the patch
// centres with single correctly rounded f32 operations (explicit __fmul_rn/__fsub_rn/__fadd_rn: no FMA,
// whatever the flags) and compares integer SSDs.
//
// One warp per 32 triplets of one keypoint: lane l takes triplet 32 * chunk + l, reads its three
// (2h + 1)^2 patches from global memory through the read-only cache (lanes of a warp share the image
// neighbourhood of one keypoint), and one ballot gives the 32 bits, which lane 0 writes as one word.
#include "clatch.h"

__device__ __forceinline__ int clamp_offset(int v) {
    return max(-CLATCH_OPENCV_MAX_OFFSET, min(CLATCH_OPENCV_MAX_OFFSET, v));
}

extern "C" __global__ void __launch_bounds__(CLATCH_OPENCV_THREADS) clatch_describe_opencv(
    const unsigned char* __restrict__ image, int stride,           // the (blurred) image, row pitch
    const clatch_opencv_placement* __restrict__ placements, int count,  // keypoints that passed the rule
    const unsigned char* __restrict__ triplets,  // CLATCH_TRIPLETS x 6 window corners (centre + 28)
    int half,                                    // half_ssd_size: patches are (2 half + 1)^2
    int bits,                                    // 8 * bytes
    unsigned int* __restrict__ out               // count x ceil(bits / 32) words, triplet t at bit t % 32
) {
    const int lane = threadIdx.x & 31;
    const long long warp = ((long long)blockIdx.x * blockDim.x + threadIdx.x) >> 5;
    const int chunks = (bits + 31) >> 5;
    const long long k = warp / chunks;
    if (k >= count) return;  // the whole warp: no lane of a live warp leaves before the ballot
    const int chunk = (int)(warp - k * chunks);
    const int t = chunk * 32 + lane;

    bool bit = false;
    if (t < bits) {
        const clatch_opencv_placement p = placements[k];
        const unsigned char* row = triplets + 6 * t;
        int cx[3], cy[3];
#pragma unroll
        for (int i = 0; i < 3; ++i) {
            const float x = (float)(row[2 * i] - CLATCH_OPENCV_WINDOW_TO_CENTRE);
            const float y = (float)(row[2 * i + 1] - CLATCH_OPENCV_WINDOW_TO_CENTRE);
            // (int) of a float truncates toward zero, as in C; without rotation cos = 1, sin = 0 give
            // back x and y exactly.
            cx[i] = p.x + clamp_offset(__float2int_rz(__fsub_rn(__fmul_rn(x, p.cos), __fmul_rn(y, p.sin))));
            cy[i] = p.y + clamp_offset(__float2int_rz(__fadd_rn(__fmul_rn(x, p.sin), __fmul_rn(y, p.cos))));
        }
        int sum_a = 0, sum_c = 0;
        for (int dy = -half; dy <= half; ++dy) {
            const unsigned char* ra = image + (size_t)(cy[0] + dy) * stride + cx[0];
            const unsigned char* rb = image + (size_t)(cy[1] + dy) * stride + cx[1];
            const unsigned char* rc = image + (size_t)(cy[2] + dy) * stride + cx[2];
            for (int dx = -half; dx <= half; ++dx) {
                const int b = __ldg(rb + dx);
                const int da = (int)__ldg(ra + dx) - b;
                const int dc = (int)__ldg(rc + dx) - b;
                sum_a += da * da;
                sum_c += dc * dc;
            }
        }
        bit = sum_a < sum_c;
    }
    const unsigned word = __ballot_sync(0xffffffffu, bit);
    if (lane == 0) out[k * chunks + chunk] = word;
}
