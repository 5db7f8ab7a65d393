//! `clatch.verify_pair` and `clatch.verify_pairs`: the library's geometric verification
//! (`clatch::verify`, COLMAP 3.8's two-view geometry) on numpy arrays.

use clatch::verify::{self, Camera, GeometryConfig, Intrinsics, VerifyConfig, ViewPair};
use clatch::{KeyPoint, Match, Verifier};
use numpy::ndarray::Ix2;
use numpy::{
    Element, IntoPyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::args::typed;
use crate::arrays::{KeyPointRecord, MatchRecord, keypoints_in, matches_in, ndarray, shape_text};
use crate::backend::{backend_error, parse_backend};
use crate::errors::{compute, invalid_input};

/// The options `verify_pair` and `verify_pairs` take, each a `VerifyConfig` field.
const OPTIONS: &str = "max_error, confidence, trials_multiplier, min_num_trials, max_num_trials, \
min_inlier_ratio, min_num_inliers, min_e_f_inlier_ratio, max_h_inlier_ratio, detect_watermark, \
watermark_min_inlier_ratio, watermark_border_size, seed, planar_keeps_homography_inliers, \
neighbour_consistency";

/// The verification settings of `options` (keywords), on top of COLMAP 3.8's defaults
/// (`VerifyConfig::default`): each checked for its type here, for its range by the library.
fn config_of(options: Option<&Bound<'_, PyDict>>) -> PyResult<VerifyConfig> {
    let mut config = VerifyConfig::default();
    let Some(options) = options else {
        return Ok(config);
    };
    for (key, value) in options.iter() {
        let name: String = typed(&key, "option name", "a str")?;
        let v = &value;
        match name.as_str() {
            "max_error" => config.max_error = typed(v, "max_error", "a float")?,
            "confidence" => config.confidence = typed(v, "confidence", "a float")?,
            "trials_multiplier" => {
                config.trials_multiplier = typed(v, "trials_multiplier", "a float")?
            }
            "min_num_trials" => config.min_num_trials = typed(v, "min_num_trials", "an int >= 0")?,
            "max_num_trials" => config.max_num_trials = typed(v, "max_num_trials", "an int >= 1")?,
            "min_inlier_ratio" => {
                config.min_inlier_ratio = typed(v, "min_inlier_ratio", "a float")?
            }
            "min_num_inliers" => {
                config.min_num_inliers = typed(v, "min_num_inliers", "an int >= 0")?
            }
            "min_e_f_inlier_ratio" => {
                config.min_e_f_inlier_ratio = typed(v, "min_e_f_inlier_ratio", "a float")?
            }
            "max_h_inlier_ratio" => {
                config.max_h_inlier_ratio = typed(v, "max_h_inlier_ratio", "a float")?
            }
            "detect_watermark" => config.detect_watermark = typed(v, "detect_watermark", "a bool")?,
            "watermark_min_inlier_ratio" => {
                config.watermark_min_inlier_ratio =
                    typed(v, "watermark_min_inlier_ratio", "a float")?
            }
            "watermark_border_size" => {
                config.watermark_border_size = typed(v, "watermark_border_size", "a float")?
            }
            "seed" => config.seed = typed(v, "seed", "an int >= 0")?,
            "planar_keeps_homography_inliers" => {
                config.planar_keeps_homography_inliers =
                    typed(v, "planar_keeps_homography_inliers", "a bool")?
            }
            "neighbour_consistency" => {
                let on: bool = typed(v, "neighbour_consistency", "a bool")?;
                config.neighbour_consistency = on.then(verify::NeighbourConsistency::default);
            }
            other => {
                return Err(invalid_input(
                    key.py(),
                    "UnknownOption",
                    format!("no verification option {other:?}; the options are {OPTIONS}"),
                ));
            }
        }
    }
    Ok(config)
}

/// Keypoints of one image: a `KEYPOINT_DTYPE` array (the extractor's) or an (N, 2) `float32` array
/// of positions (x, y), clatch's pixel convention (pixel centres at integers).
fn keypoints_arg(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<KeyPoint>> {
    let py = obj.py();
    let array = ndarray(obj, what)?;
    let dtype = array.dtype();
    if dtype.is_equiv_to(&KeyPointRecord::get_dtype(py)) {
        return keypoints_in(obj, what);
    }
    let shape = array.shape();
    let positions = dtype.is_equiv_to(&numpy::dtype::<f32>(py));
    if !positions || shape.len() != 2 || shape[1] != 2 {
        return Err(invalid_input(
            py,
            if positions {
                "WrongShape"
            } else {
                "WrongDtype"
            },
            format!(
                "{what} must be an (N, 2) float32 array of positions or a clatch.KEYPOINT_DTYPE \
                 array, got {dtype} of shape {}",
                shape_text(shape)
            ),
        ));
    }
    let typed = array
        .cast::<PyArrayDyn<f32>>()?
        .try_readonly()
        .map_err(|e| invalid_input(py, "ArrayBorrowed", format!("{what}: {e}")))?;
    let view = typed
        .as_array()
        .into_dimensionality::<Ix2>()
        .map_err(|e| invalid_input(py, "WrongShape", e.to_string()))?;
    Ok(view
        .outer_iter()
        .map(|row| KeyPoint::new(row[0], row[1]))
        .collect())
}

/// Matches of a pair: a `MATCH_DTYPE` array (the matcher's) or an (M, 2) integer array of
/// `(query, train)` indices.
fn matches_arg(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Match>> {
    let py = obj.py();
    let array = ndarray(obj, what)?;
    let dtype = array.dtype();
    if dtype.is_equiv_to(&MatchRecord::get_dtype(py)) {
        return matches_in(obj, what);
    }
    let shape = array.shape().to_vec();
    let integer = matches!(dtype.kind(), b'i' | b'u');
    if !integer || shape.len() != 2 || shape[1] != 2 {
        return Err(invalid_input(
            py,
            if integer { "WrongShape" } else { "WrongDtype" },
            format!(
                "{what} must be a clatch.MATCH_DTYPE array or an (M, 2) integer array of \
                 (query, train) indices, got {dtype} of shape {}",
                shape_text(&shape)
            ),
        ));
    }
    // Every integer dtype fits in i128 but uint64's top half in int64: read through Python's
    // integers only for uint64, as int64 otherwise.
    let wide = if dtype.kind() == b'u' && dtype.itemsize() == 8 {
        "uint64"
    } else {
        "int64"
    };
    let converted = obj.call_method1("astype", (wide,))?;
    let index = |value: i128, row: usize, column: &str| -> PyResult<u32> {
        u32::try_from(value).map_err(|_| {
            invalid_input(
                py,
                "IndexOutOfRange",
                format!("{what}[{row}] has {column} index {value}; indices are 0 to 2^32 - 1"),
            )
        })
    };
    let shape_error =
        |e: numpy::ndarray::ShapeError| invalid_input(py, "WrongShape", e.to_string());
    let rows: Vec<(i128, i128)> = if wide == "uint64" {
        let typed = converted.cast::<PyArrayDyn<u64>>()?.readonly();
        let view = typed
            .as_array()
            .into_dimensionality::<Ix2>()
            .map_err(shape_error)?;
        view.outer_iter()
            .map(|r| (i128::from(r[0]), i128::from(r[1])))
            .collect()
    } else {
        let typed = converted.cast::<PyArrayDyn<i64>>()?.readonly();
        let view = typed
            .as_array()
            .into_dimensionality::<Ix2>()
            .map_err(shape_error)?;
        view.outer_iter()
            .map(|r| (i128::from(r[0]), i128::from(r[1])))
            .collect()
    };
    rows.into_iter()
        .enumerate()
        .map(|(row, (query, train))| {
            Ok(Match {
                query: index(query, row, "query")?,
                train: index(train, row, "train")?,
                distance: 0,
            })
        })
        .collect()
}

/// A camera: `None`, `(width, height)` (the watermark test), or `(width, height, K)` with `K` a
/// 3 x 3 pinhole matrix in clatch's pixel convention (calibrated verification when both have one).
fn camera_arg(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Option<Camera>> {
    let py = obj.py();
    if obj.is_none() {
        return Ok(None);
    }
    let expected = "None, (width, height) or (width, height, K) with K a 3 x 3 matrix";
    let parts: Vec<Bound<'_, PyAny>> = typed(obj, what, expected)?;
    if !(2..=3).contains(&parts.len()) {
        return Err(invalid_input(
            py,
            "InvalidCamera",
            format!("{what} must be {expected}, got {} items", parts.len()),
        ));
    }
    let width: u32 = typed(&parts[0], what, "an int width in 0..2^32")?;
    let height: u32 = typed(&parts[1], what, "an int height in 0..2^32")?;
    let camera = Camera::new(width, height);
    let Some(k) = parts.get(2) else {
        return Ok(Some(camera));
    };
    let k: [[f64; 3]; 3] = typed(k, what, "a 3 x 3 matrix K of floats")?;
    if k[0][1] != 0.0 || k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
        return Err(invalid_input(
            py,
            "InvalidCamera",
            format!(
                "{what}'s K must be a pinhole matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {k:?}"
            ),
        ));
    }
    Ok(Some(camera.with_intrinsics(Intrinsics::new(
        k[0][0], k[1][1], k[0][2], k[1][2],
    ))))
}

/// `key=`: a pair's sampler key.
fn sampler_key(obj: &Bound<'_, PyAny>) -> PyResult<u64> {
    typed(obj, "key", "an int >= 0")
}

/// One pair's inputs, copied out of the arrays.
struct PairInput {
    keypoints_a: Vec<KeyPoint>,
    keypoints_b: Vec<KeyPoint>,
    matches: Vec<Match>,
    cameras: Option<(Camera, Camera)>,
    key: u64,
}

impl PairInput {
    #[allow(clippy::too_many_arguments)]
    fn new(
        keypoints_a: &Bound<'_, PyAny>,
        keypoints_b: &Bound<'_, PyAny>,
        matches: &Bound<'_, PyAny>,
        camera_a: Option<&Bound<'_, PyAny>>,
        camera_b: Option<&Bound<'_, PyAny>>,
        key: u64,
        prefix: &str,
    ) -> PyResult<Self> {
        let py = keypoints_a.py();
        let camera = |obj: Option<&Bound<'_, PyAny>>, what: &str| match obj {
            Some(obj) => camera_arg(obj, &format!("{prefix}{what}")),
            None => Ok(None),
        };
        let cameras = match (camera(camera_a, "camera_a")?, camera(camera_b, "camera_b")?) {
            (Some(a), Some(b)) => Some((a, b)),
            (None, None) => None,
            _ => {
                return Err(invalid_input(
                    py,
                    "InvalidCamera",
                    format!("{prefix}give both cameras or neither"),
                ));
            }
        };
        Ok(Self {
            keypoints_a: keypoints_arg(keypoints_a, &format!("{prefix}keypoints_a"))?,
            keypoints_b: keypoints_arg(keypoints_b, &format!("{prefix}keypoints_b"))?,
            matches: matches_arg(matches, &format!("{prefix}matches"))?,
            cameras,
            key,
        })
    }

    fn view(&self) -> ViewPair<'_> {
        let pair =
            ViewPair::new(&self.keypoints_a, &self.keypoints_b, &self.matches).with_key(self.key);
        match &self.cameras {
            Some((a, b)) => pair.with_cameras(a, b),
            None => pair,
        }
    }
}

/// The geometry of a verified pair (``verify_pair``), as COLMAP 3.8's ``TwoViewGeometry::Estimate``
/// reports it: ``config`` (``"degenerate"``, ``"calibrated"``, ``"uncalibrated"``,
/// ``"planar_or_panoramic"``, ``"watermark"``, ...) and ``config_code`` (COLMAP's integer), ``F``,
/// ``E`` (calibrated pairs) and ``H`` as 3 x 3 ``float64`` arrays (``None`` where not estimated;
/// row-major, acting on clatch's pixel coordinates, ``b^T F a = 0``, ``b ~ H a``), ``inliers`` (the
/// indices into the pair's matches of the chosen model's inliers, ascending, ``uint32``),
/// ``num_inliers``, and ``inlier_counts`` (each model's, ``{"E": .., "F": .., "H": ..}``).
#[pyclass(module = "clatch", frozen, name = "TwoViewGeometry")]
pub struct TwoViewGeometry {
    inner: verify::TwoViewGeometry,
}

/// Python's name of a configuration.
fn config_name(config: GeometryConfig) -> &'static str {
    match config {
        GeometryConfig::Undefined => "undefined",
        GeometryConfig::Degenerate => "degenerate",
        GeometryConfig::Calibrated => "calibrated",
        GeometryConfig::Uncalibrated => "uncalibrated",
        GeometryConfig::Planar => "planar",
        GeometryConfig::Panoramic => "panoramic",
        GeometryConfig::PlanarOrPanoramic => "planar_or_panoramic",
        GeometryConfig::Watermark => "watermark",
        GeometryConfig::Multiple => "multiple",
    }
}

fn matrix_out<'py>(
    py: Python<'py>,
    m: Option<[[f64; 3]; 3]>,
) -> PyResult<Option<Bound<'py, PyAny>>> {
    m.map(|m| {
        let flat: Vec<f64> = m.iter().flatten().copied().collect();
        Ok(flat.into_pyarray(py).reshape([3, 3])?.into_any())
    })
    .transpose()
}

#[pymethods]
impl TwoViewGeometry {
    /// COLMAP's name of the configuration, in snake case.
    #[getter]
    fn config(&self) -> &'static str {
        config_name(self.inner.config)
    }

    /// COLMAP 3.8's integer for the configuration (the ``config`` column of ``two_view_geometries``).
    #[getter]
    fn config_code(&self) -> i32 {
        self.inner.config.colmap_code()
    }

    /// The fundamental matrix, or ``None``.
    #[getter(F)]
    fn f<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        matrix_out(py, self.inner.f)
    }

    /// The essential matrix (both cameras with K), or ``None``.
    #[getter(E)]
    fn e<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        matrix_out(py, self.inner.e)
    }

    /// The homography, or ``None``.
    #[getter(H)]
    fn h<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        matrix_out(py, self.inner.h)
    }

    /// Indices into the pair's matches of the inliers, ascending.
    #[getter]
    fn inliers<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.inner.inliers.clone().into_pyarray(py).into_any()
    }

    /// How many inliers (``len(inliers)``).
    #[getter]
    fn num_inliers(&self) -> usize {
        self.inner.inliers.len()
    }

    /// Inliers of each model RANSAC found: ``{"E": .., "F": .., "H": ..}`` (0: not estimated).
    #[getter]
    fn inlier_counts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let counts = self.inner.inlier_counts;
        let out = PyDict::new(py);
        out.set_item("E", counts.e)?;
        out.set_item("F", counts.f)?;
        out.set_item("H", counts.h)?;
        Ok(out)
    }

    fn __repr__(&self) -> String {
        format!(
            "TwoViewGeometry(config={:?}, num_inliers={})",
            self.config(),
            self.num_inliers()
        )
    }
}

/// verify_pair(keypoints_a, keypoints_b, matches, camera_a=None, camera_b=None, *, key=0, **options) -> TwoViewGeometry
///
/// The two-view geometry COLMAP 3.8 would find for one pair of images (``clatch::verify``, on the
/// CPU, with the GIL released): a fundamental matrix, an essential matrix when both cameras have a
/// K, a homography, each by LO-RANSAC, and COLMAP's rules to choose among them.
///
/// - ``keypoints_a``, ``keypoints_b``: each image's keypoints, an (N, 2) ``float32`` array of
///   positions (x, y; pixel centres at integers) or a ``KEYPOINT_DTYPE`` array.
/// - ``matches``: a ``MATCH_DTYPE`` array (``Matcher.match``) or an (M, 2) integer array of
///   ``(query, train)`` indices (``query`` into ``keypoints_a``).
/// - ``camera_a``, ``camera_b``: both or neither; ``(width, height)`` (the watermark test) or
///   ``(width, height, K)`` with ``K`` a 3 x 3 pinhole matrix (calibrated when both have one).
/// - ``key``: the pair's sampler key (with ``seed``, it fixes every random sample).
/// - ``options``: ``VerifyConfig`` fields, COLMAP's defaults otherwise: ``max_error`` (4 px),
///   ``confidence``, ``trials_multiplier``, ``min_num_trials``, ``max_num_trials``,
///   ``min_inlier_ratio``, ``min_num_inliers`` (15), ``min_e_f_inlier_ratio``,
///   ``max_h_inlier_ratio``, ``detect_watermark``, ``watermark_min_inlier_ratio``,
///   ``watermark_border_size``, ``seed``, ``planar_keeps_homography_inliers`` (``True``),
///   ``neighbour_consistency`` (``False``; ``True`` is the folder run's filter).
///
/// Raises ``InvalidInputError`` for a wrong dtype or shape, an unknown option or one out of range,
/// a match naming a keypoint that is not there, a matched keypoint at a non-finite position, or a
/// bad camera; ``ArgumentTypeError`` for an option of the wrong type.
#[pyfunction]
#[pyo3(signature = (keypoints_a, keypoints_b, matches, camera_a = None, camera_b = None, *, key = 0, **options))]
#[allow(clippy::too_many_arguments)]
pub fn verify_pair(
    py: Python<'_>,
    keypoints_a: &Bound<'_, PyAny>,
    keypoints_b: &Bound<'_, PyAny>,
    matches: &Bound<'_, PyAny>,
    camera_a: Option<&Bound<'_, PyAny>>,
    camera_b: Option<&Bound<'_, PyAny>>,
    #[pyo3(from_py_with = sampler_key)] key: u64,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<TwoViewGeometry> {
    let config = config_of(options)?;
    let pair = PairInput::new(
        keypoints_a,
        keypoints_b,
        matches,
        camera_a,
        camera_b,
        key,
        "",
    )?;
    let inner = compute(py, || pair.view().verify(&config))?;
    Ok(TwoViewGeometry { inner })
}

/// verify_pairs(pairs, *, keys=None, backend="cpu", **options) -> list[TwoViewGeometry]
///
/// ``verify_pair`` of many pairs, with the GIL released: side by side on the CPU's threads, or with
/// ``backend="cuda"`` (``"cuda:N"``, ``"auto"``) a whole batch per launch on the GPU, the same
/// geometries bit for bit. Each result equals ``verify_pair`` of that pair (with its key) whatever the
/// batch and the backend. ``pairs``: a sequence of ``(keypoints_a, keypoints_b, matches)`` or
/// ``(keypoints_a, keypoints_b, matches, camera_a, camera_b)``; ``keys``: one sampler key per pair
/// (default 0 each); ``options`` as for ``verify_pair``. Every pair is checked before any work; an
/// error names the pair.
#[pyfunction]
#[pyo3(signature = (pairs, *, keys = None, backend = "cpu", **options))]
pub fn verify_pairs(
    py: Python<'_>,
    pairs: &Bound<'_, PyAny>,
    keys: Option<&Bound<'_, PyAny>>,
    backend: &str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Vec<TwoViewGeometry>> {
    let config = config_of(options)?;
    let backend = parse_backend(py, backend)?;
    let verifier = Verifier::new(backend, config).map_err(|e| backend_error(py, e))?;
    let expected = "a sequence of (keypoints_a, keypoints_b, matches[, camera_a, camera_b])";
    let pairs: Vec<Bound<'_, PyAny>> = typed(pairs, "pairs", expected)?;
    let keys: Vec<u64> = match keys {
        None => vec![0; pairs.len()],
        Some(keys) if keys.is_none() => vec![0; pairs.len()],
        Some(keys) => typed(keys, "keys", "a sequence of ints >= 0")?,
    };
    if keys.len() != pairs.len() {
        return Err(invalid_input(
            py,
            "WrongLength",
            format!("{} keys for {} pairs", keys.len(), pairs.len()),
        ));
    }
    let inputs = pairs
        .iter()
        .zip(&keys)
        .enumerate()
        .map(|(index, (pair, &key))| {
            let parts = pair
                .cast::<PyTuple>()
                .map(|t| t.iter().collect::<Vec<_>>())
                .or_else(|_| typed::<Vec<Bound<'_, PyAny>>>(pair, "pairs", expected))?;
            let prefix = format!("pairs[{index}]: ");
            match parts.as_slice() {
                [a, b, m] => PairInput::new(a, b, m, None, None, key, &prefix),
                [a, b, m, ca, cb] => PairInput::new(a, b, m, Some(ca), Some(cb), key, &prefix),
                _ => Err(invalid_input(
                    py,
                    "WrongLength",
                    format!("{prefix}a pair has 3 or 5 items, got {}", parts.len()),
                )),
            }
        })
        .collect::<PyResult<Vec<PairInput>>>()?;
    let geometries = compute(py, || {
        let views: Vec<ViewPair<'_>> = inputs.iter().map(PairInput::view).collect();
        verifier.verify_pairs(&views)
    })?;
    Ok(geometries
        .into_iter()
        .map(|inner| TwoViewGeometry { inner })
        .collect())
}
