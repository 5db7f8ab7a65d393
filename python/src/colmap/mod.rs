//! The native half of `clatch.colmap` (`clatch/colmap.py`) and of `clatch.ray`'s stages: a folder of
//! photos, the library's one folder run and the one writer of the COLMAP database and match list,
//! all the library's `clatch::colmap`, the code `clatch colmap` runs.

mod folder;
mod job;
mod report;
mod writer;

use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// Adds the native half of `clatch.colmap` to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<folder::ImageFolder>()?;
    m.add_class::<folder::PinholeCamera>()?;
    m.add_class::<writer::FolderWriter>()?;
    m.add_class::<job::FolderJob>()?;
    m.add_class::<job::FolderPlan>()?;
    m.add_function(wrap_pyfunction!(folder::_extract_photos, m)?)?;
    m.add("DEFAULT_GRID", clatch::colmap::DEFAULT_GRID)?;
    m.add(
        "DEFAULT_MAX_KEYPOINTS",
        clatch::colmap::DEFAULT_MAX_KEYPOINTS,
    )?;
    m.add(
        "SUBPIXEL_METHODS",
        PyTuple::new(m.py(), folder::SUBPIXEL_METHODS)?,
    )?;
    Ok(())
}
