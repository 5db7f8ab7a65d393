//! The CUDA backend. This release compiles the feature but ships no kernels yet, so the backend reports
//! itself unavailable and [`crate::Backend::auto`] picks the CPU.

use crate::error::{Error, Result};

/// Checks whether CUDA device `device` can run clatch's kernels.
pub fn ensure_available(device: usize) -> Result<()> {
    Err(Error::BackendUnavailable {
        backend: format!("cuda:{device}"),
        reason: "this build's CUDA backend has no kernels yet; use Backend::Cpu".into(),
    })
}
