//! The harness of the GPU suites (`tests/cuda_*.rs`, `harness = false`): without the `cuda` feature or
//! without a device every trial is reported as ignored, with `skipped: no CUDA device`, never as passed.

use libtest_mimic::{Arguments, Failed, Trial};

/// Why the suite cannot run on a device.
enum NoDevice {
    /// Nothing to run on (no feature, no driver, no device): the trials are skipped.
    Absent(String),
    /// A device is there but clatch could not start on it (a kernel that does not load, say): every
    /// trial fails with this, so a broken build never passes as "skipped".
    Broken(String),
}

/// Runs `trials` when CUDA device 0 can run clatch's kernels; reports each as ignored when there is no
/// device, and as failed when there is one that clatch cannot start on.
pub fn run(trials: Vec<Trial>) -> ! {
    let args = Arguments::from_args();
    if let Some(line) = super::scale::banner() {
        println!("{line}");
    }
    let trials = match device_name() {
        Ok(name) => {
            println!("device: {name}");
            trials
        }
        Err(NoDevice::Absent(reason)) => {
            println!("skipped: no CUDA device ({reason})");
            trials
                .into_iter()
                .map(|t| t.with_ignored_flag(true))
                .collect()
        }
        Err(NoDevice::Broken(reason)) => {
            println!("the CUDA device does not start: {reason}");
            trials
                .into_iter()
                .map(|t| {
                    let reason = reason.clone();
                    Trial::test(t.name().to_string(), move || {
                        Err(format!("the CUDA device does not start: {reason}").into())
                    })
                })
                .collect()
        }
    };
    libtest_mimic::run(&args, trials).exit()
}

#[cfg(feature = "cuda")]
fn device_name() -> Result<String, NoDevice> {
    match clatch::cuda::hooks::device(0) {
        Ok(dev) => Ok(dev.name().to_string()),
        // No driver, no device 0: nothing to test on.
        Err(e @ clatch::Error::BackendUnavailable { .. }) => Err(NoDevice::Absent(e.to_string())),
        Err(e) => Err(NoDevice::Broken(e.to_string())),
    }
}

#[cfg(not(feature = "cuda"))]
fn device_name() -> Result<String, NoDevice> {
    Err(NoDevice::Absent("built without the `cuda` feature".into()))
}

/// A trial for a build without the `cuda` feature, which has no GPU tests to list.
pub fn feature_missing(name: &str) -> Vec<Trial> {
    vec![Trial::test(name, || -> Result<(), Failed> {
        Err("built without the `cuda` feature".into())
    })]
}
