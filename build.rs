//! Build script. The default (`cpu`) build needs nothing beyond cargo and does nothing here.
//!
//! Under the `cuda` feature it is the one place that knows about nvcc:
//! - finds nvcc (`NVCC`, then `CUDA_HOME`/`CUDA_PATH`, then `PATH`);
//! - compiles every `kernels/*.cu` to portable PTX for a baseline virtual architecture (the driver
//!   JIT-compiles it for the GPU at hand), with FMA contraction off so no float decides a bit by accident;
//! - builds a fatbin of each with native sm_90 code plus that PTX (loaded at run time: no JIT on Hopper),
//!   which is also the ptxas check for sm_90, and keeps ptxas's resource report;
//! - writes `kernels.rs` (the PTX as string constants) and `clatch_h.rs` (bindgen of `kernels/clatch.h`)
//!   into OUT_DIR.
//!
//! `kernels/bench_*.cu` (bench and diagnostic kernels) are compiled only with the `internals` feature.
//! On docs.rs (`DOCS_RS` set, no nvcc there), or with `CLATCH_STUB_KERNELS=1`, every kernel constant is
//! an empty stub, so the documentation of every feature builds without a CUDA toolkit; a library built
//! that way refuses to start a device (`Error::BackendUnavailable`), so a stub is never launched.

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-changed=kernels");
    #[cfg(feature = "cuda")]
    cuda::build();
}

#[cfg(feature = "cuda")]
mod cuda {
    use std::fs;
    use std::path::{Path, PathBuf};
    use std::process::Command;

    /// PTX target: old enough for every GPU the driver supports, new enough for the intrinsics used.
    /// A kernel file that needs more opens with `// clatch-ptx-arch: compute_NN` (see [`ptx_arch`]).
    const PTX_ARCH: &str = "compute_75";
    const PTX_ARCH_MARKER: &str = "// clatch-ptx-arch: ";
    /// Native target checked with ptxas (the H100).
    const CHECK_ARCH: &str = "sm_90";
    const NVCC_FLAGS: &[&str] = &["-O3", "--fmad=false", "-lineinfo", "-std=c++17"];

    pub fn build() {
        for var in [
            "NVCC",
            "CUDA_HOME",
            "CUDA_PATH",
            "PATH",
            "DOCS_RS",
            "CLATCH_STUB_KERNELS",
        ] {
            println!("cargo::rerun-if-env-changed={var}");
        }
        let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
        let kernels = Path::new("kernels");
        let stub = std::env::var_os("DOCS_RS").is_some()
            || std::env::var_os("CLATCH_STUB_KERNELS").is_some_and(|v| v == "1");
        let with_bench = std::env::var_os("CARGO_FEATURE_INTERNALS").is_some();

        let mut sources: Vec<PathBuf> = fs::read_dir(kernels)
            .expect("kernels/ exists")
            .map(|entry| entry.expect("readable kernels/ entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "cu"))
            .filter(|p| with_bench || !is_bench(p))
            .collect();
        sources.sort();

        let mut constants = format!(
            "/// True when the kernels below are empty stubs (a documentation build).\npub const STUB: bool = {stub};\n"
        );
        if stub {
            for source in &sources {
                let name = stem(source).to_uppercase();
                constants.push_str(&format!(
                    "/// Stub (documentation build): never launched.\npub const {name}_PTX: &str = \"\";\n\
                     /// Stub (documentation build): never launched.\npub const {name}_FATBIN: &[u8] = &[];\n"
                ));
            }
            fs::write(out.join("kernels.rs"), constants).expect("write kernels.rs");
            bind_header(kernels, &out);
            return;
        }
        let nvcc = find_nvcc().unwrap_or_else(|| {
            panic!(
                "\n\nclatch: the `cuda` feature compiles kernels/*.cu with nvcc, and none was found.\n\
                 Set NVCC=/path/to/nvcc, or CUDA_HOME, or put nvcc on PATH. nvcc 13.0 is known to work\n\
                 (its PTX is accepted by 13.0 drivers); without a CUDA toolkit it installs with pip:\n\
                 \n    pip install --target DIR nvidia-cuda-nvcc==13.0.88 nvidia-cuda-crt==13.0.88 \\\n\
                 \x20       nvidia-cuda-runtime==13.0.96 nvidia-nvvm==13.0.88\n\
                 \x20   export NVCC=DIR/nvidia/cu13/bin/nvcc\n\n"
            )
        });

        let mut report = String::new();
        for source in &sources {
            println!("cargo::rerun-if-changed={}", source.display());
            let stem = stem(source);
            let arch = ptx_arch(source);
            let ptx = out.join(format!("{stem}.ptx"));
            run(Command::new(&nvcc)
                .args(NVCC_FLAGS)
                .args(["-ptx", &format!("-arch={arch}"), "-I"])
                .arg(kernels)
                .arg(source)
                .arg("-o")
                .arg(&ptx));
            // The fatbin carries native sm_90 code (no JIT on an H100) plus the portable PTX, so the
            // driver JIT-compiles only on other GPUs; building it is also the ptxas check for sm_90.
            let fatbin = out.join(format!("{stem}.fatbin"));
            let check = run(Command::new(&nvcc)
                .args(NVCC_FLAGS)
                .args([
                    "-fatbin",
                    &format!("-gencode=arch=compute_{0},code=sm_{0}", &CHECK_ARCH[3..]),
                    &format!("-gencode=arch={arch},code={arch}"),
                    "-Xptxas",
                    "-v",
                    "-I",
                ])
                .arg(kernels)
                .arg(source)
                .arg("-o")
                .arg(&fatbin));
            report.push_str(&format!("== {stem} ({CHECK_ARCH})\n{check}\n"));
            let name = stem.to_uppercase();
            constants.push_str(&format!(
                "/// PTX of `kernels/{stem}.cu` ({arch}).\npub const {name}_PTX: &str = include_str!(concat!(env!(\"OUT_DIR\"), \"/{stem}.ptx\"));\n\
                 /// Fatbin of `kernels/{stem}.cu`: {CHECK_ARCH} code and {arch} PTX.\npub const {name}_FATBIN: &[u8] = include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{stem}.fatbin\"));\n"
            ));
        }
        fs::write(out.join("kernels.rs"), constants).expect("write kernels.rs");
        fs::write(out.join("ptxas-report.txt"), report).expect("write ptxas report");
        bind_header(kernels, &out);
    }

    fn stem(source: &Path) -> String {
        source
            .file_stem()
            .expect("a .cu file has a stem")
            .to_string_lossy()
            .into_owned()
    }

    /// Bench and diagnostic kernels: `kernels/bench_*.cu`.
    fn is_bench(source: &Path) -> bool {
        stem(source).starts_with("bench_")
    }

    /// `clatch_h.rs`: the constants and record layouts of `kernels/clatch.h`, by bindgen.
    fn bind_header(kernels: &Path, out: &Path) {
        let header = kernels.join("clatch.h");
        bindgen::Builder::default()
            .header(header.to_string_lossy())
            .allowlist_item("clatch_.*|CLATCH_.*")
            .derive_default(true)
            .layout_tests(true)
            .generate()
            .expect("bindgen parses kernels/clatch.h")
            .write_to_file(out.join("clatch_h.rs"))
            .expect("write clatch_h.rs");
    }

    /// The PTX architecture of one kernel file: [`PTX_ARCH`], or what its first line asks for
    /// (`// clatch-ptx-arch: compute_80` for instructions the baseline lacks, such as int8 MMA).
    fn ptx_arch(source: &Path) -> String {
        let text = fs::read_to_string(source).expect("readable kernel source");
        match text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix(PTX_ARCH_MARKER))
        {
            Some(arch) => {
                let arch = arch.trim();
                assert!(
                    arch.starts_with("compute_") && arch[8..].chars().all(|c| c.is_ascii_digit()),
                    "clatch: {}: bad PTX architecture {arch:?}",
                    source.display()
                );
                arch.to_string()
            }
            None => PTX_ARCH.to_string(),
        }
    }

    fn find_nvcc() -> Option<PathBuf> {
        let exists = |p: PathBuf| p.is_file().then_some(p);
        if let Some(p) = std::env::var_os("NVCC") {
            return exists(PathBuf::from(p));
        }
        for var in ["CUDA_HOME", "CUDA_PATH"] {
            if let Some(home) = std::env::var_os(var)
                && let Some(p) = exists(Path::new(&home).join("bin").join("nvcc"))
            {
                return Some(p);
            }
        }
        std::env::split_paths(&std::env::var_os("PATH")?).find_map(|dir| exists(dir.join("nvcc")))
    }

    /// Runs a command; on failure stops the build with the exact command line and its output.
    fn run(cmd: &mut Command) -> String {
        let output = cmd
            .output()
            .unwrap_or_else(|e| panic!("clatch: cannot run {cmd:?}: {e}"));
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
        if !output.status.success() {
            panic!("clatch: kernel build failed:\n  {cmd:?}\n{text}");
        }
        text
    }
}
