//! `clatch.Matcher`: brute-force Hamming matching.

use clatch::{DescriptorSet, MatchConfig};
use numpy::ndarray::Ix2;
use numpy::{IntoPyArray, PyArrayDescrMethods};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};

use crate::args;
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
/// they compute. A pair that cannot match (no query, or fewer gallery descriptors than the rules look
/// at) gives no matches in ``match`` as in ``match_pairs``. A Matcher pickles (the same settings and
/// backend).
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
        signature = (backend = "cpu".to_string(), ratio = Some(0.8), cross_check = true, max_distance = None),
        text_signature = "(backend='cpu', ratio=0.8, cross_check=True, max_distance=None)"
    )]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = args::backend)] backend: String,
        #[pyo3(from_py_with = args::ratio)] ratio: Option<f32>,
        #[pyo3(from_py_with = args::cross_check)] cross_check: bool,
        #[pyo3(from_py_with = args::max_distance)] max_distance: Option<i64>,
    ) -> PyResult<Self> {
        let backend = parse_backend(py, &backend)?;
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

    /// Pickling: an equal matcher on the same backend (``Matcher(backend, ratio, cross_check,
    /// max_distance)``), for ``multiprocessing``, Ray and ``copy``.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let this = slf.get();
        let args = (
            this.backend(),
            this.ratio(),
            this.cross_check(),
            this.max_distance(),
        );
        PyTuple::new(
            py,
            [
                slf.get_type().into_any(),
                args.into_pyobject(py)?.into_any(),
            ],
        )
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
    /// A pair that cannot match (no query, or fewer gallery descriptors than the rules look at: none,
    /// or one with the ratio test; the library's ``MatchConfig::can_match``) gives no matches, as in
    /// ``match_pairs``: a blank frame is data, not an error.
    #[pyo3(name = "match")]
    fn match_<'py>(
        &self,
        py: Python<'py>,
        query: &Bound<'py, PyAny>,
        train: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let query = descriptors_in(query, "query")?;
        let train = descriptors_in(train, "train")?;
        let config = self.inner.config();
        if query.width() == train.width() && !config.can_match(query.len(), train.len()) {
            return Ok(matches_out(py, Vec::new()).into_any());
        }
        let matches = compute(py, || self.inner.match_descriptors(&query, &train))?;
        Ok(matches_out(py, matches).into_any())
    }

    /// knn(query, train, k) -> neighbours
    ///
    /// The ``k`` nearest gallery descriptors of every query, nearest first, ties to the lowest index
    /// (no ratio test, cross-check or distance limit): a ``MATCH_DTYPE`` array of shape (N, k).
    /// ``1 <= k <= len(train)``, an empty gallery included (``k`` names more neighbours than there
    /// are: ``InvalidK``); the CUDA backend returns at most 8 neighbours.
    fn knn<'py>(
        &self,
        py: Python<'py>,
        query: &Bound<'py, PyAny>,
        train: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = args::k)] k: i64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let query = descriptors_in(query, "query")?;
        let train = descriptors_in(train, "train")?;
        let gallery = train.len();
        let k = match usize::try_from(k) {
            Ok(k) if query.width() != train.width() || (1..=gallery).contains(&k) => k,
            // k itself is what is wrong (the library would call an empty gallery EmptyGallery).
            _ => {
                return Err(invalid_input(
                    py,
                    "InvalidK",
                    format!(
                        "k = {k} is invalid for a gallery of {gallery} descriptors \
                         (need 1 <= k <= gallery)"
                    ),
                ));
            }
        };
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
    /// (``all_pairs(n)``). A pair that cannot match (no query, or too small a gallery) gets no
    /// matches, as in ``match``; every index and width is checked before any work. The CPU spreads
    /// the pairs over its threads, CUDA uploads each set once and matches many pairs per kernel
    /// launch.
    fn match_pairs<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = args::descriptors)] descriptors: Vec<Bound<'py, PyAny>>,
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
    /// ``int64`` array of shape (n (n - 1) / 2, 2) for ``match_pairs``. At most ``MAX_PAIRS`` pairs
    /// (2 GiB; ``n`` up to 16384): more raise ``InvalidInputError`` (kind ``TooManyPairs``) before
    /// anything is allocated.
    #[staticmethod]
    fn all_pairs(
        py: Python<'_>,
        #[pyo3(from_py_with = args::n)] n: i64,
    ) -> PyResult<Bound<'_, PyAny>> {
        let n = usize::try_from(n)
            .map_err(|_| invalid_input(py, "InvalidInput", format!("n must be >= 0, got {n}")))?;
        let count = n
            .checked_mul(n.saturating_sub(1))
            .map(|twice| twice / 2)
            .filter(|&count| count <= MAX_PAIRS);
        let Some(count) = count else {
            return Err(invalid_input(
                py,
                "TooManyPairs",
                format!(
                    "n = {n} sets have {} pairs, more than the {MAX_PAIRS} (2 GiB as int64) \
                     all_pairs lists; pass the pairs you need to match_pairs",
                    n as u128 * (n as u128).saturating_sub(1) / 2
                ),
            ));
        };
        let flat = py.detach(|| {
            let mut flat = Vec::with_capacity(2 * count);
            for i in 0..n as i64 {
                for j in i + 1..n as i64 {
                    flat.extend_from_slice(&[i, j]);
                }
            }
            flat
        });
        Ok(flat.into_pyarray(py).reshape([count, 2])?.into_any())
    }
}

/// The most pairs `all_pairs` lists: 2^27, 2 GiB as an int64 (P, 2) array (16384 sets have
/// 134 209 536 pairs).
pub const MAX_PAIRS: usize = 1 << 27;
