//! Where the work runs. Every backend returns the same bits; only speed differs.

use crate::error::{Error, Result};

/// The compute backend of an [`crate::Extractor`] or [`crate::Matcher`].
///
/// Both variants exist in every build, so code that chooses a backend needs no `cfg`: without the
/// `cuda` feature, `Backend::Cuda` is refused at construction with [`Error::BackendUnavailable`].
///
/// ```
/// use clatch::{Backend, Error, Extractor, ExtractorConfig};
///
/// match Extractor::new(Backend::Cuda { device: 0 }, ExtractorConfig::default()) {
///     Ok(extractor) => println!("extracting on {}", extractor.backend()),
///     Err(Error::BackendUnavailable { reason, .. }) => println!("no GPU ({reason}); using the CPU"),
///     Err(other) => return Err(other),
/// }
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Backend {
    /// The CPU: rayon over all cores with the `cpu` feature (the default), one thread without it.
    /// This is the reference implementation.
    Cpu,
    /// An NVIDIA GPU. Needs the `cuda` feature, a driver and the device.
    Cuda {
        /// Device ordinal, as in `CUDA_VISIBLE_DEVICES` order.
        device: usize,
    },
}

impl Backend {
    /// CUDA device 0 when the `cuda` feature is compiled in and a device is usable, else the CPU.
    pub fn auto() -> Self {
        let gpu = Backend::Cuda { device: 0 };
        if gpu.ensure_available().is_ok() {
            gpu
        } else {
            Backend::Cpu
        }
    }

    /// Checks that this backend can run here (always true for the CPU): for CUDA that the feature is
    /// compiled in, the driver loads, the device exists and clatch's kernels load on it.
    pub fn ensure_available(&self) -> Result<()> {
        match *self {
            Backend::Cpu => Ok(()),
            Backend::Cuda { device } => cuda_available(device),
        }
    }
}

#[cfg(feature = "cuda")]
fn cuda_available(device: usize) -> Result<()> {
    crate::cuda::ensure_available(device)
}

#[cfg(not(feature = "cuda"))]
fn cuda_available(device: usize) -> Result<()> {
    Err(cuda_unavailable(device, CUDA_NOT_BUILT))
}

impl Default for Backend {
    fn default() -> Self {
        Self::auto()
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Backend::Cpu => write!(f, "cpu ({} threads)", crate::parallel::threads()),
            Backend::Cuda { device } => write!(f, "cuda:{device}"),
        }
    }
}

/// Why `Backend::Cuda` is refused in a build without the `cuda` feature.
#[cfg_attr(feature = "cuda", allow(dead_code))]
pub(crate) const CUDA_NOT_BUILT: &str =
    "clatch was built without its `cuda` feature (the command-line tool: `--features cuda`)";

/// Builds the [`Error::BackendUnavailable`] of an unusable CUDA device.
pub(crate) fn cuda_unavailable(device: usize, reason: impl Into<String>) -> Error {
    Error::BackendUnavailable {
        backend: Backend::Cuda { device }.to_string(),
        reason: reason.into(),
    }
}
