//! Backend strings: `"cpu"`, `"cuda"`, `"cuda:N"`, `"auto"`.

use clatch::Backend;
use pyo3::prelude::*;

use crate::errors::{from_clatch, invalid_input};

/// The backend a string names, or an `InvalidInputError`. Whether it can run here is checked by the
/// constructors (`BackendUnavailableError`).
pub fn parse_backend(py: Python<'_>, name: &str) -> PyResult<Backend> {
    let device = |d: &str| d.parse::<usize>().ok();
    match name {
        "cpu" => Ok(Backend::Cpu),
        "cuda" => Ok(Backend::Cuda { device: 0 }),
        "auto" => Ok(Backend::auto()),
        _ => match name.strip_prefix("cuda:").and_then(device) {
            Some(device) => Ok(Backend::Cuda { device }),
            None => Err(invalid_input(
                py,
                "InvalidBackend",
                format!("backend must be \"cpu\", \"cuda\", \"cuda:N\" or \"auto\", got {name:?}"),
            )),
        },
    }
}

/// `"cpu"` or `"cuda:N"`: what `parse_backend` reads back.
pub fn backend_name(backend: Backend) -> String {
    match backend {
        Backend::Cuda { device } => format!("cuda:{device}"),
        _ => "cpu".into(),
    }
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
