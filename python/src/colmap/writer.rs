//! `clatch.colmap._FolderWriter`: the library's one writer of a folder's database and match list,
//! directly at two paths or under temporary names beside a plan's outputs (`clatch.ray`'s driver).

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::Mutex;

use clatch::Match;
use clatch::colmap::{ColmapError, FolderCounts, FolderOutput, FolderWriter as Writer, Photo};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::folder::PinholeCamera;
use super::report::report_out;
use crate::arrays::{keypoints_in, matches_in};
use crate::errors::{Class, OrRaise, raise};

/// Where a writer writes.
enum Writing {
    /// Straight to the two paths given.
    Direct(Box<Writer<BufWriter<File>>>),
    /// Under temporary names, renamed into place by `finish` ([`FolderOutput`]).
    Staged(Box<FolderOutput>),
}

impl Writing {
    fn add_photo(&mut self, photo: &Photo) -> Result<usize, ColmapError> {
        match self {
            Writing::Direct(w) => w.add_photo(photo),
            Writing::Staged(w) => w.add_photo(photo),
        }
    }

    fn add_matches(&mut self, i: usize, j: usize, matches: &[Match]) -> Result<(), ColmapError> {
        match self {
            Writing::Direct(w) => w.add_matches(i, j, matches),
            Writing::Staged(w) => w.add_matches(i, j, matches),
        }
    }

    fn counts(&self) -> FolderCounts {
        match self {
            Writing::Direct(w) => w.counts(),
            Writing::Staged(w) => w.counts(),
        }
    }
}

/// Not public API (the tests, and ``clatch.ray`` through ``_FolderPlan.open_writer``): the library's
/// one writer of a folder's database and match list (``clatch::colmap::FolderWriter``).
///
/// _FolderWriter(database, match_list, camera=None)
#[pyclass(module = "clatch.colmap", frozen, name = "_FolderWriter")]
pub struct FolderWriter {
    inner: Mutex<Option<Writing>>,
}

impl FolderWriter {
    /// A writer of `output`, a plan's temporary files.
    pub fn staged(output: FolderOutput) -> Self {
        Self {
            inner: Mutex::new(Some(Writing::Staged(Box::new(output)))),
        }
    }

    /// Runs `f` on the open writer, or raises when it is finished or closed.
    fn with<T>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Writing) -> Result<T, ColmapError>,
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
        Class::InvalidInput,
        "WriterClosed",
        "the COLMAP writer is already finished or closed".into(),
    )
}

fn list_error(py: Python<'_>, e: impl std::fmt::Display) -> PyErr {
    raise(
        py,
        Class::Database,
        "MatchListIo",
        format!("cannot write the match list: {e}"),
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
                Class::Database,
                "MatchListIo",
                format!("cannot write {}: {e}", match_list.display()),
            )
        })?;
        let writer = Writer::create(
            &database,
            Some(BufWriter::new(list)),
            camera.map(|c| &c.inner),
        )
        .or_raise(py)?;
        Ok(Self {
            inner: Mutex::new(Some(Writing::Direct(Box::new(writer)))),
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
        let photo = Photo::new(name, width, height, keypoints_in(keypoints, "keypoints")?)
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
        self.with(py, |w| Ok(w.counts().photos))
    }

    /// finish() -> dict or None
    ///
    /// Commits the database and writes the match list to disk; a plan's writer then renames both
    /// into place and returns what ``match_folder`` reports (paths, counts, ``stage_seconds``).
    fn finish<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let writer = self
            .inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .ok_or_else(|| closed(py))?;
        match writer {
            Writing::Staged(output) => {
                let report = output.finish().and_then(|w| w.commit()).or_raise(py)?;
                Ok(Some(report_out(py, &report)?))
            }
            Writing::Direct(writer) => {
                // A direct writer always has its match list.
                if let Some(list) = writer.finish().or_raise(py)? {
                    let file = list.into_inner().map_err(|e| list_error(py, e.error()))?;
                    file.sync_all().map_err(|e| list_error(py, e))?;
                }
                Ok(None)
            }
        }
    }

    /// close()
    ///
    /// Drops an unfinished writer: a plan's writer removes its temporary files; a direct one leaves
    /// the database with its tables but no row.
    fn close(&self) {
        self.inner.lock().unwrap_or_else(|p| p.into_inner()).take();
    }
}
