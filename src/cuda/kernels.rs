//! The registry of kernels: every kernel file the build compiles (`kernels/*.cu`), its PTX and fatbin,
//! and every entry point the crate launches from it, as a typed [`Kernel`]. A launch site names one of
//! the constants here (or indexes one of the families), never a string, so a kernel it asks for is a
//! kernel the device loaded; `kernel_lists_match_the_ptx` checks the lists against the PTX, and
//! `every_kernel_has_native_code_for_every_listed_architecture` against each fatbin's native code.

use super::ptx;

/// One entry point of clatch's kernels. Made only in this file, from the lists below.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Kernel(&'static str);

impl Kernel {
    /// The `extern "C"` name, as in the PTX.
    pub(crate) const fn name(self) -> &'static str {
        self.0
    }
}

// kernels/describe.cu
pub(crate) const DESCRIBE: Kernel = Kernel("clatch_describe");
pub(crate) const DESCRIBE_BINARY: Kernel = Kernel("clatch_describe_binary");
pub(crate) const BUILD_QUADS: Kernel = Kernel("clatch_build_quads");
pub(crate) const SMOOTH_BINOMIAL3: Kernel = Kernel("clatch_smooth_binomial3");
pub(crate) const SMOOTH_BINOMIAL5: Kernel = Kernel("clatch_smooth_binomial5");
pub(crate) const GATHER_ROWS: Kernel = Kernel("clatch_gather_rows");
// kernels/describe_opencv.cu
pub(crate) const DESCRIBE_OPENCV: Kernel = Kernel("clatch_describe_opencv");
// kernels/detect.cu
pub(crate) const DETECT_NMS: Kernel = Kernel("clatch_detect_nms");
pub(crate) const SCAN_REDUCE: Kernel = Kernel("clatch_scan_reduce");
pub(crate) const SCAN_PARTIALS: Kernel = Kernel("clatch_scan_partials");
pub(crate) const SCAN_APPLY: Kernel = Kernel("clatch_scan_apply");
pub(crate) const DETECT_SCATTER: Kernel = Kernel("clatch_detect_scatter");
pub(crate) const DETECT_ORIENT: Kernel = Kernel("clatch_detect_orient");
pub(crate) const ORIENT_REFINE: Kernel = Kernel("clatch_orient_refine");
// kernels/pyramid.cu
pub(crate) const DOWNSCALE: Kernel = Kernel("clatch_downscale");
// kernels/matching.cu
pub(crate) const KNN_MERGE: Kernel = Kernel("clatch_knn_merge");
pub(crate) const MATCH_FILTER: Kernel = Kernel("clatch_match_filter");
pub(crate) const MATCH_SCAN: Kernel = Kernel("clatch_match_scan");
pub(crate) const MATCH_COMPACT: Kernel = Kernel("clatch_match_compact");
// kernels/match_pairs.cu
pub(crate) const PAIRS_COMPACT: Kernel = Kernel("clatch_pairs_compact");
// kernels/matching_tensor.cu
pub(crate) const EXPAND_SIGNS: Kernel = Kernel("clatch_expand_signs");
// kernels/verify.cu
pub(crate) const VERIFY_PAIRS: Kernel = Kernel("clatch_verify_pairs");
// kernels/bench_*.cu
#[cfg(feature = "internals")]
pub(crate) const MMA_S8_RATE: Kernel = Kernel("clatch_mma_s8_rate");
#[cfg(feature = "internals")]
pub(crate) const DEBUG_READ_TEXTURE: Kernel = Kernel("clatch_debug_read_texture");

macro_rules! knn_family {
    ($($w:literal)*) => {
        &[$(
            Kernel(concat!("clatch_knn_w", $w, "_k1")),
            Kernel(concat!("clatch_knn_w", $w, "_k2")),
            Kernel(concat!("clatch_knn_w", $w, "_k4")),
            Kernel(concat!("clatch_knn_w", $w, "_k8")),
            Kernel(concat!("clatch_knn_mutual_w", $w, "_k1")),
            Kernel(concat!("clatch_knn_mutual_w", $w, "_k2")),
        )*]
    };
}

/// The kNN kernels of `kernels/matching.cu` for rows of 1..8 words: per width, one per list length
/// (1, 2, 4, 8), then the two with the fused reverse 1-NN (k = 1, 2). Indexed by
/// `cuda::matching::knn_kernel`.
pub(crate) const KNN: &[Kernel] = knn_family!(1 2 3 4 5 6 7 8);

macro_rules! pairs_family {
    ($prefix:literal, $suffix:literal: $($w:literal)*) => {
        &[$(
            Kernel(concat!($prefix, $suffix, $w, "_k1")),
            Kernel(concat!($prefix, $suffix, $w, "_k2")),
            Kernel(concat!($prefix, "mutual_", $suffix, $w, "_k1")),
            Kernel(concat!($prefix, "mutual_", $suffix, $w, "_k2")),
        )*]
    };
}

/// The grouped kNN kernels of `kernels/match_pairs.cu`: per width of 1..8 words, k = 1, 2, then the
/// same with the reverse 1-NN.
pub(crate) const PAIRS_KNN: &[Kernel] = pairs_family!("clatch_pairs_knn_", "w": 1 2 3 4 5 6 7 8);
/// The grouped tensor-core kNN kernels of `kernels/match_pairs_tensor.cu`: per padded row width of
/// 64, 128, 256 and 512 bits, k = 1, 2, then the same with the reverse 1-NN.
pub(crate) const TENSOR_PAIRS_KNN: &[Kernel] =
    pairs_family!("clatch_knn_tensor_pairs_", "b": 64 128 256 512);
/// The tensor-core kNN kernels of `kernels/matching_tensor.cu`, laid out as [`TENSOR_PAIRS_KNN`].
pub(crate) const TENSOR_KNN: &[Kernel] = pairs_family!("clatch_knn_tensor_", "b": 64 128 256 512);

/// The alternatives of `kernels/bench_knn_variants.cu` (512 bits, k = 2): `q` queries per thread,
/// popcount groups of `g` words, gallery loop unrolled `u` times.
#[cfg(feature = "internals")]
pub(crate) const KNN_VARIANTS: &[Kernel] = &[
    Kernel("clatch_knn_variant_q1_g1_u1"),
    Kernel("clatch_knn_variant_q1_g3_u1"),
    Kernel("clatch_knn_variant_q1_g7_u1"),
    Kernel("clatch_knn_variant_q1_g15_u1"),
    Kernel("clatch_knn_variant_q2_g1_u1"),
    Kernel("clatch_knn_variant_q2_g3_u1"),
    Kernel("clatch_knn_variant_q2_g7_u1"),
    Kernel("clatch_knn_variant_q2_g15_u1"),
    Kernel("clatch_knn_variant_q2_g7_u2"),
];

/// One kernel file: its portable PTX, its fatbin and its entry points.
pub(crate) struct KernelFile {
    pub(crate) path: &'static str,
    pub(crate) ptx: &'static str,
    pub(crate) fatbin: &'static [u8],
    /// Its entry points, in groups (single kernels, families).
    pub(crate) kernels: &'static [&'static [Kernel]],
    /// Its PTX architecture (`80` for compute_80): the oldest compute capability it runs on, where
    /// it is loaded (the int8 MMA of the tensor-core files needs 8.0).
    pub(crate) min_capability: u32,
}

impl KernelFile {
    /// Every entry point of the file.
    pub(crate) fn entry_points(&self) -> impl Iterator<Item = Kernel> + '_ {
        self.kernels.iter().flat_map(|group| group.iter().copied())
    }

    /// Whether a device of compute `capability` (`86` for 8.6) can load it.
    pub(crate) fn runs_on(&self, capability: u32) -> bool {
        capability >= self.min_capability
    }
}

/// Whether the tensor-core matcher runs on a device of compute `capability`: both of its files load.
pub(crate) fn tensor_cores_on(capability: u32) -> bool {
    KERNELS
        .iter()
        .filter(|f| {
            f.entry_points()
                .any(|k| TENSOR_KNN.contains(&k) || TENSOR_PAIRS_KNN.contains(&k))
        })
        .all(|f| f.runs_on(capability))
}

/// Every kernel file the library loads, with its entry points. Add a kernel above, list it here and
/// fetch it with `GpuDevice::kernel`. A static, not a const: a const's fatbins and PTX (tens of MB)
/// would be copied into every codegen unit that names it.
pub(crate) static KERNELS: &[KernelFile] = &[
    KernelFile {
        path: "kernels/describe.cu",
        ptx: ptx::DESCRIBE_PTX,
        fatbin: ptx::DESCRIBE_FATBIN,
        kernels: &[&[
            DESCRIBE,
            DESCRIBE_BINARY,
            BUILD_QUADS,
            SMOOTH_BINOMIAL3,
            SMOOTH_BINOMIAL5,
            GATHER_ROWS,
        ]],
        min_capability: ptx::DESCRIBE_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/describe_opencv.cu",
        ptx: ptx::DESCRIBE_OPENCV_PTX,
        fatbin: ptx::DESCRIBE_OPENCV_FATBIN,
        kernels: &[&[DESCRIBE_OPENCV]],
        min_capability: ptx::DESCRIBE_OPENCV_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/detect.cu",
        ptx: ptx::DETECT_PTX,
        fatbin: ptx::DETECT_FATBIN,
        kernels: &[&[
            DETECT_NMS,
            SCAN_REDUCE,
            SCAN_PARTIALS,
            SCAN_APPLY,
            DETECT_SCATTER,
            DETECT_ORIENT,
            ORIENT_REFINE,
        ]],
        min_capability: ptx::DETECT_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/pyramid.cu",
        ptx: ptx::PYRAMID_PTX,
        fatbin: ptx::PYRAMID_FATBIN,
        kernels: &[&[DOWNSCALE]],
        min_capability: ptx::PYRAMID_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/matching.cu",
        ptx: ptx::MATCHING_PTX,
        fatbin: ptx::MATCHING_FATBIN,
        kernels: &[KNN, &[KNN_MERGE, MATCH_FILTER, MATCH_SCAN, MATCH_COMPACT]],
        min_capability: ptx::MATCHING_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/match_pairs.cu",
        ptx: ptx::MATCH_PAIRS_PTX,
        fatbin: ptx::MATCH_PAIRS_FATBIN,
        kernels: &[PAIRS_KNN, &[PAIRS_COMPACT]],
        min_capability: ptx::MATCH_PAIRS_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/match_pairs_tensor.cu",
        ptx: ptx::MATCH_PAIRS_TENSOR_PTX,
        fatbin: ptx::MATCH_PAIRS_TENSOR_FATBIN,
        kernels: &[TENSOR_PAIRS_KNN],
        min_capability: ptx::MATCH_PAIRS_TENSOR_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/matching_tensor.cu",
        ptx: ptx::MATCHING_TENSOR_PTX,
        fatbin: ptx::MATCHING_TENSOR_FATBIN,
        kernels: &[&[EXPAND_SIGNS], TENSOR_KNN],
        min_capability: ptx::MATCHING_TENSOR_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/verify.cu",
        ptx: ptx::VERIFY_PTX,
        fatbin: ptx::VERIFY_FATBIN,
        kernels: &[&[VERIFY_PAIRS]],
        min_capability: ptx::VERIFY_PTX_ARCH,
    },
];

/// Bench and diagnostic kernels (`kernels/bench_*.cu`), compiled and loaded only with the `internals`
/// feature, on first use ([`GpuDevice::load_bench_kernels`]).
#[cfg(feature = "internals")]
pub(crate) static BENCH_KERNELS: &[KernelFile] = &[
    KernelFile {
        path: "kernels/bench_knn_variants.cu",
        ptx: ptx::BENCH_KNN_VARIANTS_PTX,
        fatbin: ptx::BENCH_KNN_VARIANTS_FATBIN,
        kernels: &[KNN_VARIANTS],
        min_capability: ptx::BENCH_KNN_VARIANTS_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/bench_mma_rate.cu",
        ptx: ptx::BENCH_MMA_RATE_PTX,
        fatbin: ptx::BENCH_MMA_RATE_FATBIN,
        kernels: &[&[MMA_S8_RATE]],
        min_capability: ptx::BENCH_MMA_RATE_PTX_ARCH,
    },
    KernelFile {
        path: "kernels/bench_texture_read.cu",
        ptx: ptx::BENCH_TEXTURE_READ_PTX,
        fatbin: ptx::BENCH_TEXTURE_READ_FATBIN,
        kernels: &[&[DEBUG_READ_TEXTURE]],
        min_capability: ptx::BENCH_TEXTURE_READ_PTX_ARCH,
    },
];

#[cfg(test)]
mod tests {

    use super::super::fatbin::{self, Kind};
    use super::*;

    /// Every kernel file the build compiled: the library's, and with `internals` the bench kernels.
    fn files() -> impl Iterator<Item = &'static KernelFile> {
        #[cfg(feature = "internals")]
        return KERNELS.iter().chain(BENCH_KERNELS);
        #[cfg(not(feature = "internals"))]
        KERNELS.iter()
    }

    /// Every entry point a file lists is in that file's PTX, and every kernel of the PTX is listed, so
    /// a moved or renamed kernel fails here, on any machine, not at device start.
    #[test]
    fn kernel_lists_match_the_ptx() {
        if ptx::STUB {
            return;
        }
        for file in files() {
            let mut entries: Vec<&str> = file
                .ptx
                .lines()
                .filter_map(|l| l.trim().strip_prefix(".visible .entry "))
                .map(|l| l.trim_end_matches('(').trim())
                .collect();
            let mut listed: Vec<&str> = file.entry_points().map(Kernel::name).collect();
            entries.sort_unstable();
            listed.sort_unstable();
            assert_eq!(entries, listed, "{}", file.path);
        }
    }

    /// Each file's fatbin, read as the driver reads it: native code for every architecture the build
    /// lists from the file's PTX architecture up (and no other), each defining every kernel of the file
    /// and no other; then the file's portable PTX alone (never a Blackwell PTX: build/cuda.rs says why).
    /// A kernel or an architecture missing from the native code fails here, on any machine.
    #[test]
    fn every_kernel_has_native_code_for_every_listed_architecture() {
        if ptx::STUB {
            return;
        }
        assert!(!ptx::NATIVE_ARCHS.is_empty());
        for file in files() {
            let path = file.path;
            let images = fatbin::images(file.fatbin).unwrap_or_else(|e| panic!("{path}: {e}"));
            let mut listed: Vec<&str> = file.entry_points().map(Kernel::name).collect();
            listed.sort_unstable();
            let mut native = Vec::new();
            for image in images.iter().filter(|i| i.kind == Kind::Native) {
                let (arch, mut kernels) = fatbin::kernels(&image.payload)
                    .unwrap_or_else(|e| panic!("{path}: sm_{}: {e}", image.arch));
                assert_eq!(
                    arch, image.arch,
                    "{path}: the sm_{arch} code is filed as sm_{}",
                    image.arch
                );
                kernels.sort_unstable();
                assert_eq!(kernels, listed, "{path}: the kernels of its sm_{arch} code");
                native.push(arch);
            }
            native.sort_unstable();
            let expected: Vec<u32> = ptx::NATIVE_ARCHS
                .iter()
                .copied()
                .filter(|&a| file.runs_on(a))
                .collect();
            assert_eq!(
                native, expected,
                "{path}: the architectures with native code"
            );

            let ptx: Vec<u32> = images
                .iter()
                .filter(|i| i.kind == Kind::Ptx)
                .map(|i| i.arch)
                .collect();
            assert_eq!(
                ptx,
                [file.min_capability],
                "{path}: the architectures of its PTX"
            );
        }
    }

    /// Without `CUDA_COMPUTE_CAP`, every GPU generation from Turing on has native code (the README's
    /// list: Turing, Ampere and Jetson Orin, Ada, Hopper, Blackwell datacentre and desktop), so a toolkit
    /// or a reading of its list that dropped one fails here. A narrowed build reports it ignored.
    #[test]
    #[cfg_attr(
        not(clatch_all_archs),
        ignore = "built for the architectures CUDA_COMPUTE_CAP lists"
    )]
    fn a_full_build_covers_every_generation_from_turing() {
        for arch in [75, 80, 86, 87, 89, 90, 100, 120] {
            assert!(
                ptx::NATIVE_ARCHS.contains(&arch),
                "sm_{arch} missing from {:?}",
                ptx::NATIVE_ARCHS
            );
        }
    }

    /// The int8 MMA needs compute capability 8.0: the tensor-core files load from there on, the others
    /// everywhere from Turing.
    #[test]
    fn files_load_where_their_instructions_exist() {
        assert!(!tensor_cores_on(75) && tensor_cores_on(80) && tensor_cores_on(121));
        for file in KERNELS {
            let tensor = file
                .entry_points()
                .any(|k| TENSOR_KNN.contains(&k) || TENSOR_PAIRS_KNN.contains(&k));
            assert_eq!(file.runs_on(75), !tensor, "{}", file.path);
            assert!(file.runs_on(80), "{}", file.path);
        }
    }
}
