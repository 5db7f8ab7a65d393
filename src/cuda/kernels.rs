//! The registry of kernels: every kernel file the build compiles (`kernels/*.cu`), its PTX and fatbin,
//! and the entry points the crate launches from it. The device loads what is listed here; each stage
//! module lists its own entry points.

use super::ptx;

/// One kernel file: its portable PTX, its fatbin and its entry points.
pub(crate) struct KernelFile {
    pub(crate) path: &'static str,
    pub(crate) ptx: &'static str,
    pub(crate) fatbin: &'static [u8],
    pub(crate) names: &'static [&'static str],
    /// Int8 MMA: loaded only on compute capability 8.0 and later.
    pub(crate) needs_tensor_cores: bool,
}

/// Every kernel entry point the library launches, by the file that defines it. Add a kernel here and
/// fetch it with `GpuDevice::kernel`.
pub(crate) const KERNELS: &[KernelFile] = &[
    KernelFile {
        path: "kernels/describe.cu",
        ptx: ptx::DESCRIBE_PTX,
        fatbin: ptx::DESCRIBE_FATBIN,
        names: &[
            "clatch_describe",
            "clatch_describe_binary",
            "clatch_build_quads",
            "clatch_smooth_binomial3",
            "clatch_smooth_binomial5",
            "clatch_gather_rows",
        ],
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/describe_opencv.cu",
        ptx: ptx::DESCRIBE_OPENCV_PTX,
        fatbin: ptx::DESCRIBE_OPENCV_FATBIN,
        names: &["clatch_describe_opencv"],
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/detect.cu",
        ptx: ptx::DETECT_PTX,
        fatbin: ptx::DETECT_FATBIN,
        names: &[
            "clatch_detect_nms",
            "clatch_scan_reduce",
            "clatch_scan_partials",
            "clatch_scan_apply",
            "clatch_detect_scatter",
            "clatch_detect_orient",
            "clatch_orient_refine",
        ],
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/pyramid.cu",
        ptx: ptx::PYRAMID_PTX,
        fatbin: ptx::PYRAMID_FATBIN,
        names: &["clatch_downscale"],
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/matching.cu",
        ptx: ptx::MATCHING_PTX,
        fatbin: ptx::MATCHING_FATBIN,
        names: crate::cuda::matching::KERNELS,
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/match_pairs.cu",
        ptx: ptx::MATCH_PAIRS_PTX,
        fatbin: ptx::MATCH_PAIRS_FATBIN,
        names: crate::cuda::collection::KERNELS,
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/match_pairs_tensor.cu",
        ptx: ptx::MATCH_PAIRS_TENSOR_PTX,
        fatbin: ptx::MATCH_PAIRS_TENSOR_FATBIN,
        names: crate::cuda::collection::TENSOR_KERNELS,
        needs_tensor_cores: true,
    },
    KernelFile {
        path: "kernels/matching_tensor.cu",
        ptx: ptx::MATCHING_TENSOR_PTX,
        fatbin: ptx::MATCHING_TENSOR_FATBIN,
        names: crate::cuda::matching_tensor::KERNELS,
        needs_tensor_cores: true,
    },
];

/// Bench and diagnostic kernels (`kernels/bench_*.cu`), compiled and loaded only with the `internals`
/// feature, on first use ([`GpuDevice::load_bench_kernels`]).
#[cfg(feature = "internals")]
pub(crate) const BENCH_KERNELS: &[KernelFile] = &[
    KernelFile {
        path: "kernels/bench_knn_variants.cu",
        ptx: ptx::BENCH_KNN_VARIANTS_PTX,
        fatbin: ptx::BENCH_KNN_VARIANTS_FATBIN,
        names: crate::cuda::matching::hooks::VARIANT_KERNELS,
        needs_tensor_cores: false,
    },
    KernelFile {
        path: "kernels/bench_mma_rate.cu",
        ptx: ptx::BENCH_MMA_RATE_PTX,
        fatbin: ptx::BENCH_MMA_RATE_FATBIN,
        names: &["clatch_mma_s8_rate"],
        needs_tensor_cores: true,
    },
    KernelFile {
        path: "kernels/bench_texture_read.cu",
        ptx: ptx::BENCH_TEXTURE_READ_PTX,
        fatbin: ptx::BENCH_TEXTURE_READ_FATBIN,
        names: &["clatch_debug_read_texture"],
        needs_tensor_cores: false,
    },
];

#[cfg(test)]
mod tests {

    use super::*;

    /// Every entry point a file lists is in that file's PTX, and every kernel of the PTX is listed, so
    /// a moved or renamed kernel fails here, on any machine, not at device start.
    #[test]
    fn kernel_lists_match_the_ptx() {
        if ptx::STUB {
            return;
        }
        #[cfg(feature = "internals")]
        let files = KERNELS.iter().chain(BENCH_KERNELS);
        #[cfg(not(feature = "internals"))]
        let files = KERNELS.iter();
        for file in files {
            let mut entries: Vec<&str> = file
                .ptx
                .lines()
                .filter_map(|l| l.trim().strip_prefix(".visible .entry "))
                .map(|l| l.trim_end_matches('(').trim())
                .collect();
            let mut listed = file.names.to_vec();
            entries.sort_unstable();
            listed.sort_unstable();
            assert_eq!(entries, listed, "{}", file.path);
        }
    }
}
