//! Compiles `kernels/verify_math.cuh` as host C++ (through `src/verify_twin.cpp`) with FMA contraction
//! off, as nvcc compiles it for the device with `--fmad=false`: the same operations in the same order.
//! The warp's stand-in runs 32 threads per pair (`-pthread`).

fn main() {
    println!("cargo::rerun-if-changed=src/verify_twin.cpp");
    println!("cargo::rerun-if-changed=../kernels/verify_math.cuh");
    println!("cargo::rerun-if-changed=../kernels/clatch.h");
    cc::Build::new()
        .cpp(true)
        .file("src/verify_twin.cpp")
        .include("../kernels")
        .flag("-std=c++17")
        .flag("-ffp-contract=off")
        .flag("-pthread")
        .flag_if_supported("-fno-fast-math")
        .warnings(true)
        .extra_warnings(true)
        .warnings_into_errors(true)
        .compile("clatch_verify_twin");
}
