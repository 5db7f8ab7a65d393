//! Build script. The default (`cpu`) build needs nothing beyond cargo and does nothing here.
//!
//! Under the `cuda` feature it is the one place that knows about nvcc (`build/cuda.rs`):
//! - finds nvcc (`NVCC`, then `CUDA_HOME`/`CUDA_PATH`, then `PATH`) and the `fatbinary` beside it;
//! - compiles every `kernels/*.cu` to portable PTX for a baseline virtual architecture (`compute_75`, or
//!   what the file's first line asks for), with FMA contraction off so no float decides a bit by accident;
//! - assembles that PTX into native code for every GPU architecture the nvcc knows from Turing (sm_75) up,
//!   or for those `CUDA_COMPUTE_CAP` lists (`build/archs.rs`), one ptxas per file and architecture, side
//!   by side (`build/parallel.rs`), and keeps ptxas's resource report (`OUT_DIR/ptxas-report.txt`);
//! - packs each file's native code and its portable PTX into a fatbin, which is what the library loads: the driver picks the native code of the GPU at hand (no JIT), and
//!   JIT-compiles the PTX only on a GPU newer than the list, or one a narrowed list leaves out;
//! - writes `kernels.rs` (the PTX as string constants, the fatbins, the architectures) and `clatch_h.rs`
//!   (bindgen of `kernels/clatch.h`) into OUT_DIR.
//!
//! `kernels/bench_*.cu` (bench and diagnostic kernels) are compiled only with the `internals` feature.
//! On docs.rs (`DOCS_RS` set, no nvcc there), or with `CLATCH_STUB_KERNELS=1`, every kernel constant is
//! an empty stub, so the documentation of every feature builds without a CUDA toolkit; a library built
//! that way refuses to start a device (`Error::BackendUnavailable`), so a stub is never launched.

#[cfg(feature = "cuda")]
#[path = "build/archs.rs"]
mod archs;
#[cfg(feature = "cuda")]
#[path = "build/cuda.rs"]
mod cuda;
#[cfg(feature = "cuda")]
#[path = "build/parallel.rs"]
mod parallel;

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-changed=build");
    println!("cargo::rerun-if-changed=kernels");
    println!("cargo::rustc-check-cfg=cfg(clatch_all_archs)");
    #[cfg(feature = "cuda")]
    cuda::build();
}
