//! `clatch.colmap._FolderJob`: the library's one folder run (`clatch::colmap::FolderJob`), which
//! `clatch.colmap.match_folder` runs whole and `clatch.ray` runs in stages (its workers' extraction
//! and matching, its driver's `_FolderPlan` and writer).

use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::PathBuf;

use clatch::DescriptorSet;
use clatch::colmap::{FolderCamera, FolderProgress, FolderStage, Overwrite, PhotoRef};
use clatch::decode::DecodeLimits;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

use super::folder::{check_lengths, photos_out, refinement};
use super::report::report_out;
use super::writer::FolderWriter;
use crate::arrays::{descriptors_in, matches_out};
use crate::errors::compute_with;
use crate::extractor::Extractor;
use crate::matcher::Matcher;

/// A photo of a pair: its index or its name.
#[derive(FromPyObject)]
enum PhotoArg {
    Index(usize),
    Name(String),
}

impl From<PhotoArg> for PhotoRef {
    fn from(photo: PhotoArg) -> Self {
        match photo {
            PhotoArg::Index(i) => PhotoRef::Index(i),
            PhotoArg::Name(name) => PhotoRef::Name(name),
        }
    }
}

/// Not public API (``clatch.colmap.match_folder`` and ``clatch.ray`` build it): the library's
/// description of a folder run, ``clatch::colmap::FolderJob``.
///
/// _FolderJob(images, database, *, extractor, matcher, workspace=None, pairs=None, camera_k=None,
///            camera_k_file=None, subpixel="score", subpixel_radius=3, max_pixels=100_000_000,
///            force=False, verify=True, match_list=False)
///
/// ``extractor`` and ``matcher`` give the settings and the backend (the detector's sub-pixel method
/// is ``subpixel``'s); ``pairs``: ``(a, b)`` of photo indices or names; ``camera_k``: the text of
/// K, read from ``camera_k_file`` if that is given; ``verify``: the library's verification
/// (``FolderJob::default_verification``), else none; ``match_list``: the match list written with
/// verification too.
#[pyclass(module = "clatch.colmap", frozen, name = "_FolderJob")]
pub struct FolderJob {
    inner: clatch::colmap::FolderJob,
}

/// Python's name of a stage (`progress(stage, done, total)`).
fn stage_name(stage: FolderStage) -> &'static str {
    match stage {
        FolderStage::Extraction => "extract",
        FolderStage::Matching => "match",
        _ => "other",
    }
}

/// Calls `progress(stage, done, total)`, then lets Python handle a signal (Ctrl-C) that came
/// meanwhile: an exception of either stops the run.
fn tell(py: Python<'_>, progress: Option<&Py<PyAny>>, p: FolderProgress) -> PyResult<()> {
    if let Some(progress) = progress {
        progress.call1(py, (stage_name(p.stage), p.done, p.total))?;
    }
    py.check_signals()
}

#[pymethods]
impl FolderJob {
    #[new]
    #[pyo3(signature = (
        images,
        database,
        *,
        extractor,
        matcher,
        workspace = None,
        pairs = None,
        camera_k = None,
        camera_k_file = None,
        subpixel = "score",
        subpixel_radius = 3,
        max_pixels = 100_000_000,
        force = false,
        verify = true,
        match_list = false,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        images: PathBuf,
        database: PathBuf,
        extractor: &Extractor,
        matcher: &Matcher,
        workspace: Option<PathBuf>,
        pairs: Option<Vec<(PhotoArg, PhotoArg)>>,
        camera_k: Option<String>,
        camera_k_file: Option<PathBuf>,
        subpixel: &str,
        subpixel_radius: i64,
        max_pixels: u64,
        force: bool,
        verify: bool,
        match_list: bool,
    ) -> PyResult<Self> {
        let mut job = clatch::colmap::FolderJob::new(images, database)
            .with_backend(extractor.inner.backend())
            .with_extractor(extractor.inner.config().clone())
            .with_matching(matcher.inner.config().clone())
            .with_refinement(refinement(py, subpixel, subpixel_radius)?)
            .with_limits(DecodeLimits::default().with_max_pixels(max_pixels))
            .with_overwrite(if force {
                Overwrite::Replace
            } else {
                Overwrite::Refuse
            });
        if let Some(workspace) = workspace {
            job = job.with_workspace(workspace);
        }
        if !verify {
            job = job.without_verification();
        }
        job = job.with_match_list_written(match_list);
        if let Some(pairs) = pairs {
            job = job.with_pairs(pairs);
        }
        if let Some(text) = camera_k {
            job = job.with_camera(FolderCamera::KText {
                text,
                file: camera_k_file,
            });
        }
        Ok(Self { inner: job })
    }

    /// run(progress=None) -> dict
    ///
    /// The whole run (``clatch::colmap::FolderJob::run``), with the GIL released; what
    /// ``MatchFolderResult`` reports. ``progress(stage, done, total)``, with ``stage`` ``"extract"``
    /// or ``"match"``: ``done = 0`` as each stage starts, then after every photo and every group of
    /// pairs; an exception it raises (or a KeyboardInterrupt meanwhile) stops the run, leaves nothing
    /// at the outputs and is raised.
    #[pyo3(signature = (progress = None))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut stopped_by: Option<PyErr> = None;
        let result = {
            let stopped_by = &mut stopped_by;
            let mut progress = |p: FolderProgress| {
                Python::attach(|py| match tell(py, progress.as_ref(), p) {
                    Ok(()) => ControlFlow::Continue(()),
                    Err(e) => {
                        *stopped_by = Some(e);
                        ControlFlow::Break(())
                    }
                })
            };
            compute_with(py, || self.inner.run(Some(&mut progress)))
        };
        match (result, stopped_by) {
            (_, Some(e)) => Err(e),
            (result, None) => report_out(py, &result?),
        }
    }

    /// plan() -> _FolderPlan
    ///
    /// Every check before any work (``clatch::colmap::FolderJob::plan``); writes nothing.
    fn plan(&self, py: Python<'_>) -> PyResult<FolderPlan> {
        let inner = compute_with(py, || self.inner.plan())?;
        Ok(FolderPlan { inner })
    }

    /// extract_photos(paths, names) -> list
    ///
    /// The extraction stage on these photos with the job's settings
    /// (``clatch::colmap::extract_photos``): one ``(name, width, height, focal_35mm, keypoints,
    /// descriptors)`` tuple per photo, in order. Runs with the GIL released.
    fn extract_photos<'py>(
        &self,
        py: Python<'py>,
        paths: Vec<PathBuf>,
        names: Vec<String>,
    ) -> PyResult<Vec<Bound<'py, PyTuple>>> {
        check_lengths(py, &paths, &names)?;
        let job = &self.inner;
        let (photos, _decoding) = compute_with(py, || {
            let extractor = clatch::Extractor::new(job.backend, job.extractor_config())?;
            clatch::colmap::extract_photos(
                &extractor,
                (&paths, &names),
                &job.limits,
                job.refinement,
                &|_| {},
            )
        })?;
        photos_out(py, photos)
    }

    /// match_pairs(descriptors, pairs) -> list
    ///
    /// The matching stage on these pairs of photo indices with the job's settings
    /// (``clatch::colmap::match_photo_pairs``): ``descriptors`` maps each photo the pairs name to its
    /// descriptors. The matches of each pair (``MATCH_DTYPE``), in order. Runs with the GIL released.
    fn match_pairs<'py>(
        &self,
        py: Python<'py>,
        descriptors: &Bound<'py, PyAny>,
        pairs: Vec<(usize, usize)>,
    ) -> PyResult<Bound<'py, PyList>> {
        let mut sets: HashMap<usize, DescriptorSet> = HashMap::new();
        for image in pairs.iter().flat_map(|&(i, j)| [i, j]) {
            if sets.contains_key(&image) {
                continue;
            }
            // A photo missing from the mapping is the library's error (MissingDescriptors).
            if let Ok(array) = descriptors.get_item(image) {
                sets.insert(
                    image,
                    descriptors_in(&array, &format!("descriptors[{image}]"))?,
                );
            }
        }
        let job = &self.inner;
        let found = compute_with(py, || {
            let matcher = clatch::Matcher::new(job.backend, job.matching.clone())?;
            clatch::colmap::match_photo_pairs(&matcher, |i| sets.get(&i), &pairs)
        })?;
        PyList::new(py, found.into_iter().map(|m| matches_out(py, m)))
    }
}

/// Not public API (``clatch.ray``'s driver): a ``_FolderJob`` checked before any work
/// (``clatch::colmap::FolderPlan``): its photos, its pairs, and the writer of its outputs.
#[pyclass(module = "clatch.colmap", frozen, name = "_FolderPlan")]
pub struct FolderPlan {
    inner: clatch::colmap::FolderPlan,
}

#[pymethods]
impl FolderPlan {
    /// The image files, in name order.
    #[getter]
    fn paths(&self) -> Vec<PathBuf> {
        self.inner.folder().paths.clone()
    }

    /// Their names in the database.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.folder().names.clone()
    }

    /// The pairs to match, as ``(i, j)`` photo indices, in the order they are written.
    #[getter]
    fn pairs(&self) -> Vec<(usize, usize)> {
        self.inner.pairs().to_vec()
    }

    fn __len__(&self) -> usize {
        self.inner.folder().paths.len()
    }

    /// open_writer() -> _FolderWriter
    ///
    /// The writer of the job's database and match list under temporary names beside them
    /// (``clatch::colmap::FolderPlan::open_output``): ``finish`` renames them into place, ``close``
    /// removes them.
    fn open_writer(&self, py: Python<'_>) -> PyResult<FolderWriter> {
        let output = compute_with(py, || self.inner.open_output())?;
        Ok(FolderWriter::staged(output))
    }
}
