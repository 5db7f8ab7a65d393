//! The native module of the `clatch` Python package (`clatch._clatch`); `clatch/__init__.py`
//! re-exports it. Type stubs: `clatch/_clatch.pyi`.

mod args;
mod arrays;
mod backend;
mod bench;
mod colmap;
mod errors;
mod extractor;
mod matcher;
mod verify;

use clatch::decode::DecodeLimits;
use numpy::{Element, IntoPyArray, PyArrayMethods};
use pyo3::prelude::*;

use arrays::{Channels, ImageInput, KeyPointRecord, MatchRecord};
use errors::{OrRaise, from_decode};

/// imread(path, max_pixels=100_000_000) -> image
///
/// Reads a PNG, JPEG or PNM file as the command-line tool does (``clatch::decode::open_gray``):
/// the size checked from the header against ``max_pixels`` before decoding, colour converted with
/// OpenCV's RGB weights, 16-bit scaled full range. Returns a 2-D ``uint8`` array. Raises
/// ``ImageReadError`` (an ``OSError``) naming the file when it cannot be read.
#[pyfunction]
#[pyo3(signature = (path, max_pixels = 100_000_000))]
fn imread<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = args::path)] path: std::path::PathBuf,
    #[pyo3(from_py_with = args::max_pixels)] max_pixels: u64,
) -> PyResult<Bound<'py, PyAny>> {
    let limits = DecodeLimits::default().with_max_pixels(max_pixels);
    let gray = py
        .detach(|| clatch::decode::open_gray(&path, &limits))
        .map_err(|e| from_decode(py, e))?;
    let (w, h) = (gray.width() as usize, gray.height() as usize);
    Ok(gray.into_raw().into_pyarray(py).reshape([h, w])?.into_any())
}

/// to_gray(image, *, channels="rgb") -> image
///
/// The gray image the extractor sees: a 2-D ``uint8`` image as it is (a copy), an H x W x 3 (RGB) or
/// H x W x 4 (RGBA, alpha ignored) ``uint8`` image converted with OpenCV's ``COLOR_RGB2GRAY``
/// integer weights (``clatch::decode::luma``: ``(4899 R + 9617 G + 1868 B + 8192) >> 14``), as the
/// command-line tool converts colour files. OpenCV's ``cv2.imread`` gives BGR: pass
/// ``channels="bgr"`` (then the result equals ``cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)``).
#[pyfunction]
#[pyo3(signature = (image, *, channels = "rgb".to_string()), text_signature = "(image, *, channels='rgb')")]
fn to_gray<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = args::channels)] channels: String,
) -> PyResult<Bound<'py, PyAny>> {
    let input = ImageInput::new(image, "image", Channels::parse(py, &channels)?)?;
    let view = input.view().or_raise(py)?;
    let (w, h) = (view.width(), view.height());
    Ok(input
        .to_vec(py)?
        .into_pyarray(py)
        .reshape([h, w])?
        .into_any())
}

/// _reads_in_place(image) -> bool
///
/// Not public API (the tests): whether ``image`` would be read in place (no copy) by the extractor.
#[pyfunction]
fn _reads_in_place(image: &Bound<'_, PyAny>) -> PyResult<bool> {
    Ok(ImageInput::new(image, "image", Channels::Rgb)?.zero_copy())
}

/// The native module.
#[pymodule]
fn _clatch(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<extractor::Extractor>()?;
    m.add_class::<matcher::Matcher>()?;
    m.add_class::<extractor::OpencvLatch>()?;
    m.add_class::<verify::TwoViewGeometry>()?;
    m.add_function(wrap_pyfunction!(verify::verify_pair, m)?)?;
    m.add_function(wrap_pyfunction!(verify::verify_pairs, m)?)?;
    colmap::register(m)?;
    m.add_function(wrap_pyfunction!(imread, m)?)?;
    m.add_function(wrap_pyfunction!(to_gray, m)?)?;
    m.add_function(wrap_pyfunction!(_reads_in_place, m)?)?;
    m.add_function(wrap_pyfunction!(bench::_rust_match_seconds, m)?)?;
    m.add_function(wrap_pyfunction!(bench::_rust_extract_seconds, m)?)?;
    m.add("KEYPOINT_DTYPE", KeyPointRecord::get_dtype(py))?;
    m.add("MATCH_DTYPE", MatchRecord::get_dtype(py))?;
    m.add("CUDA_BUILT", cfg!(feature = "cuda"))?;
    m.add("MAX_PAIRS", matcher::MAX_PAIRS)?;
    m.add("MAX_IMAGE_SIDE", clatch::MAX_IMAGE_SIDE)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
