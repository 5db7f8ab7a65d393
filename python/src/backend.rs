//! Backend strings: the library's names (`"cpu"`, `"cuda"`, `"cuda:N"`, `"auto"`; `Backend`'s
//! `FromStr` and `Backend::name`).

use clatch::Backend;
use pyo3::prelude::*;

use crate::errors::{from_clatch, invalid_input};

/// The backend a string names, or an `InvalidInputError` (kind `InvalidBackend`). Whether it can run
/// here is checked by the constructors (`BackendUnavailableError`).
pub fn parse_backend(py: Python<'_>, name: &str) -> PyResult<Backend> {
    name.parse()
        .map_err(|e: clatch::ParseNameError| invalid_input(py, "InvalidBackend", e.to_string()))
}

/// A constructor's error; when CUDA is asked for in a build without it, the message (the library's)
/// is followed by how to install the package with CUDA.
pub fn backend_error(py: Python<'_>, e: clatch::Error) -> PyErr {
    let err = from_clatch(py, e.clone());
    if cfg!(feature = "cuda") || !matches!(e, clatch::Error::BackendUnavailable { .. }) {
        return err;
    }
    let hint = format!(
        "{e}; the Python package: MATURIN_PEP517_ARGS=\"--features cuda\" pip install ./python"
    );
    let value = err.value(py);
    match value.setattr("args", (hint,)) {
        Ok(()) => err,
        Err(_) => from_clatch(py, e),
    }
}
