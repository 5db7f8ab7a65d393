// The one tensor-core instruction of the int8 kNN (sm_80 and later), shared by matching_tensor.cu and the
// rate probe of bench_mma_rate.cu.
#pragma once

// acc += A (16 x 32, row-major) * B (32 x 8, column-major), signed bytes, int32 accumulators.
__device__ __forceinline__ void mma_s8(int (&acc)[4], const unsigned (&a)[4], unsigned b0, unsigned b1) {
    asm volatile(
        "mma.sync.aligned.m16n8k32.row.col.s32.s8.s8.s32 {%0, %1, %2, %3}, {%4, %5, %6, %7}, {%8, %9}, "
        "{%0, %1, %2, %3};"
        : "+r"(acc[0]), "+r"(acc[1]), "+r"(acc[2]), "+r"(acc[3])
        : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b0), "r"(b1));
}
