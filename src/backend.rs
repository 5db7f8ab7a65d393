//! Where the work runs. Every backend returns the same bits; only speed differs.

use crate::error::Result;

/// The compute backend of an [`crate::Extractor`] or [`crate::Matcher`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Backend {
    /// Rayon over all CPU cores: the reference implementation.
    Cpu,
    /// An NVIDIA GPU (needs the `cuda` feature and a device).
    #[cfg(feature = "cuda")]
    Cuda {
        /// Device ordinal, as in `CUDA_VISIBLE_DEVICES` order.
        device: usize,
    },
}

impl Backend {
    /// CUDA device 0 when the `cuda` feature is compiled in and a device is usable, else the CPU.
    pub fn auto() -> Self {
        #[cfg(feature = "cuda")]
        if crate::cuda::ensure_available(0).is_ok() {
            return Backend::Cuda { device: 0 };
        }
        Backend::Cpu
    }

    /// Checks that this backend can run here (always true for the CPU).
    pub fn ensure_available(&self) -> Result<()> {
        match self {
            Backend::Cpu => Ok(()),
            #[cfg(feature = "cuda")]
            Backend::Cuda { device } => crate::cuda::ensure_available(*device),
        }
    }
}

impl Default for Backend {
    fn default() -> Self {
        Self::auto()
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Backend::Cpu => write!(f, "cpu ({} threads)", rayon::current_num_threads()),
            #[cfg(feature = "cuda")]
            Backend::Cuda { device } => write!(f, "cuda:{device}"),
        }
    }
}
