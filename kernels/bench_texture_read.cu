// Diagnostic kernel, compiled and loaded only with the `internals` feature (the GPU test suites), never
// by the library itself.
#include "clatch.h"

// Diagnostics: every texel as the detector's texture reads return it (row-major width x height).
extern "C" __global__ void clatch_debug_read_texture(cudaTextureObject_t image, int width, int height,
                                                     unsigned char* __restrict__ out) {
    const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y;
    if (x < width && y < height)
        out[(size_t)y * width + x] = tex2D<unsigned char>(image, (float)x + 0.5f, (float)y + 0.5f);
}
