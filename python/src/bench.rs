//! The Rust side of `python/bench/overhead.py`: the library's own call timed in this process, on
//! inputs converted beforehand, so that the Python call's overhead (conversions in and out, the
//! GIL, argument parsing) is what the two differ by.

use std::time::Instant;

use pyo3::prelude::*;

use crate::arrays::{ImageInput, descriptors_in};
use crate::errors::{OrRaise, compute};
use crate::extractor::Extractor;
use crate::matcher::Matcher;

/// _rust_match_seconds(matcher, query, train, repeats) -> list[float]
///
/// Not public API (the overhead bench): seconds of each of ``repeats`` calls of the library's
/// ``Matcher::match_descriptors`` on the descriptor sets converted once beforehand.
#[pyfunction]
pub fn _rust_match_seconds(
    py: Python<'_>,
    matcher: &Bound<'_, Matcher>,
    query: &Bound<'_, PyAny>,
    train: &Bound<'_, PyAny>,
    repeats: usize,
) -> PyResult<Vec<f64>> {
    let matcher = &matcher.get().inner;
    let query = descriptors_in(query, "query")?;
    let train = descriptors_in(train, "train")?;
    compute(py, || {
        (0..repeats)
            .map(|_| {
                let start = Instant::now();
                let matches = matcher.match_descriptors(&query, &train)?;
                let seconds = start.elapsed().as_secs_f64();
                drop(std::hint::black_box(matches));
                Ok(seconds)
            })
            .collect()
    })
}

/// _rust_extract_seconds(extractor, image, repeats) -> list[float]
///
/// Not public API (the overhead bench): seconds of each of ``repeats`` calls of the library's
/// ``Extractor::detect_and_describe`` on the image viewed once beforehand.
#[pyfunction]
pub fn _rust_extract_seconds(
    py: Python<'_>,
    extractor: &Bound<'_, Extractor>,
    image: &Bound<'_, PyAny>,
    repeats: usize,
) -> PyResult<Vec<f64>> {
    let extractor = &extractor.get().inner;
    let input = ImageInput::new(image, "image", crate::arrays::Channels::Rgb)?;
    let view = input.view().or_raise(py)?;
    compute(py, || {
        (0..repeats)
            .map(|_| {
                let start = Instant::now();
                let features = extractor.detect_and_describe(&view)?;
                let seconds = start.elapsed().as_secs_f64();
                drop(std::hint::black_box(features));
                Ok(seconds)
            })
            .collect()
    })
}
