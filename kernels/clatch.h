/* clatch.h: the constants and record layouts shared by the CUDA kernels and the Rust host.
 * build.rs runs bindgen on this file, so the host gets these exact values and layouts; a test checks
 * that they equal the CPU reference's constants. Plain C, no includes: bindgen and nvcc read it alike. */
#ifndef CLATCH_H
#define CLATCH_H

/* Descriptor window and patches (see docs/numerics.md, section 4). */
#define CLATCH_WINDOW 64
#define CLATCH_PATCH 8
#define CLATCH_TRIPLETS 512
#define CLATCH_DESCRIPTOR_WORDS 8 /* 64-bit words in a 512-bit descriptor */

/* Orientation (section 2). */
#define CLATCH_ANGLE_BINS 2880
#define CLATCH_BINS_PER_DEGREE 8
#define CLATCH_ROTATION_FRAC_BITS 16
#define CLATCH_ORIENTATION_RADIUS 15

/* FAST (section 3). */
#define CLATCH_FAST_ARC 9

/* Launch shapes the host must use. */
#define CLATCH_DESCRIBE_WARPS 8 /* one 64-bit descriptor word per warp */
#define CLATCH_MATCH_THREADS 128
#define CLATCH_MATCH_TILE 256 /* gallery descriptors per shared-memory tile */
#define CLATCH_MATCH_MAX_K 8

/* One keypoint; the same layout as clatch::KeyPoint (#[repr(C)]). */
typedef struct clatch_keypoint {
    float x;
    float y;
    float size;
    float angle;
    float response;
    int octave;
} clatch_keypoint;

/* One match; the same layout as clatch::Match (#[repr(C)]). */
typedef struct clatch_match {
    unsigned int query;
    unsigned int train;
    unsigned int distance;
} clatch_match;

#endif /* CLATCH_H */
