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
/* Matching (kernels/matching.cu, kernels/knn.cuh). */
#define CLATCH_MATCH_THREADS 128 /* threads per block of the kNN kernels */
#define CLATCH_MATCH_QUERIES_PER_THREAD 2 /* queries held in each thread's registers */
#define CLATCH_MATCH_TILE 64 /* gallery descriptors per shared-memory tile */
#define CLATCH_MATCH_MAX_K 8 /* most neighbours per query on the GPU */
#define CLATCH_MATCH_ROW_PAD 256 /* device descriptor buffers hold a multiple of this many rows */
#define CLATCH_MATCH_SELECT_THREADS 256 /* clatch_match_filter / clatch_match_compact (8 warps) */
#define CLATCH_MATCH_SCAN_THREADS 1024 /* clatch_match_scan: one block */
/* Grouped matching of many pairs per launch (kernels/match_pairs.cu, src/cuda/collection/). */
#define CLATCH_PAIRS_ROW_ALIGN 16 /* each set of a device collection starts at a multiple of this many rows */
#define CLATCH_PAIRS_BLOCK_QUERIES 256 /* queries per task (CLATCH_MATCH_THREADS * CLATCH_MATCH_QUERIES_PER_THREAD) */
#define CLATCH_PAIRS_REJECTED 0xffffffffu /* query field of a best-match record the ratio test or distance limit refused */
/* Tensor-core matching (kernels/matching_tensor.cu): descriptors as +-1 bytes, int8 MMA. */
#define CLATCH_TENSOR_WARPS 8 /* warps per block; each holds 32 queries in registers */
#define CLATCH_TENSOR_QUERIES 256 /* queries per block (CLATCH_TENSOR_WARPS * 32) */
#define CLATCH_TENSOR_TILE 64 /* gallery descriptors per shared-memory stage */
#define CLATCH_TENSOR_STAGES 3 /* cp.async pipeline depth */
#define CLATCH_EXPAND_THREADS 256 /* clatch_expand_signs */
#define CLATCH_GATHER_THREADS 256 /* clatch_gather_rows: one thread per descriptor word */

/* Detection (kernels/detect.cu). */
#define CLATCH_DETECT_TILE_X 32    /* clatch_detect_nms: one thread per pixel of a 32x16 tile */
#define CLATCH_DETECT_TILE_Y 16
#define CLATCH_DETECT_ROW_ALIGN 128 /* row pitch of the kept map, in bytes (one warp reads 128 per step) */
#define CLATCH_DETECT_WARPS 8      /* warps per block of clatch_detect_scatter / clatch_detect_orient */
#define CLATCH_SCAN_THREADS 256    /* clatch_scan_reduce / clatch_scan_apply */
#define CLATCH_SCAN_CHUNK 4096     /* counts per block of the scan (16 per thread) */
#define CLATCH_SCAN_TOP_THREADS 1024 /* clatch_scan_partials: one block */
#define CLATCH_MAX_LEVELS 32         /* most pyramid levels (clatch::pyramid::MAX_LEVELS) */
#define CLATCH_SUBPIXEL_FRAC_BITS 16 /* sub-pixel offsets are in 1/65536 pixel */

/* Smoothing before description (kernels/describe.cu, clatch_smooth_binomial3/5). */
#define CLATCH_SMOOTH_TILE_X 32 /* one thread per output pixel of a 32x8 tile */
#define CLATCH_SMOOTH_TILE_Y 8

/* Pyramid levels (kernels/pyramid.cu). */
#define CLATCH_PYRAMID_STEP_FRAC_BITS 16 /* the scale step is 16.16 fixed point */
#define CLATCH_PYRAMID_TILE_X 32         /* clatch_downscale: one thread per output pixel of a 32x8 tile */
#define CLATCH_PYRAMID_TILE_Y 8

/* OpenCV-compatible LATCH (kernels/describe_opencv.cu). */
#define CLATCH_OPENCV_THREADS 256        /* threads per block: one warp per 32 triplets of a keypoint */
#define CLATCH_OPENCV_MAX_OFFSET 24      /* rotated patch centres are clamped to [-24, 24] */
#define CLATCH_OPENCV_WINDOW_TO_CENTRE 28 /* triplet table value - 28 = OpenCV's centre offset */

/* Where one keypoint's patches go, computed on the host; the same layout as
 * clatch::describe::opencv::Placement (#[repr(C)]). */
typedef struct clatch_opencv_placement {
    int x;     /* (int)(x + 0.5) */
    int y;     /* (int)(y + 0.5) */
    float cos; /* (float)cos((double)angle_radians); 1 without rotation invariance */
    float sin; /* likewise; 0 without rotation invariance */
} clatch_opencv_placement;

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

/* One pair of a grouped launch (kernels/match_pairs.cu): the queries are rows [query_row, query_row +
 * query_rows) of the query buffer, the gallery rows [train_row, train_row + train_rows) of the gallery
 * buffer; the pair's per-query records start at best_row of the launch's best and kept arenas, its
 * per-gallery-row reverse keys at reverse_row of the reverse arena. */
typedef struct clatch_pair {
    unsigned long long query_row;
    unsigned long long train_row;
    unsigned long long best_row;
    unsigned long long reverse_row;
    unsigned int query_rows;
    unsigned int train_rows;
} clatch_pair;

/* One block's work in a grouped kNN launch: queries [CLATCH_PAIRS_BLOCK_QUERIES * query_block, + that)
 * of pair `pair` (an index into the launch's pair list) against the pair's whole gallery. */
typedef struct clatch_pair_task {
    unsigned int pair;
    unsigned int query_block;
} clatch_pair_task;

/* The levels of a pyramid's selection, for one launch over all of them (clatch_orient_refine): level
 * l's texture and size, and its keypoints, records [starts[l], starts[l + 1]) of the launch's buffer
 * (starts[count] keypoints in all). */
typedef struct clatch_levels {
    unsigned long long textures[CLATCH_MAX_LEVELS];
    int widths[CLATCH_MAX_LEVELS];
    int heights[CLATCH_MAX_LEVELS];
    unsigned int starts[CLATCH_MAX_LEVELS + 1];
    int count;
} clatch_levels;

/* Verification (kernels/verify.cu, kernels/verify_math.cuh, src/cuda/verify/): one warp per pair. */
#define CLATCH_VERIFY_WARPS 4 /* warps (pairs) per block of clatch_verify_pairs */
#define CLATCH_VERIFY_LISTS 4 /* u32 scratch entries per correspondence: the F, H, E and translation inliers */
/* clatch_verify_pair.flags */
#define CLATCH_VERIFY_CAMERAS 1u    /* both cameras known: the watermark test may run */
#define CLATCH_VERIFY_INTRINSICS 2u /* both cameras have intrinsics: E is estimated */
/* clatch_verify_result.models */
#define CLATCH_VERIFY_HAS_F 1u
#define CLATCH_VERIFY_HAS_E 2u
#define CLATCH_VERIFY_HAS_H 4u
/* clatch_verify_result.config: COLMAP's numbers (clatch::verify::GeometryConfig). */
#define CLATCH_VERIFY_DEGENERATE 1
#define CLATCH_VERIFY_CALIBRATED 2
#define CLATCH_VERIFY_UNCALIBRATED 3
#define CLATCH_VERIFY_PLANAR_OR_PANORAMIC 6
#define CLATCH_VERIFY_WATERMARK 7

/* One correspondence: the matched keypoints' positions in image A and image B. */
typedef struct clatch_verify_point {
    float xa;
    float ya;
    float xb;
    float yb;
} clatch_verify_point;

/* One estimator's LO-RANSAC settings, resolved on the host (clatch::verify's RansacSettings). */
typedef struct clatch_verify_ransac {
    double max_residual;   /* squared threshold (E's comes per pair) */
    double stop_threshold; /* (1 - confidence)^multiplier */
    unsigned int min_trials;
    unsigned int max_trials;
} clatch_verify_ransac;

/* The settings of a launch (clatch::verify::VerifyConfig, resolved on the host). */
typedef struct clatch_verify_settings {
    clatch_verify_ransac fundamental;
    clatch_verify_ransac homography;
    clatch_verify_ransac essential;
    clatch_verify_ransac translation;
    double min_e_f_inlier_ratio;
    double max_h_inlier_ratio;
    double watermark_min_inlier_ratio;
    double watermark_border_size;
    unsigned long long seed;
    unsigned long long min_num_inliers;
    unsigned int detect_watermark;
    unsigned int planar_keeps_homography_inliers;
} clatch_verify_settings;

/* One pair of a launch: correspondences [first, first + count) of the point buffer (its scratch lists
 * and output inliers at the same offsets). */
typedef struct clatch_verify_pair {
    unsigned long long key; /* the sampler's pair key */
    unsigned long long first;
    unsigned int count;
    unsigned int flags; /* CLATCH_VERIFY_CAMERAS | CLATCH_VERIFY_INTRINSICS */
    double intrinsics_a[4]; /* fx, fy, cx, cy */
    double intrinsics_b[4];
    double size_a[2]; /* width, height */
    double size_b[2];
    double essential_max_residual; /* E's squared threshold in camera units */
} clatch_verify_pair;

/* What one pair gives: clatch::verify::TwoViewGeometry; the inliers are written at the pair's offset. */
typedef struct clatch_verify_result {
    double f[9];
    double e[9];
    double h[9];
    unsigned long long inliers_e;
    unsigned long long inliers_f;
    unsigned long long inliers_h;
    unsigned int config;
    unsigned int models; /* CLATCH_VERIFY_HAS_* */
    unsigned int inlier_count;
    unsigned int pad;
} clatch_verify_result;

#endif /* CLATCH_H */
