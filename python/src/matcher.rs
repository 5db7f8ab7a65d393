//! `clatch.Matcher`: brute-force Hamming matching.

use clatch::{DescriptorSet, MatchConfig};
use numpy::ndarray::Ix2;
use numpy::{IntoPyArray, PyArrayDescrMethods};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::arrays::{descriptors_in, matches_out};
use crate::backend::{backend_error, parse_backend};
use crate::errors::{OrRaise, compute, invalid_input};
use crate::extractor::shortest;

/// Brute-force Hamming matcher of descriptors in OpenCV LATCH's byte order.
///
/// Matcher(backend="cpu", ratio=0.8, cross_check=True, max_distance=None)
///
/// ``match`` keeps the nearest gallery descriptor of each query when it passes Lowe's ratio test
/// (``d1 < ratio * d2``, one float32 product; ``ratio=None`` turns it off; otherwise in (0, 1]),
/// the cross-check (the query is also the nearest query of its gallery descriptor; ``cross_check``)
/// and the distance limit (``d1 <= max_distance``; ``None``: none). Ties always go to the lowest
/// index. Matches come back as a structured array of ``MATCH_DTYPE`` (query, train, distance, all
/// ``uint32``) in query order. ``backend`` as for ``Extractor``. The methods release the GIL while
/// they compute.
#[pyclass(module = "clatch", frozen)]
pub struct Matcher {
    pub(crate) inner: clatch::Matcher,
}

/// The pairs of `match_pairs`: a sequence of `(i, j)` or an integer array of shape (P, 2), each index
/// checked against `sets` sets.
fn pairs_in(obj: &Bound<'_, PyAny>, sets: usize) -> PyResult<Vec<(usize, usize)>> {
    let py = obj.py();
    let raw: Vec<(i64, i64)> = if let Ok(array) = obj.cast::<PyUntypedArray>() {
        let kind = array.dtype().kind();
        let shape = array.shape().to_vec();
        if !(kind == b'i' || kind == b'u') || shape.len() != 2 || shape[1] != 2 {
            return Err(invalid_input(
                py,
                "WrongShape",
                format!(
                    "pairs must be an integer array of shape (P, 2), got {} of shape {shape:?}",
                    array.dtype()
                ),
            ));
        }
        let as_i64 = obj.call_method1("astype", ("int64",))?;
        let typed = as_i64.cast::<PyArrayDyn<i64>>()?.readonly();
        let view = typed
            .as_array()
            .into_dimensionality::<Ix2>()
            .map_err(|e| invalid_input(py, "WrongShape", e.to_string()))?;
        view.outer_iter().map(|r| (r[0], r[1])).collect()
    } else {
        // Any sequence of two-element sequences: tuples, lists, 1-D arrays.
        let not_pairs = || {
            invalid_input(
                py,
                "WrongShape",
                "pairs must be a sequence of (i, j) index pairs or an integer array of shape (P, 2)",
            )
        };
        let items: Vec<Bound<'_, PyAny>> = obj.extract().map_err(|_| not_pairs())?;
        items
            .iter()
            .map(|item| match item.extract::<Vec<i64>>().as_deref() {
                Ok(&[a, b]) => Ok((a, b)),
                _ => Err(not_pairs()),
            })
            .collect::<PyResult<_>>()?
    };
    raw.into_iter()
        .enumerate()
        .map(|(p, (a, b))| {
            for index in [a, b] {
                if index < 0 {
                    return Err(invalid_input(
                        py,
                        "PairOutOfRange",
                        format!("pair {p} names set {index}, but there are {sets} sets"),
                    ));
                }
            }
            Ok((a as usize, b as usize))
        })
        .collect()
}

#[pymethods]
impl Matcher {
    #[new]
    #[pyo3(
        signature = (backend = "cpu", ratio = Some(0.8), cross_check = true, max_distance = None),
        text_signature = "(backend='cpu', ratio=0.8, cross_check=True, max_distance=None)"
    )]
    fn new(
        py: Python<'_>,
        backend: &str,
        ratio: Option<f32>,
        cross_check: bool,
        max_distance: Option<i64>,
    ) -> PyResult<Self> {
        let backend = parse_backend(py, backend)?;
        let max_distance = match max_distance {
            Some(d) => Some(u32::try_from(d).or_else(|_| {
                Err(clatch::Error::InvalidConfig {
                    field: "max_distance",
                    value: d.to_string(),
                    reason: "must be a number of bits >= 0",
                })
                .or_raise(py)
            })?),
            None => None,
        };
        let config = MatchConfig::default()
            .with_ratio(ratio)
            .with_cross_check(cross_check)
            .with_max_distance(max_distance);
        let inner = clatch::Matcher::new(backend, config).map_err(|e| backend_error(py, e))?;
        Ok(Self { inner })
    }

    /// The backend: ``"cpu"`` or ``"cuda:N"``.
    #[getter]
    fn backend(&self) -> String {
        self.inner.backend().name()
    }

    /// Lowe's ratio (``None``: no ratio test).
    #[getter]
    fn ratio(&self) -> Option<f64> {
        self.inner.config().ratio.map(shortest)
    }

    /// Whether only mutual nearest neighbours are kept.
    #[getter]
    fn cross_check(&self) -> bool {
        self.inner.config().cross_check
    }

    /// The largest distance kept, in bits (``None``: no limit).
    #[getter]
    fn max_distance(&self) -> Option<u32> {
        self.inner.config().max_distance
    }

    fn __repr__(&self) -> String {
        let c = self.inner.config();
        let opt = |v: Option<String>| v.unwrap_or_else(|| "None".into());
        format!(
            "Matcher({:?}, ratio={}, cross_check={}, max_distance={})",
            self.backend(),
            opt(c.ratio.map(|r| r.to_string())),
            if c.cross_check { "True" } else { "False" },
            opt(c.max_distance.map(|d| d.to_string()))
        )
    }

    /// match(query, train) -> matches
    ///
    /// The best gallery (``train``) match of every query descriptor that passes the ratio test,
    /// cross-check and distance limit, in query order. Both are ``uint8`` arrays of shape
    /// (N, bytes) in OpenCV LATCH's byte order (as ``detect_and_describe`` returns) and of one width.
    /// The ratio test needs at least two gallery descriptors; an empty gallery is an error, an empty
    /// query set gives no matches.
    #[pyo3(name = "match")]
    fn match_<'py>(
        &self,
        py: Python<'py>,
        query: &Bound<'py, PyAny>,
        train: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let query = descriptors_in(query, "query")?;
        let train = descriptors_in(train, "train")?;
        let matches = compute(py, || self.inner.match_descriptors(&query, &train))?;
        Ok(matches_out(py, matches).into_any())
    }

    /// knn(query, train, k) -> neighbours
    ///
    /// The ``k`` nearest gallery descriptors of every query, nearest first, ties to the lowest index
    /// (no ratio test, cross-check or distance limit): a ``MATCH_DTYPE`` array of shape (N, k).
    /// ``1 <= k <= len(train)``; the CUDA backend returns at most 8 neighbours.
    fn knn<'py>(
        &self,
        py: Python<'py>,
        query: &Bound<'py, PyAny>,
        train: &Bound<'py, PyAny>,
        k: i64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let query = descriptors_in(query, "query")?;
        let train = descriptors_in(train, "train")?;
        // A negative k is as invalid as 0: the library's error says so.
        let k = usize::try_from(k).unwrap_or(0);
        let knn = compute(py, || self.inner.knn(&query, &train, k))?;
        let rows = knn.len();
        let k = knn.k();
        Ok(matches_out(py, knn.into_vec())
            .reshape([rows, k])?
            .into_any())
    }

    /// match_pairs(descriptors, pairs) -> list[matches]
    ///
    /// The matches of many pairs in one call: ``pairs[p] = (a, b)`` matches ``descriptors[a]``
    /// (queries) against ``descriptors[b]`` (gallery) exactly as ``match`` does, results in pair
    /// order. ``pairs`` is a sequence of ``(a, b)`` or an integer array of shape (P, 2)
    /// (``all_pairs(n)``). A pair with no query, or too small a gallery, gets no matches rather than
    /// an error; every index and width is checked before any work. The CPU spreads the pairs over its
    /// threads, CUDA uploads each set once and matches many pairs per kernel launch.
    fn match_pairs<'py>(
        &self,
        py: Python<'py>,
        descriptors: Vec<Bound<'py, PyAny>>,
        pairs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyList>> {
        let sets = descriptors
            .iter()
            .enumerate()
            .map(|(i, d)| descriptors_in(d, &format!("descriptors[{i}]")))
            .collect::<PyResult<Vec<DescriptorSet>>>()?;
        let pairs = pairs_in(pairs, sets.len())?;
        let refs: Vec<&DescriptorSet> = sets.iter().collect();
        let all = compute(py, || self.inner.match_pairs(&refs, &pairs))?;
        let out: Vec<_> = all.into_iter().map(|m| matches_out(py, m)).collect();
        PyList::new(py, out)
    }

    /// all_pairs(n) -> pairs
    ///
    /// Every pair ``(i, j)``, ``i < j``, of ``n`` sets in order (0, 1), (0, 2), ..., (1, 2), ...: an
    /// ``int64`` array of shape (n (n - 1) / 2, 2) for ``match_pairs``.
    #[staticmethod]
    fn all_pairs(py: Python<'_>, n: i64) -> PyResult<Bound<'_, PyAny>> {
        let n = usize::try_from(n)
            .map_err(|_| invalid_input(py, "InvalidInput", format!("n must be >= 0, got {n}")))?;
        // More pairs than any array can index is refused rather than run out of memory.
        if n.checked_mul(n.saturating_sub(1))
            .is_none_or(|twice| twice / 2 > isize::MAX as usize / 32)
        {
            return Err(invalid_input(
                py,
                "InvalidInput",
                format!("n = {n} sets have too many pairs to list"),
            ));
        }
        let pairs = clatch::Matcher::all_pairs(n);
        let count = pairs.len();
        let flat: Vec<i64> = pairs
            .into_iter()
            .flat_map(|(i, j)| [i as i64, j as i64])
            .collect();
        Ok(flat.into_pyarray(py).reshape([count, 2])?.into_any())
    }
}
