//! Build script. The default (`cpu`) build needs nothing beyond cargo. Under the `cuda` feature this is
//! where `kernels/*.cu` will be compiled to PTX with nvcc; this release ships no kernels yet.

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-changed=kernels");
}
