//! What every build of the CUDA module has, with or without the `cuda` feature: the timing of a
//! device's set-up and the error of an unusable device.

use std::time::Duration;

use crate::error::Error;

/// The steps of a GPU's set-up, timed once per process: [`crate::Backend::set_up_steps`].
///
/// The driver's own work dominates all but the last: on an H200 the whole set-up took 150–370 ms a
/// process (BENCHMARKS.md), against under 2 ms of kernels for a 21-megapixel photo.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct SetUpSteps {
    /// `cuInit` and counting the devices (and loading the driver library, if nothing did before).
    pub driver: Duration,
    /// Creating the device's primary context (`cuDevicePrimaryCtxRetain`) and making it current.
    pub context: Duration,
    /// Loading clatch's kernel modules (the fatbins' native code, or their PTX through the JIT).
    pub kernels: Duration,
    /// Uploading the lookup tables (rotations, triplets, direction boundaries) and reading the
    /// device's attributes and name.
    pub tables: Duration,
}

impl SetUpSteps {
    /// The four steps together.
    pub fn total(&self) -> Duration {
        self.driver + self.context + self.kernels + self.tables
    }
}

/// Formats as `driver 41.2 ms, context 120.0 ms, kernels 60.3 ms, tables 1.1 ms`.
impl std::fmt::Display for SetUpSteps {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        write!(
            f,
            "driver {:.1} ms, context {:.1} ms, kernels {:.1} ms, tables {:.1} ms",
            ms(self.driver),
            ms(self.context),
            ms(self.kernels),
            ms(self.tables)
        )
    }
}

/// Why `Backend::Cuda` is refused in a build without the `cuda` feature.
#[cfg_attr(feature = "cuda", allow(dead_code))]
pub(crate) const NOT_BUILT: &str =
    "clatch was built without its `cuda` feature (the command-line tool: `--features cuda`)";

/// Builds the [`Error::BackendUnavailable`] of an unusable CUDA device (named as `Backend::Cuda`
/// displays it).
pub(crate) fn unavailable(device: usize, reason: impl Into<String>) -> Error {
    Error::BackendUnavailable {
        backend: format!("cuda:{device}"),
        reason: reason.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_up_steps_add_up_and_print_in_milliseconds() {
        let steps = SetUpSteps {
            driver: Duration::from_micros(41_250),
            context: Duration::from_millis(120),
            kernels: Duration::from_micros(60_340),
            tables: Duration::from_micros(1_060),
        };
        assert_eq!(steps.total(), Duration::from_micros(222_650));
        assert_eq!(
            steps.to_string(),
            "driver 41.2 ms, context 120.0 ms, kernels 60.3 ms, tables 1.1 ms"
        );
    }
}
