//! The crate's one error type. Every variant says what was wrong and where.

use thiserror::Error;

/// Everything that can go wrong in clatch. Bad input is always reported here, never by a panic.
///
/// `Error` is `Send + Sync + 'static`, so it crosses threads and fits `Box<dyn std::error::Error>`
/// and `anyhow`. CUDA driver failures keep the driver's error as their [`std::error::Error::source`].
// Field names are described by each variant's message.
#[allow(missing_docs)]
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// The image has no pixels.
    #[error("image is empty ({width}x{height}); width and height must both be at least 1")]
    EmptyImage { width: usize, height: usize },

    /// The row stride is smaller than the width.
    #[error("row stride {stride} is smaller than the image width {width}")]
    StrideTooSmall { width: usize, stride: usize },

    /// The pixel buffer is shorter than `stride * (height - 1) + width`.
    #[error(
        "pixel buffer holds {got} bytes but a {width}x{height} image with stride {stride} needs {needed}"
    )]
    BufferTooSmall {
        width: usize,
        height: usize,
        stride: usize,
        needed: usize,
        got: usize,
    },

    /// The image is smaller than the least clatch detects on: the descriptor's 64x64 sample grid
    /// (spread over the keypoint's window, 40 pixels by default) needs `min` pixels on each side.
    #[error(
        "image {width}x{height} is too small: clatch needs at least {min}x{min} pixels (its descriptor \
         samples a {min}x{min} grid)"
    )]
    ImageTooSmall {
        width: usize,
        height: usize,
        min: usize,
    },

    /// The image is larger than the fixed-point sampling arithmetic allows.
    #[error("image {width}x{height} exceeds the largest supported side of {max} pixels")]
    ImageTooLarge {
        width: usize,
        height: usize,
        max: usize,
    },

    /// A keypoint has a field that is not finite or out of range.
    #[error("keypoint {index}: {field} = {value} is invalid ({reason})")]
    InvalidKeyPoint {
        index: usize,
        field: &'static str,
        value: f32,
        reason: &'static str,
    },

    /// A descriptor width that is not 8·n bits with n in 1..=64.
    #[error(
        "descriptor width {bits} bits is invalid: it must be a multiple of 8 between 8 and 512"
    )]
    InvalidDescriptorWidth { bits: usize },

    /// Query and gallery descriptors have different widths.
    #[error(
        "query descriptors are {query_bits} bits wide but gallery descriptors are {train_bits} bits"
    )]
    DescriptorWidthMismatch {
        query_bits: usize,
        train_bits: usize,
    },

    /// A pair of [`crate::Matcher::match_pairs`] names a set that is not there.
    #[error("pair {pair} names set {index}, but there are {sets} sets")]
    PairOutOfRange {
        pair: usize,
        index: usize,
        sets: usize,
    },

    /// A [`crate::DevicePool`] was given no workers.
    #[error("a device pool needs at least one worker; the list of backends is empty")]
    NoWorkers,

    /// Worker `worker` of a [`crate::DevicePool`] (running on `backend`) failed: its backend cannot
    /// run (no such device, say), or its work failed on the device. `source` is the worker's own
    /// error, e.g. [`Error::BackendUnavailable`] or [`Error::DeviceOutOfMemory`].
    #[error("device pool worker {worker} ({backend}): {source}")]
    Worker {
        worker: usize,
        backend: String,
        #[source]
        source: Box<Error>,
    },

    /// A descriptor buffer whose length is not a whole number of descriptors.
    #[error(
        "descriptor buffer of {words} words is not a multiple of {words_per_descriptor} words per descriptor"
    )]
    DescriptorBufferLength {
        words: usize,
        words_per_descriptor: usize,
    },

    /// A buffer of descriptor bytes ([`crate::DescriptorSet::from_opencv_bytes`]) whose length is
    /// not a whole number of descriptors.
    #[error(
        "descriptor buffer of {bytes} bytes is not a multiple of {bytes_per_descriptor} bytes per descriptor"
    )]
    DescriptorBytesLength {
        bytes: usize,
        bytes_per_descriptor: usize,
    },

    /// Matching against a gallery with no descriptors.
    #[error("the gallery (train set) is empty: there is nothing to match against")]
    EmptyGallery,

    /// k = 0 or k larger than the gallery.
    #[error("k = {k} is invalid for a gallery of {gallery} descriptors (need 1 <= k <= gallery)")]
    InvalidK { k: usize, gallery: usize },

    /// k is more neighbours than the chosen backend returns per query.
    #[error(
        "k = {k} is more than backend {backend} supports: it returns at most {max} neighbours per query"
    )]
    KTooLargeForBackend {
        k: usize,
        max: usize,
        backend: String,
    },

    /// The patch weights have the wrong length.
    #[error("patch weights must have {expected} entries (8x8, row-major), got {got}")]
    WeightsLength { expected: usize, got: usize },

    /// The patch weights could overflow the 32-bit signed SSD accumulator.
    #[error("patch weights sum to {sum}; the most the i32 SSD accumulator allows is {max}")]
    WeightsOverflow { sum: u64, max: u64 },

    /// All patch weights are zero: every bit would be 0.
    #[error("patch weights are all zero")]
    WeightsAllZero,

    /// A configuration value out of its range: a setting of [`crate::ExtractorConfig`],
    /// [`crate::MatchConfig`], [`crate::OpencvLatch`] or a [`crate::DevicePool`]. Inputs that are not
    /// settings (a stream, a set, a list of keypoints) are [`Error::InvalidInput`].
    #[error("invalid configuration: {field} = {value} ({reason})")]
    InvalidConfig {
        field: &'static str,
        value: String,
        reason: &'static str,
    },

    /// An argument of a call that is not a setting, and that no more specific variant describes, is
    /// not usable here: `what` names it (`"stream"`, `"keypoints"`, ...), `reason` says why. For
    /// example a [`crate::cuda::GpuStream`] of another device than the backend's, or more keypoints
    /// than one launch takes.
    #[error("invalid {what}: {reason}")]
    InvalidInput { what: &'static str, reason: String },

    /// A CUDA driver call or kernel launch failed. `source` is the driver's own error: its
    /// `CUresult` code (`source.0`) and the driver's description.
    #[cfg(feature = "cuda")]
    #[cfg_attr(docsrs, doc(cfg(feature = "cuda")))]
    #[error("CUDA {operation} failed: {source}")]
    Cuda {
        operation: String,
        #[source]
        source: cudarc::driver::DriverError,
    },

    /// The device ran out of memory (`CUDA_ERROR_OUT_OF_MEMORY`); the context stays usable.
    #[error("CUDA device out of memory during {operation} ({bytes} bytes requested)")]
    DeviceOutOfMemory { operation: String, bytes: usize },

    /// The requested backend cannot run here: not compiled in (`Backend::Cuda` without the `cuda`
    /// feature), no driver, no such device, or its kernels do not load.
    #[error("backend {backend} is unavailable: {reason}")]
    BackendUnavailable { backend: String, reason: String },

    /// A broken internal invariant: a bug in clatch, never the caller's input. Please report it.
    #[error("internal error in {operation}: {message} (a bug in clatch; please report it)")]
    Internal {
        operation: &'static str,
        message: String,
    },
}

/// Shorthand for `Result<T, clatch::Error>`.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Which [`enum@Error`] variant an error is, without its fields: for telling errors apart by class in
/// code, logs or bindings ([`Error::kind`]). `Display` writes the variant's name (`ImageTooSmall`),
/// as [`ErrorKind::name`] gives it.
///
/// ```
/// use clatch::{DescriptorWidth, ErrorKind};
///
/// let error = DescriptorWidth::from_bits(100).unwrap_err();
/// assert_eq!(error.kind(), ErrorKind::InvalidDescriptorWidth);
/// assert_eq!(error.kind().to_string(), "InvalidDescriptorWidth");
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// [`Error::EmptyImage`]: the image has no pixels.
    EmptyImage,
    /// [`Error::StrideTooSmall`]: the row stride is smaller than the width.
    StrideTooSmall,
    /// [`Error::BufferTooSmall`]: the pixel buffer is too short for the image.
    BufferTooSmall,
    /// [`Error::ImageTooSmall`]: the image cannot hold one descriptor window.
    ImageTooSmall,
    /// [`Error::ImageTooLarge`]: the image is larger than the sampling arithmetic allows.
    ImageTooLarge,
    /// [`Error::InvalidKeyPoint`]: a keypoint field is not finite or out of range.
    InvalidKeyPoint,
    /// [`Error::InvalidDescriptorWidth`]: a width that is not 8·n bits with n in 1..=64.
    InvalidDescriptorWidth,
    /// [`Error::DescriptorWidthMismatch`]: query and gallery descriptors have different widths.
    DescriptorWidthMismatch,
    /// [`Error::PairOutOfRange`]: a pair names a set that is not there.
    PairOutOfRange,
    /// [`Error::NoWorkers`]: a device pool was given no workers.
    NoWorkers,
    /// [`Error::Worker`]: a device pool worker failed; the worker's own error is its `source`.
    Worker,
    /// [`Error::DescriptorBufferLength`]: a buffer that is not a whole number of descriptors.
    DescriptorBufferLength,
    /// [`Error::DescriptorBytesLength`]: descriptor bytes that are not a whole number of
    /// descriptors.
    DescriptorBytesLength,
    /// [`Error::EmptyGallery`]: matching against a gallery with no descriptors.
    EmptyGallery,
    /// [`Error::InvalidK`]: k = 0 or k larger than the gallery.
    InvalidK,
    /// [`Error::KTooLargeForBackend`]: more neighbours than the backend returns per query.
    KTooLargeForBackend,
    /// [`Error::WeightsLength`]: patch weights of the wrong length.
    WeightsLength,
    /// [`Error::WeightsOverflow`]: patch weights that could overflow the SSD accumulator.
    WeightsOverflow,
    /// [`Error::WeightsAllZero`]: every patch weight is zero.
    WeightsAllZero,
    /// [`Error::InvalidConfig`]: a configuration value out of its range.
    InvalidConfig,
    /// [`Error::InvalidInput`]: an argument that is not a setting is not usable.
    InvalidInput,
    /// `Error::Cuda` (a build with the `cuda` feature): a CUDA driver call or kernel launch failed.
    /// The kind exists in every build, so that code matching on kinds needs no `cfg`.
    Cuda,
    /// [`Error::DeviceOutOfMemory`]: the device ran out of memory.
    DeviceOutOfMemory,
    /// [`Error::BackendUnavailable`]: the requested backend cannot run here.
    BackendUnavailable,
    /// [`Error::Internal`]: a broken internal invariant (a bug in clatch).
    Internal,
}

impl ErrorKind {
    /// The variant's name, as written in the source: `"ImageTooSmall"`, `"Cuda"`.
    pub fn name(self) -> &'static str {
        match self {
            ErrorKind::EmptyImage => "EmptyImage",
            ErrorKind::StrideTooSmall => "StrideTooSmall",
            ErrorKind::BufferTooSmall => "BufferTooSmall",
            ErrorKind::ImageTooSmall => "ImageTooSmall",
            ErrorKind::ImageTooLarge => "ImageTooLarge",
            ErrorKind::InvalidKeyPoint => "InvalidKeyPoint",
            ErrorKind::InvalidDescriptorWidth => "InvalidDescriptorWidth",
            ErrorKind::DescriptorWidthMismatch => "DescriptorWidthMismatch",
            ErrorKind::PairOutOfRange => "PairOutOfRange",
            ErrorKind::NoWorkers => "NoWorkers",
            ErrorKind::Worker => "Worker",
            ErrorKind::DescriptorBufferLength => "DescriptorBufferLength",
            ErrorKind::DescriptorBytesLength => "DescriptorBytesLength",
            ErrorKind::EmptyGallery => "EmptyGallery",
            ErrorKind::InvalidK => "InvalidK",
            ErrorKind::KTooLargeForBackend => "KTooLargeForBackend",
            ErrorKind::WeightsLength => "WeightsLength",
            ErrorKind::WeightsOverflow => "WeightsOverflow",
            ErrorKind::WeightsAllZero => "WeightsAllZero",
            ErrorKind::InvalidConfig => "InvalidConfig",
            ErrorKind::InvalidInput => "InvalidInput",
            ErrorKind::Cuda => "Cuda",
            ErrorKind::DeviceOutOfMemory => "DeviceOutOfMemory",
            ErrorKind::BackendUnavailable => "BackendUnavailable",
            ErrorKind::Internal => "Internal",
        }
    }
}

/// Writes [`ErrorKind::name`].
impl std::fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Error {
    /// Which variant this error is ([`ErrorKind`]). A device pool worker's error is
    /// [`ErrorKind::Worker`]; the kind of what the worker hit is its source's.
    ///
    /// ```
    /// use clatch::{ErrorKind, GrayView};
    ///
    /// let error = GrayView::new(&[0u8; 10], 4, 4, 4).unwrap_err();
    /// assert_eq!(error.kind(), ErrorKind::BufferTooSmall);
    /// ```
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::EmptyImage { .. } => ErrorKind::EmptyImage,
            Error::StrideTooSmall { .. } => ErrorKind::StrideTooSmall,
            Error::BufferTooSmall { .. } => ErrorKind::BufferTooSmall,
            Error::ImageTooSmall { .. } => ErrorKind::ImageTooSmall,
            Error::ImageTooLarge { .. } => ErrorKind::ImageTooLarge,
            Error::InvalidKeyPoint { .. } => ErrorKind::InvalidKeyPoint,
            Error::InvalidDescriptorWidth { .. } => ErrorKind::InvalidDescriptorWidth,
            Error::DescriptorWidthMismatch { .. } => ErrorKind::DescriptorWidthMismatch,
            Error::PairOutOfRange { .. } => ErrorKind::PairOutOfRange,
            Error::NoWorkers => ErrorKind::NoWorkers,
            Error::Worker { .. } => ErrorKind::Worker,
            Error::DescriptorBufferLength { .. } => ErrorKind::DescriptorBufferLength,
            Error::DescriptorBytesLength { .. } => ErrorKind::DescriptorBytesLength,
            Error::EmptyGallery => ErrorKind::EmptyGallery,
            Error::InvalidK { .. } => ErrorKind::InvalidK,
            Error::KTooLargeForBackend { .. } => ErrorKind::KTooLargeForBackend,
            Error::WeightsLength { .. } => ErrorKind::WeightsLength,
            Error::WeightsOverflow { .. } => ErrorKind::WeightsOverflow,
            Error::WeightsAllZero => ErrorKind::WeightsAllZero,
            Error::InvalidConfig { .. } => ErrorKind::InvalidConfig,
            Error::InvalidInput { .. } => ErrorKind::InvalidInput,
            #[cfg(feature = "cuda")]
            Error::Cuda { .. } => ErrorKind::Cuda,
            Error::DeviceOutOfMemory { .. } => ErrorKind::DeviceOutOfMemory,
            Error::BackendUnavailable { .. } => ErrorKind::BackendUnavailable,
            Error::Internal { .. } => ErrorKind::Internal,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One error of every variant.
    fn one_of_each() -> Vec<Error> {
        #[cfg_attr(not(feature = "cuda"), allow(unused_mut))]
        let mut errors = vec![
            Error::EmptyImage {
                width: 0,
                height: 5,
            },
            Error::StrideTooSmall {
                width: 8,
                stride: 4,
            },
            Error::BufferTooSmall {
                width: 8,
                height: 8,
                stride: 8,
                needed: 64,
                got: 10,
            },
            Error::ImageTooSmall {
                width: 10,
                height: 10,
                min: 64,
            },
            Error::ImageTooLarge {
                width: 1 << 20,
                height: 1,
                max: 1 << 15,
            },
            Error::InvalidKeyPoint {
                index: 3,
                field: "x",
                value: f32::NAN,
                reason: "not finite",
            },
            Error::InvalidDescriptorWidth { bits: 100 },
            Error::DescriptorWidthMismatch {
                query_bits: 256,
                train_bits: 512,
            },
            Error::PairOutOfRange {
                pair: 0,
                index: 9,
                sets: 2,
            },
            Error::NoWorkers,
            Error::Worker {
                worker: 1,
                backend: "cuda:1".into(),
                source: Box::new(Error::EmptyGallery),
            },
            Error::DescriptorBufferLength {
                words: 9,
                words_per_descriptor: 8,
            },
            Error::DescriptorBytesLength {
                bytes: 65,
                bytes_per_descriptor: 32,
            },
            Error::EmptyGallery,
            Error::InvalidK { k: 0, gallery: 4 },
            Error::KTooLargeForBackend {
                k: 9,
                max: 8,
                backend: "cuda:0".into(),
            },
            Error::WeightsLength {
                expected: 64,
                got: 63,
            },
            Error::WeightsOverflow {
                sum: 1 << 40,
                max: 1 << 31,
            },
            Error::WeightsAllZero,
            Error::InvalidConfig {
                field: "ratio",
                value: "2".into(),
                reason: "must be finite and in (0, 1]",
            },
            Error::InvalidInput {
                what: "stream",
                reason: "it is on cuda:1, the backend on cuda:0".into(),
            },
            Error::DeviceOutOfMemory {
                operation: "upload".into(),
                bytes: 1 << 30,
            },
            Error::BackendUnavailable {
                backend: "cuda:0".into(),
                reason: "no driver".into(),
            },
            Error::Internal {
                operation: "a test",
                message: "on purpose".into(),
            },
        ];
        #[cfg(feature = "cuda")]
        errors.push(Error::Cuda {
            operation: "a test".into(),
            source: cudarc::driver::DriverError(
                cudarc::driver::sys::cudaError_enum::CUDA_ERROR_INVALID_VALUE,
            ),
        });
        errors
    }

    #[test]
    fn every_variant_has_the_kind_of_its_name() {
        let errors = one_of_each();
        let expected = [
            ErrorKind::EmptyImage,
            ErrorKind::StrideTooSmall,
            ErrorKind::BufferTooSmall,
            ErrorKind::ImageTooSmall,
            ErrorKind::ImageTooLarge,
            ErrorKind::InvalidKeyPoint,
            ErrorKind::InvalidDescriptorWidth,
            ErrorKind::DescriptorWidthMismatch,
            ErrorKind::PairOutOfRange,
            ErrorKind::NoWorkers,
            ErrorKind::Worker,
            ErrorKind::DescriptorBufferLength,
            ErrorKind::DescriptorBytesLength,
            ErrorKind::EmptyGallery,
            ErrorKind::InvalidK,
            ErrorKind::KTooLargeForBackend,
            ErrorKind::WeightsLength,
            ErrorKind::WeightsOverflow,
            ErrorKind::WeightsAllZero,
            ErrorKind::InvalidConfig,
            ErrorKind::InvalidInput,
            ErrorKind::DeviceOutOfMemory,
            ErrorKind::BackendUnavailable,
            ErrorKind::Internal,
            #[cfg(feature = "cuda")]
            ErrorKind::Cuda,
        ];
        assert_eq!(errors.len(), expected.len());
        for (error, kind) in errors.iter().zip(expected) {
            assert_eq!(error.kind(), kind);
            // The name is the variant's, as its Debug form begins (what bindings showed before).
            // Not formatted for `Cuda`: the driver error's Debug asks the driver (cudarc panics
            // without one, as on CI; a real `Cuda` error only ever comes from a loaded driver).
            #[cfg(feature = "cuda")]
            if matches!(error, Error::Cuda { .. }) {
                assert_eq!(kind.name(), "Cuda");
                continue;
            }
            let debug = format!("{error:?}");
            let variant = debug.split([' ', '{', '(']).next().unwrap_or_default();
            assert_eq!(kind.name(), variant, "{error:?}");
            assert_eq!(kind.to_string(), variant);
        }
        let mut names: Vec<_> = expected.iter().map(|k| k.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), expected.len(), "two kinds share a name");
    }

    #[test]
    fn the_cuda_kind_exists_in_every_build() {
        assert_eq!(ErrorKind::Cuda.to_string(), "Cuda");
    }

    #[test]
    fn a_worker_error_is_of_kind_worker_and_its_source_keeps_its_own() {
        let error = Error::Worker {
            worker: 0,
            backend: "cpu".into(),
            source: Box::new(Error::DeviceOutOfMemory {
                operation: "upload".into(),
                bytes: 8,
            }),
        };
        assert_eq!(error.kind(), ErrorKind::Worker);
        let Error::Worker { source, .. } = &error else {
            unreachable!("built as a worker error")
        };
        assert_eq!(source.kind(), ErrorKind::DeviceOutOfMemory);
    }
}
