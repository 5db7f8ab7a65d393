//! The `cuda` feature's build: every `kernels/*.cu` to PTX and to a fatbin with native code for each GPU
//! architecture (see build.rs for the whole picture).

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::archs;
use crate::parallel;

/// A kernel file that needs more than the baseline ([`archs::OLDEST`]) opens with
/// `// clatch-ptx-arch: compute_NN` (see [`ptx_arch`]).
const PTX_ARCH_MARKER: &str = "// clatch-ptx-arch: ";
/// FMA contraction off: no float decides a bit by accident (docs/numerics.md).
const NVCC_FLAGS: &[&str] = &["-O3", "--fmad=false", "-lineinfo", "-std=c++17"];
/// The ptxas options the fatbin records for its PTX, so that the driver JIT-compiles it as ptxas compiled
/// the native code (what nvcc itself passes).
const JIT_FLAGS: &str = "--fmad false --generate-line-info";

/// One kernel file and what is built from it.
struct Source {
    path: PathBuf,
    stem: String,
    /// Its PTX architecture: [`archs::OLDEST`], or what its first line asks for.
    ptx_arch: u32,
    /// The architectures it gets native code for: those listed, from its PTX architecture up.
    native: Vec<u32>,
}

impl Source {
    fn ptx(&self, out: &Path) -> PathBuf {
        out.join(format!("{}.ptx", self.stem))
    }

    fn cubin(&self, out: &Path, arch: u32) -> PathBuf {
        out.join(format!("{}.sm_{arch}.cubin", self.stem))
    }
}

pub fn build() {
    for var in [
        "NVCC",
        "CUDA_HOME",
        "CUDA_PATH",
        "PATH",
        "DOCS_RS",
        "CLATCH_STUB_KERNELS",
        archs::VARIABLE,
    ] {
        println!("cargo::rerun-if-env-changed={var}");
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let kernels = Path::new("kernels");
    let stub = std::env::var_os("DOCS_RS").is_some()
        || std::env::var_os("CLATCH_STUB_KERNELS").is_some_and(|v| v == "1");
    let with_bench = std::env::var_os("CARGO_FEATURE_INTERNALS").is_some();

    let mut paths: Vec<PathBuf> = fs::read_dir(kernels)
        .expect("kernels/ exists")
        .map(|entry| entry.expect("readable kernels/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "cu"))
        .filter(|p| with_bench || !is_bench(p))
        .collect();
    paths.sort();
    for path in &paths {
        println!("cargo::rerun-if-changed={}", path.display());
    }

    if stub {
        let sources = sources(&paths, &[]);
        write_constants(&out, &sources, &[], true);
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
    let fatbinary = find_fatbinary(&nvcc);
    let listed = parallel::run(Command::new(&nvcc).arg("--list-gpu-code"))
        .unwrap_or_else(|e| panic!("clatch: nvcc --list-gpu-code failed:\n{e}"));
    let supported = archs::supported(&listed);
    let requested = std::env::var(archs::VARIABLE).ok();
    let native = archs::select(requested.as_deref(), &supported)
        .unwrap_or_else(|e| panic!("\n\nclatch: {e}\n\n"));
    if native == supported {
        // Lets a test that needs the whole list report itself ignored in a narrowed build.
        println!("cargo::rustc-cfg=clatch_all_archs");
    }
    let sources = sources(&paths, &native);
    let threads = parallel::threads();

    // 1. The front end, once per file, for the file's PTX architecture only. Up to Hopper it writes the
    // same PTX whatever it targets; for Blackwell targets (compute_100 and up) nvcc 13.0's front end
    // takes minutes and gigabytes on kernels/verify.cu (over 10 minutes and 2 GB for compute_121, where
    // compute_75 takes 20 s and 0.3 GB), so no file is ever compiled for one.
    let mut front = Vec::new();
    for source in &sources {
        let mut nvcc = Command::new(&nvcc);
        nvcc.args(NVCC_FLAGS)
            .args(["-ptx", &format!("-arch=compute_{}", source.ptx_arch), "-I"])
            .arg(kernels)
            .arg(&source.path)
            .arg("-o")
            .arg(source.ptx(&out));
        // The front end's work grows with the source it reads.
        let size = with_headers(&source.path)
            .iter()
            .map(|f| fs::metadata(f).map_or(0, |m| m.len()))
            .sum();
        front.push((size, nvcc));
    }
    parallel::run_all(longest_first(front), threads);

    // 2. ptxas, once per file and architecture: native code from the portable PTX, the code the driver's
    // JIT would make of it, without the wait (sm_90's is byte for byte the code of an sm_90-only nvcc
    // build).
    let mut back = Vec::new();
    for source in &sources {
        for &arch in &source.native {
            let mut nvcc = Command::new(&nvcc);
            nvcc.args(NVCC_FLAGS)
                .args(["-cubin", &format!("-arch=sm_{arch}"), "-Xptxas", "-v"])
                .arg(source.ptx(&out))
                .arg("-o")
                .arg(source.cubin(&out, arch));
            let ptx = fs::metadata(source.ptx(&out)).map_or(0, |m| m.len());
            back.push((ptx, ((source.stem.clone(), arch), nvcc)));
        }
    }
    let (labels, back): (Vec<(String, u32)>, Vec<Command>) =
        longest_first(back).into_iter().unzip();
    let mut reports: Vec<((String, u32), String)> = labels
        .into_iter()
        .zip(parallel::run_all(back, threads))
        .collect();
    // The report reads file by file, architecture by architecture, whatever order the jobs ran in.
    reports.sort_by(|a, b| a.0.cmp(&b.0));

    // 3. One fatbin per file: its native code and its portable PTX (for any GPU the list leaves out or
    // newer than all of it, JIT-compiled by the driver).
    // Every image is compressed (LZ4): the native code of a dozen architectures, with its line tables,
    // is about 80 MB uncompressed.
    let mut pack = Vec::new();
    for source in &sources {
        let mut fatbin = Command::new(&fatbinary);
        fatbin
            .arg(format!(
                "--create={}",
                out.join(format!("{}.fatbin", source.stem)).display()
            ))
            .args(["-64", "--compress-all", "--compress-mode=speed"])
            .arg(format!("--ident={}", source.path.display()))
            .arg(format!("--cmdline={JIT_FLAGS}"));
        for &arch in &source.native {
            fatbin.arg(format!(
                "--image3=kind=elf,sm={arch},file={}",
                source.cubin(&out, arch).display()
            ));
        }
        fatbin.arg(format!(
            "--image3=kind=ptx,sm={},file={}",
            source.ptx_arch,
            source.ptx(&out).display()
        ));
        pack.push(fatbin);
    }
    parallel::run_all(pack, threads);
    // The fatbins hold them now: only the portable PTX (a constant) and the fatbins stay.
    for source in &sources {
        for &arch in &source.native {
            let _ = fs::remove_file(source.cubin(&out, arch));
        }
    }

    let report: String = reports
        .iter()
        .map(|((stem, arch), text)| format!("== {stem} (sm_{arch})\n{text}\n"))
        .collect();
    fs::write(out.join("ptxas-report.txt"), report).expect("write ptxas report");
    write_constants(&out, &sources, &native, false);
    bind_header(kernels, &out);
}

/// Each kernel file with its PTX architecture and the listed architectures it gets native code for.
fn sources(paths: &[PathBuf], native: &[u32]) -> Vec<Source> {
    paths
        .iter()
        .map(|path| {
            let ptx_arch = ptx_arch(path);
            Source {
                path: path.clone(),
                stem: stem(path),
                ptx_arch,
                native: native.iter().copied().filter(|&a| a >= ptx_arch).collect(),
            }
        })
        .collect()
}

/// `kernels.rs`: per kernel file its PTX, its fatbin and its PTX architecture, and the architectures
/// with native code (empty stubs in a documentation build).
fn write_constants(out: &Path, sources: &[Source], native: &[u32], stub: bool) {
    let mut constants = format!(
        "/// True when the kernels below are empty stubs (a documentation build).\n\
         pub const STUB: bool = {stub};\n\
         /// The architectures every fatbin has native code for (those from a file's PTX architecture up).\n\
         pub const NATIVE_ARCHS: &[u32] = &{native:?};\n"
    );
    for source in sources {
        let (stem, arch) = (&source.stem, source.ptx_arch);
        let name = stem.to_uppercase();
        constants.push_str(&format!(
            "/// The PTX architecture of `kernels/{stem}.cu` (compute_{arch}): the oldest it runs on.\n\
             pub const {name}_PTX_ARCH: u32 = {arch};\n"
        ));
        if stub {
            constants.push_str(&format!(
                "/// Stub (documentation build): never launched.\npub const {name}_PTX: &str = \"\";\n\
                 /// Stub (documentation build): never launched.\npub const {name}_FATBIN: &[u8] = &[];\n"
            ));
        } else {
            constants.push_str(&format!(
                "/// PTX of `kernels/{stem}.cu` (compute_{arch}).\n\
                 pub const {name}_PTX: &str = include_str!(concat!(env!(\"OUT_DIR\"), \"/{stem}.ptx\"));\n\
                 /// Fatbin of `kernels/{stem}.cu`: native code for {}, and PTX.\n\
                 pub const {name}_FATBIN: &[u8] = include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{stem}.fatbin\"));\n",
                archs::names(&source.native)
            ));
        }
    }
    fs::write(out.join("kernels.rs"), constants).expect("write kernels.rs");
}

/// The jobs, longest first by the size given (of the source, or of the PTX ptxas reads: the compilers'
/// time grows with it), so that the last one to start is a short one.
fn longest_first<T>(mut jobs: Vec<(u64, T)>) -> Vec<T> {
    jobs.sort_by_key(|(size, _)| std::cmp::Reverse(*size));
    jobs.into_iter().map(|(_, job)| job).collect()
}

/// A kernel file and every header it includes (`#include "..."`, followed), each once.
fn with_headers(source: &Path) -> Vec<PathBuf> {
    let mut files = vec![source.to_path_buf()];
    let mut next = 0;
    while let Some(file) = files.get(next).cloned() {
        next += 1;
        let text = fs::read_to_string(&file).expect("readable kernel source");
        for line in text.lines() {
            let Some(name) = line.trim().strip_prefix("#include \"") else {
                continue;
            };
            let header = file.with_file_name(name.split('"').next().unwrap_or_default());
            if header.is_file() && !files.contains(&header) {
                files.push(header);
            }
        }
    }
    files
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

/// The PTX architecture of one kernel file: [`archs::OLDEST`], or what its first line asks for
/// (`// clatch-ptx-arch: compute_80` for instructions the baseline lacks, such as int8 MMA). The host
/// loads the file only on devices of that compute capability or later.
///
/// Native code is assembled from this one PTX (see `build`), so a kernel must not branch on
/// `__CUDA_ARCH__`: the build refuses a file, or a header it includes, that names it.
fn ptx_arch(source: &Path) -> u32 {
    for file in with_headers(source) {
        let text = fs::read_to_string(&file).expect("readable kernel source");
        assert!(
            !text.contains("__CUDA_ARCH__"),
            "clatch: {}: native code is assembled from one PTX for every architecture, so \
             __CUDA_ARCH__ would not be seen; give the kernel file its own `{PTX_ARCH_MARKER}compute_NN` \
             line instead",
            file.display()
        );
    }
    let text = fs::read_to_string(source).expect("readable kernel source");
    match text
        .lines()
        .next()
        .and_then(|l| l.strip_prefix(PTX_ARCH_MARKER))
    {
        Some(arch) => arch
            .trim()
            .strip_prefix("compute_")
            .and_then(|n| n.parse().ok())
            .filter(|&n| n >= archs::OLDEST)
            .unwrap_or_else(|| {
                panic!(
                    "clatch: {}: bad PTX architecture {arch:?} (compute_{} or later)",
                    source.display(),
                    archs::OLDEST
                )
            }),
        None => archs::OLDEST,
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
    on_path("nvcc")
}

/// `fatbinary`, which packs the fatbins: beside nvcc (every CUDA toolkit and the pip packages ship it
/// there), following a link to nvcc, else on `PATH`.
fn find_fatbinary(nvcc: &Path) -> PathBuf {
    [
        nvcc.to_path_buf(),
        fs::canonicalize(nvcc).unwrap_or_default(),
    ]
    .iter()
    .filter_map(|p| p.parent().map(|dir| dir.join("fatbinary")))
    .find(|p| p.is_file())
    .or_else(|| on_path("fatbinary"))
    .unwrap_or_else(|| {
        panic!(
            "clatch: no `fatbinary` beside {} or on PATH (it ships with nvcc)",
            nvcc.display()
        )
    })
}

fn on_path(program: &str) -> Option<PathBuf> {
    std::env::split_paths(&std::env::var_os("PATH")?)
        .map(|dir| dir.join(program))
        .find(|p| p.is_file())
}
