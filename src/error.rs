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

    /// The image cannot hold one descriptor window.
    #[error("image {width}x{height} is smaller than the {min}x{min} descriptor window")]
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

    /// A configuration value out of its range.
    #[error("invalid configuration: {field} = {value} ({reason})")]
    InvalidConfig {
        field: &'static str,
        value: String,
        reason: &'static str,
    },

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
