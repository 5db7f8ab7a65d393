//! Every failure as a Python exception of `clatch._exceptions`, with the library's message.
//!
//! The classes are defined in Python (`clatch/_exceptions.py`), so that one can derive from both
//! `ClatchError` and a built-in class (`ValueError`, `RuntimeError`, ...). Each raised exception
//! carries `kind`: the name of the `clatch::Error` variant (or `DecodeError` variant) it came from.

use std::any::Any;
use std::panic::{AssertUnwindSafe, catch_unwind};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyType;

/// The exception classes of `clatch._exceptions`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// The base class: internal errors and anything not listed below.
    Clatch,
    /// Bad input or configuration (also a `ValueError`).
    InvalidInput,
    /// The backend cannot run here (also a `RuntimeError`).
    BackendUnavailable,
    /// A CUDA driver call failed (also a `RuntimeError`).
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    Cuda,
    /// The device ran out of memory (a `CudaError`, also a `MemoryError`).
    DeviceOutOfMemory,
    /// An image file could not be read (also an `OSError`).
    ImageRead,
    /// The COLMAP database or match list could not be written (also an `OSError`).
    Database,
    /// An argument of the wrong Python type (also a `TypeError`).
    ArgumentType,
    /// A host allocation the input needs cannot be made (also a `MemoryError`).
    OutOfMemory,
}

impl Class {
    fn name(self) -> &'static str {
        match self {
            Class::Clatch => "ClatchError",
            Class::InvalidInput => "InvalidInputError",
            Class::BackendUnavailable => "BackendUnavailableError",
            Class::Cuda => "CudaError",
            Class::DeviceOutOfMemory => "DeviceOutOfMemoryError",
            Class::ImageRead => "ImageReadError",
            Class::Database => "DatabaseError",
            Class::ArgumentType => "ArgumentTypeError",
            Class::OutOfMemory => "OutOfMemoryError",
        }
    }

    fn cell(self) -> &'static PyOnceLock<Py<PyType>> {
        static CELLS: [PyOnceLock<Py<PyType>>; 9] = [const { PyOnceLock::new() }; 9];
        &CELLS[self as usize]
    }
}

/// A Python exception of `class` with `message`, its `kind` attribute set to `kind`.
pub fn raise(py: Python<'_>, class: Class, kind: &str, message: String) -> PyErr {
    let made = class
        .cell()
        .import(py, "clatch._exceptions", class.name())
        .and_then(|cls| cls.call1((message.clone(),)))
        .and_then(|exc| {
            exc.setattr("kind", kind)?;
            Ok(exc)
        });
    match made {
        Ok(exc) => PyErr::from_value(exc),
        // Only if the package's own Python files are missing: still an exception, never a panic.
        Err(e) => {
            PyRuntimeError::new_err(format!("{message} (and clatch._exceptions failed: {e})"))
        }
    }
}

/// An `InvalidInputError` raised by the bindings themselves (array type, dtype, shape, strings).
pub fn invalid_input(py: Python<'_>, kind: &str, message: impl Into<String>) -> PyErr {
    raise(py, Class::InvalidInput, kind, message.into())
}

/// The name of an enum variant from its `Debug` form (`ImageTooSmall { .. }` -> `ImageTooSmall`).
fn variant_name(debug: &str) -> &str {
    let end = debug
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(debug.len());
    &debug[..end]
}

/// The class a library error is raised as.
fn class_of(e: &clatch::Error) -> Class {
    use clatch::Error as E;
    match e {
        E::EmptyImage { .. }
        | E::StrideTooSmall { .. }
        | E::BufferTooSmall { .. }
        | E::ImageTooSmall { .. }
        | E::ImageTooLarge { .. }
        | E::InvalidKeyPoint { .. }
        | E::InvalidDescriptorWidth { .. }
        | E::DescriptorWidthMismatch { .. }
        | E::PairOutOfRange { .. }
        | E::DescriptorBufferLength { .. }
        | E::DescriptorBytesLength { .. }
        | E::EmptyGallery
        | E::InvalidK { .. }
        | E::KTooLargeForBackend { .. }
        | E::WeightsLength { .. }
        | E::WeightsOverflow { .. }
        | E::WeightsAllZero
        | E::InvalidConfig { .. }
        | E::InvalidInput { .. }
        | E::NoWorkers => Class::InvalidInput,
        // A device pool worker's error is raised as the class of what the worker hit.
        E::Worker { source, .. } => class_of(source),
        E::BackendUnavailable { .. } => Class::BackendUnavailable,
        E::DeviceOutOfMemory { .. } => Class::DeviceOutOfMemory,
        #[cfg(feature = "cuda")]
        E::Cuda { .. } => Class::Cuda,
        // `Internal` and any variant added later.
        _ => Class::Clatch,
    }
}

/// A library error as its Python exception, with the error's `Display` message and its
/// [`clatch::Error::kind`] as `kind`.
///
/// Image sizes are written as numpy writes shapes, `(H, W)`, rather than the library's `W x H`.
pub fn from_clatch(py: Python<'_>, e: clatch::Error) -> PyErr {
    use clatch::Error as E;
    let message = match e {
        E::EmptyImage { width, height } => format!(
            "image is empty: shape ({height}, {width}); height and width must both be at least 1"
        ),
        E::ImageTooSmall { width, height, min } => format!(
            "image of shape ({height}, {width}) is smaller than the {min}x{min} descriptor window"
        ),
        E::ImageTooLarge { width, height, max } => format!(
            "image of shape ({height}, {width}) exceeds the largest supported side of {max} pixels"
        ),
        _ => e.to_string(),
    };
    raise(py, class_of(&e), e.kind().name(), message)
}

/// An empty buffer with room for `len` bytes for `what` (to be filled with the GIL released), or an
/// `OutOfMemoryError` (kind `OutOfMemory`) where the allocation fails: a Rust allocation failure
/// would abort the whole interpreter.
pub fn try_buffer(py: Python<'_>, len: usize, what: &str) -> PyResult<Vec<u8>> {
    let mut buffer = Vec::new();
    buffer
        .try_reserve_exact(len)
        .map_err(|_| out_of_memory(py, len, what))?;
    Ok(buffer)
}

/// An `OutOfMemoryError`: `bytes` for `what` cannot be allocated.
pub fn out_of_memory(py: Python<'_>, bytes: usize, what: &str) -> PyErr {
    raise(
        py,
        Class::OutOfMemory,
        "OutOfMemory",
        format!("{what} needs {bytes} bytes of memory, which cannot be allocated here"),
    )
}

/// The name of `obj`'s Python type, for messages.
pub fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// An `ArgumentTypeError` (a `ClatchError` and a `TypeError`): argument `name` is not `expected`.
pub fn wrong_type(obj: &Bound<'_, PyAny>, name: &str, expected: &str) -> PyErr {
    let type_name = type_name(obj);
    raise(
        obj.py(),
        Class::ArgumentType,
        "WrongType",
        format!("{name} must be {expected}, got {type_name}"),
    )
}

/// An image decoding error (`clatch.imread`) as an `ImageReadError`.
pub fn from_decode(py: Python<'_>, e: clatch::decode::DecodeError) -> PyErr {
    let debug = format!("{e:?}");
    raise(py, Class::ImageRead, variant_name(&debug), e.to_string())
}

/// A COLMAP error (`clatch.colmap`) as its Python exception: a file that cannot be read as an
/// `ImageReadError`, a database or match list that cannot be written as a `DatabaseError`, a library
/// error as its own class, anything else about the input as an `InvalidInputError`.
pub fn from_colmap(py: Python<'_>, e: clatch::colmap::ColmapError) -> PyErr {
    use clatch::colmap::ColmapError as E;
    let class = match e {
        E::Decode(d) => return from_decode(py, d),
        E::Clatch(c) => return from_clatch(py, c),
        E::Output(o) => return from_output(py, o),
        E::Image { ref source, .. } => class_of(source),
        E::ImageDir { .. } => Class::ImageRead,
        E::Sqlite { .. } | E::DatabaseExists { .. } | E::MatchListIo(_) => Class::Database,
        _ => Class::InvalidInput,
    };
    let debug = format!("{e:?}");
    let kind = match e {
        // The kind `clatch.colmap` gave a pair of one photo before the library checked pairs.
        E::PairOfOnePhoto { .. } => "SamePair",
        _ => variant_name(&debug),
    };
    raise(py, class, kind, e.to_string())
}

/// An output refused (a folder, an input's path: `InvalidInputError`) or not written
/// (`DatabaseError`), its kind the variant's name (`OutputPath`, `OutputClash`, `Write`).
fn from_output(py: Python<'_>, e: clatch::output::OutputError) -> PyErr {
    use clatch::output::OutputError as E;
    let class = match e {
        E::Write { .. } => Class::Database,
        _ => Class::InvalidInput,
    };
    let debug = format!("{e:?}");
    raise(py, class, variant_name(&debug), e.to_string())
}

impl<T> OrRaise<T> for Result<T, clatch::colmap::ColmapError> {
    fn or_raise(self, py: Python<'_>) -> PyResult<T> {
        self.map_err(|e| from_colmap(py, e))
    }
}

/// Extension trait: `clatch::Result<T>` into `PyResult<T>`.
pub trait OrRaise<T> {
    /// The error raised as its Python exception.
    fn or_raise(self, py: Python<'_>) -> PyResult<T>;
}

impl<T> OrRaise<T> for clatch::Result<T> {
    fn or_raise(self, py: Python<'_>) -> PyResult<T> {
        self.map_err(|e| from_clatch(py, e))
    }
}

/// The text of a panic payload.
fn panic_message(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_string()
    }
}

/// Runs `f` with the GIL released (other Python threads run meanwhile), a panic inside caught and
/// raised as a `ClatchError` (kind `Panic`) rather than crossing into Python, and a library error
/// raised as its exception.
///
/// `f` must not touch Python objects: it gets only plain Rust data (`GrayView`s over array memory,
/// descriptor sets), which the caller keeps alive and borrowed for the call.
pub fn compute<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    F: FnOnce() -> clatch::Result<T> + Send,
    T: Send,
{
    compute_with(py, f)
}

/// [`compute`] for a closure with another error type than `clatch::Error` (`ColmapError`).
pub fn compute_with<T, E, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    F: FnOnce() -> Result<T, E> + Send,
    Result<T, E>: OrRaise<T> + Send,
{
    match py.detach(|| catch_unwind(AssertUnwindSafe(f))) {
        Ok(result) => result.or_raise(py),
        Err(payload) => Err(raise(
            py,
            Class::Clatch,
            "Panic",
            format!(
                "internal error: {} (a bug in clatch; please report it)",
                panic_message(&*payload)
            ),
        )),
    }
}
