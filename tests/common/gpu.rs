//! The harness of the GPU suites (`tests/cuda_*.rs`, `harness = false`): without the `cuda` feature or
//! without a device every trial is reported as ignored, with `skipped: no CUDA device`, never as passed.

use libtest_mimic::{Arguments, Failed, Trial};

/// Runs `trials` when CUDA device 0 can run clatch's kernels; otherwise reports each as ignored.
pub fn run(trials: Vec<Trial>) -> ! {
    let args = Arguments::from_args();
    let trials = match device_name() {
        Ok(name) => {
            println!("device: {name}");
            trials
        }
        Err(reason) => {
            println!("skipped: no CUDA device ({reason})");
            trials
                .into_iter()
                .map(|t| t.with_ignored_flag(true))
                .collect()
        }
    };
    libtest_mimic::run(&args, trials).exit()
}

#[cfg(feature = "cuda")]
fn device_name() -> Result<String, String> {
    clatch::cuda::hooks::device(0)
        .map(|dev| dev.name().to_string())
        .map_err(|e| e.to_string())
}

#[cfg(not(feature = "cuda"))]
fn device_name() -> Result<String, String> {
    Err("built without the `cuda` feature".into())
}

/// A trial for a build without the `cuda` feature, which has no GPU tests to list.
pub fn feature_missing(name: &str) -> Vec<Trial> {
    vec![Trial::test(name, || -> Result<(), Failed> {
        Err("built without the `cuda` feature".into())
    })]
}
