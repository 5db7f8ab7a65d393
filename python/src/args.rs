//! Arguments of the wrong Python type (`k=2.5`, `backend=None`) raised as `ArgumentTypeError`, a
//! `ClatchError` that is also a `TypeError`, naming the argument; a value of the right type that the
//! Rust type cannot hold (an integer beyond 64 bits) as `InvalidInputError`. PyO3 would raise a plain
//! `TypeError` or `OverflowError`. Each function here is a parameter's `from_py_with`.

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

use crate::errors::{invalid_input, wrong_type};

/// `obj` as `T`, or the error of argument `name`, which should be `expected`.
pub fn typed<'py, T>(obj: &Bound<'py, PyAny>, name: &str, expected: &str) -> PyResult<T>
where
    T: for<'a> FromPyObject<'a, 'py>,
{
    obj.extract::<T>().map_err(|e| {
        let e: PyErr = e.into();
        if e.is_instance_of::<PyTypeError>(obj.py()) {
            wrong_type(obj, name, expected)
        } else {
            invalid_input(obj.py(), "InvalidInput", format!("{name}: {e}"))
        }
    })
}

/// One `from_py_with` function per argument: `fn_name: RustType = "python name", "what it must be";`.
macro_rules! typed_args {
    ($($fn_name:ident: $ty:ty = $name:literal, $expected:literal;)*) => {$(
        pub fn $fn_name(obj: &Bound<'_, PyAny>) -> PyResult<$ty> {
            typed(obj, $name, $expected)
        }
    )*};
}

typed_args! {
    backend: String = "backend", "a str (\"cpu\", \"cuda\", \"cuda:N\" or \"auto\")";
    channels: String = "channels", "a str (\"rgb\" or \"bgr\")";
    single_scale: bool = "single_scale", "a bool";
    threshold: Option<i64> = "threshold", "an int or None";
    max_keypoints: Option<i64> = "max_keypoints", "an int or None";
    keypoint_size: Option<f32> = "keypoint_size", "a float or None";
    grid: Option<i64> = "grid", "an int or None";
    level_budget: Option<String> = "level_budget", "a str or None";
    ranking: Option<String> = "ranking", "a str or None";
    subpixel: Option<String> = "subpixel", "a str or None";
    bits: Option<i64> = "bits", "an int or None";
    smoothing: Option<String> = "smoothing", "a str or None";
    weights: Option<Vec<i64>> = "weights", "a sequence of 64 ints or None";
    ratio: Option<f32> = "ratio", "a float or None";
    cross_check: bool = "cross_check", "a bool";
    max_distance: Option<i64> = "max_distance", "an int or None";
    k: i64 = "k", "an int";
    n: i64 = "n", "an int";
    path: std::path::PathBuf = "path", "a str or os.PathLike";
    images_path: std::path::PathBuf = "images", "a str or os.PathLike (a folder)";
    max_pixels: u64 = "max_pixels", "an int >= 0";
    bytes: i64 = "bytes", "an int";
    rotation_invariance: bool = "rotation_invariance", "a bool";
    half_ssd_size: i64 = "half_ssd_size", "an int";
    sigma: f64 = "sigma", "a float";
}

/// `images=`: a sequence of images (each checked as an image later).
pub fn images<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Vec<Bound<'py, PyAny>>> {
    typed(obj, "images", "a sequence of images (numpy arrays)")
}

/// `descriptors=`: a sequence of descriptor arrays (each checked later).
pub fn descriptors<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Vec<Bound<'py, PyAny>>> {
    typed(obj, "descriptors", "a sequence of descriptor arrays")
}
