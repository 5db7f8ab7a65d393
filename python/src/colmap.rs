//! The native half of `clatch.colmap` (`clatch/colmap.py`): a folder of photos, their features and
//! the one writer of the COLMAP database and match list, all the library's `clatch::colmap`, the code
//! `clatch colmap` runs.

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::Mutex;

use clatch::colmap::Refinement;
use clatch::decode::DecodeLimits;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::{descriptors_out, keypoints_in, keypoints_out, matches_in};
use crate::errors::{OrRaise, compute_with, invalid_input, raise};
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
    fn new(py: Python<'_>, images: PathBuf, max_pixels: u64) -> PyResult<Self> {
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
    inner: clatch::colmap::PinholeCamera,
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

/// _extract_photos(extractor, paths, names, max_pixels, corner_radius) -> list
///
/// Not public API (``clatch.colmap`` and ``clatch.ray`` call it): each photo read, detected,
/// described and, with ``corner_radius``, refined to the least-squares corner, as
/// ``clatch::colmap::extract_photos``; one ``(name, width, height, focal_35mm, keypoints,
/// descriptors)`` tuple per photo, in order. Runs with the GIL released.
#[pyfunction]
#[pyo3(signature = (extractor, paths, names, max_pixels, corner_radius = None))]
fn _extract_photos<'py>(
    py: Python<'py>,
    extractor: &Extractor,
    paths: Vec<PathBuf>,
    names: Vec<String>,
    max_pixels: u64,
    corner_radius: Option<u32>,
) -> PyResult<Vec<Bound<'py, PyTuple>>> {
    if paths.len() != names.len() {
        return Err(invalid_input(
            py,
            "LengthMismatch",
            format!("{} paths but {} names", paths.len(), names.len()),
        ));
    }
    let refinement = match corner_radius {
        None => Refinement::None,
        Some(radius @ 1..=MAX_CORNER_RADIUS) => Refinement::Corner { radius },
        Some(radius) => {
            return Err(invalid_input(
                py,
                "InvalidConfig",
                format!("subpixel_radius must be in 1..={MAX_CORNER_RADIUS}, got {radius}"),
            ));
        }
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

type Writer = clatch::colmap::FolderWriter<BufWriter<File>>;

/// Not public API (``clatch.colmap`` and ``clatch.ray`` use it): the library's one writer of a
/// folder's database and match list (``clatch::colmap::FolderWriter``).
///
/// _FolderWriter(database, match_list, camera=None)
#[pyclass(module = "clatch.colmap", frozen, name = "_FolderWriter")]
pub struct FolderWriter {
    inner: Mutex<Option<Writer>>,
}

impl FolderWriter {
    /// Runs `f` on the open writer, or raises when it is finished or closed.
    fn with<T>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Writer) -> Result<T, clatch::colmap::ColmapError>,
    ) -> PyResult<T> {
        let mut guard = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        match guard.as_mut() {
            Some(writer) => f(writer).or_raise(py),
            None => Err(closed(py)),
        }
    }
}

fn closed(py: Python<'_>) -> PyErr {
    raise(
        py,
        crate::errors::Class::InvalidInput,
        "WriterClosed",
        "the COLMAP writer is already finished or closed".into(),
    )
}

#[pymethods]
impl FolderWriter {
    #[new]
    #[pyo3(signature = (database, match_list, camera = None))]
    fn new(
        py: Python<'_>,
        database: PathBuf,
        match_list: PathBuf,
        camera: Option<&PinholeCamera>,
    ) -> PyResult<Self> {
        let list = File::create(&match_list).map_err(|e| {
            raise(
                py,
                crate::errors::Class::Database,
                "MatchListIo",
                format!("cannot write {}: {e}", match_list.display()),
            )
        })?;
        let writer = clatch::colmap::FolderWriter::create(
            &database,
            BufWriter::new(list),
            camera.map(|c| &c.inner),
        )
        .or_raise(py)?;
        Ok(Self {
            inner: Mutex::new(Some(writer)),
        })
    }

    /// add_photo(name, width, height, focal_35mm, keypoints) -> int
    ///
    /// The next photo's camera, image row and keypoints; returns its index.
    fn add_photo(
        &self,
        py: Python<'_>,
        name: String,
        width: u32,
        height: u32,
        focal_35mm: Option<u16>,
        keypoints: &Bound<'_, PyAny>,
    ) -> PyResult<usize> {
        let photo =
            clatch::colmap::Photo::new(name, width, height, keypoints_in(keypoints, "keypoints")?)
                .with_focal_35mm(focal_35mm);
        self.with(py, |w| w.add_photo(&photo))
    }

    /// add_matches(i, j, matches)
    ///
    /// Appends the matches of photos ``i`` and ``j`` (``MATCH_DTYPE``; query indexes ``i``'s
    /// keypoints) to the match list, each index checked; a pair without matches is left out.
    fn add_matches(
        &self,
        py: Python<'_>,
        i: usize,
        j: usize,
        matches: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let matches = matches_in(matches, "matches")?;
        self.with(py, |w| w.add_matches(i, j, &matches))
    }

    /// The number of photos written.
    #[getter]
    fn photos(&self, py: Python<'_>) -> PyResult<usize> {
        self.with(py, |w| Ok(w.photos()))
    }

    /// finish()
    ///
    /// Commits the database and flushes the match list.
    fn finish(&self, py: Python<'_>) -> PyResult<()> {
        let writer = self
            .inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .ok_or_else(|| closed(py))?;
        let list = writer.finish().or_raise(py)?;
        let file = list.into_inner().map_err(|e| {
            raise(
                py,
                crate::errors::Class::Database,
                "MatchListIo",
                format!("cannot write the match list: {}", e.error()),
            )
        })?;
        file.sync_all().map_err(|e| {
            raise(
                py,
                crate::errors::Class::Database,
                "MatchListIo",
                format!("cannot write the match list: {e}"),
            )
        })
    }

    /// close()
    ///
    /// Drops an unfinished writer: the database keeps its tables but no row.
    fn close(&self) {
        self.inner.lock().unwrap_or_else(|p| p.into_inner()).take();
    }
}

/// Adds the native half of `clatch.colmap` to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ImageFolder>()?;
    m.add_class::<PinholeCamera>()?;
    m.add_class::<FolderWriter>()?;
    m.add_function(wrap_pyfunction!(_extract_photos, m)?)?;
    Ok(())
}
