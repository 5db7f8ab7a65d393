//! A folder of photos and their features: `clatch.colmap.ImageFolder`, `PinholeCamera` and
//! `extract_photos`, the library's `clatch::colmap` folder reading.

use std::path::PathBuf;

use clatch::DescriptorSet;
use clatch::colmap::{Photo, Refinement};
use clatch::decode::DecodeLimits;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::{descriptors_out, keypoints_out};
use crate::errors::{OrRaise, compute_with, invalid_input};
use crate::extractor::Extractor;

/// The photos of a folder, checked before any work.
///
/// ImageFolder(images, *, max_pixels=100_000_000)
///
/// The image files directly inside ``images`` (``.jpg``, ``.jpeg``, ``.png``, ``.pgm``, ``.ppm``,
/// ``.pbm``, ``.pnm``, any case; not its subfolders), sorted by name, as ``clatch colmap`` reads
/// them: each name must be UTF-8 without whitespace, each header within ``max_pixels``, each JPEG
/// complete and each image large enough to detect on. Raises ``ImageReadError`` for a folder that
/// cannot be listed or a file that cannot be read, ``InvalidInputError`` for no image, a bad name
/// or a too small image.
#[pyclass(module = "clatch.colmap", frozen)]
pub struct ImageFolder {
    inner: clatch::colmap::ImageFolder,
}

#[pymethods]
impl ImageFolder {
    #[new]
    #[pyo3(signature = (images, *, max_pixels = 100_000_000))]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = crate::args::images_path)] images: PathBuf,
        #[pyo3(from_py_with = crate::args::max_pixels)] max_pixels: u64,
    ) -> PyResult<Self> {
        let limits = DecodeLimits::default().with_max_pixels(max_pixels);
        let inner = compute_with(py, || clatch::colmap::ImageFolder::open(&images, &limits))?;
        Ok(Self { inner })
    }

    /// The image files, in name order (image ``i`` of every result).
    #[getter]
    fn paths(&self) -> Vec<PathBuf> {
        self.inner.paths.clone()
    }

    /// Their names in the database: the file names.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names.clone()
    }

    /// Their sizes ``(width, height)``, from the headers.
    #[getter]
    fn sizes(&self) -> Vec<(u32, u32)> {
        self.inner.sizes.clone()
    }

    fn __len__(&self) -> usize {
        self.inner.paths.len()
    }

    fn __repr__(&self) -> String {
        let first = self.inner.names.first().map(String::as_str).unwrap_or("");
        format!(
            "ImageFolder({} images: {first:?}, ...)",
            self.inner.paths.len()
        )
    }

    /// shared_camera(k_text) -> PinholeCamera
    ///
    /// The camera of the intrinsic matrix ``k_text`` (9 numbers, row-major, as in a ``K.txt`` file)
    /// shared by every photo, which all need the first one's size. Raises ``InvalidInputError``
    /// (kind ``InvalidCamera`` or ``ImageSizeMismatch``).
    fn shared_camera(&self, py: Python<'_>, k_text: &str) -> PyResult<PinholeCamera> {
        let inner = self.inner.shared_camera(k_text).or_raise(py)?;
        Ok(PinholeCamera { inner })
    }
}

/// A PINHOLE camera of the database (``ImageFolder.shared_camera``): ``fx, fy, cx, cy`` in COLMAP's
/// pixel convention (the first pixel's centre at (0.5, 0.5)).
#[pyclass(module = "clatch.colmap", frozen)]
pub struct PinholeCamera {
    pub(super) inner: clatch::colmap::PinholeCamera,
}

#[pymethods]
impl PinholeCamera {
    /// Image width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }
    /// Image height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }
    /// Focal length along x, in pixels.
    #[getter]
    fn fx(&self) -> f64 {
        self.inner.fx
    }
    /// Focal length along y, in pixels.
    #[getter]
    fn fy(&self) -> f64 {
        self.inner.fy
    }
    /// Principal point x, in pixels.
    #[getter]
    fn cx(&self) -> f64 {
        self.inner.cx
    }
    /// Principal point y, in pixels.
    #[getter]
    fn cy(&self) -> f64 {
        self.inner.cy
    }
    /// Whether the focal length is known (a given K is).
    #[getter]
    fn focal_is_known(&self) -> bool {
        self.inner.focal_is_known
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "PinholeCamera(width={}, height={}, fx={}, fy={}, cx={}, cy={}, focal_is_known={})",
            c.width,
            c.height,
            c.fx,
            c.fy,
            c.cx,
            c.cy,
            if c.focal_is_known { "True" } else { "False" }
        )
    }
}

/// The largest half side of the corner window (`clatch colmap --subpixel-radius`'s range).
const MAX_CORNER_RADIUS: u32 = 16;

/// The names of `subpixel=` (`clatch colmap --subpixel`): the extractor's FAST-score peak, whole
/// pixels, or Förstner's corner over a `2 radius + 1` window.
pub const SUBPIXEL_METHODS: [&str; 3] = ["score", "none", "corner"];

/// `subpixel=` and `subpixel_radius=` as the library's refinement, or an `InvalidInputError` (kind
/// `InvalidConfig`).
pub fn refinement(py: Python<'_>, subpixel: &str, radius: i64) -> PyResult<Refinement> {
    match subpixel {
        "score" => Ok(Refinement::Score),
        "none" => Ok(Refinement::None),
        "corner" => corner(py, radius),
        other => Err(invalid_input(
            py,
            "InvalidConfig",
            format!("subpixel must be one of {SUBPIXEL_METHODS:?}, got {other:?}"),
        )),
    }
}

/// Förstner's corner over a `2 radius + 1` window, the radius checked.
fn corner(py: Python<'_>, radius: i64) -> PyResult<Refinement> {
    if let Some(radius) = u32::try_from(radius)
        .ok()
        .filter(|r| (1..=MAX_CORNER_RADIUS).contains(r))
    {
        return Ok(Refinement::Corner { radius });
    }
    Err(invalid_input(
        py,
        "InvalidConfig",
        format!("subpixel_radius must be in 1..={MAX_CORNER_RADIUS}, got {radius}"),
    ))
}

/// Photos as `(name, width, height, focal_35mm, keypoints, descriptors)` tuples, in order.
pub fn photos_out<'py>(
    py: Python<'py>,
    photos: Vec<(Photo, DescriptorSet)>,
) -> PyResult<Vec<Bound<'py, PyTuple>>> {
    photos
        .into_iter()
        .map(|(photo, descriptors)| {
            let descriptors = descriptors_out(py, &descriptors)?;
            let keypoints = keypoints_out(py, photo.keypoints).into_any();
            (
                photo.name,
                photo.width,
                photo.height,
                photo.focal_35mm,
                keypoints,
                descriptors,
            )
                .into_pyobject(py)
        })
        .collect()
}

/// _extract_photos(extractor, paths, names, max_pixels, corner_radius) -> list
///
/// Not public API (``clatch.colmap.extract_photos`` calls it): each photo read, detected, described
/// and, with ``corner_radius``, refined to the least-squares corner, as
/// ``clatch::colmap::extract_photos``; one ``(name, width, height, focal_35mm, keypoints,
/// descriptors)`` tuple per photo, in order. Runs with the GIL released.
#[pyfunction]
#[pyo3(signature = (extractor, paths, names, max_pixels, corner_radius = None))]
pub fn _extract_photos<'py>(
    py: Python<'py>,
    extractor: &Extractor,
    paths: Vec<PathBuf>,
    names: Vec<String>,
    max_pixels: u64,
    corner_radius: Option<i64>,
) -> PyResult<Vec<Bound<'py, PyTuple>>> {
    check_lengths(py, &paths, &names)?;
    let refinement = match corner_radius {
        None => Refinement::None,
        Some(radius) => corner(py, radius)?,
    };
    let limits = DecodeLimits::default().with_max_pixels(max_pixels);
    let (photos, _decoding) = compute_with(py, || {
        clatch::colmap::extract_photos(
            &extractor.inner,
            (&paths, &names),
            &limits,
            refinement,
            &|_| {},
        )
    })?;
    photos_out(py, photos)
}

/// Refuses paths and names of different lengths.
pub fn check_lengths(py: Python<'_>, paths: &[PathBuf], names: &[String]) -> PyResult<()> {
    if paths.len() == names.len() {
        return Ok(());
    }
    Err(invalid_input(
        py,
        "LengthMismatch",
        format!("{} paths but {} names", paths.len(), names.len()),
    ))
}
