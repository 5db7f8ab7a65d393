//! `clatch.Extractor`: detection and description.

use clatch::{DescriptorWidth, ExtractorConfig, GrayView, NamedOption, PatchWeights, Pyramid};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyTuple};

use crate::args;
use crate::arrays::{Channels, ImageInput, descriptors_out, keypoints_in, keypoints_out};
use crate::backend::{backend_error, parse_backend};
use crate::errors::{OrRaise, compute, invalid_input, wrong_type};

/// Finds FAST keypoints and computes their 512-bit CLATCH descriptors.
///
/// Extractor(backend="cpu", *, single_scale=False, threshold=None, max_keypoints=None,
///           keypoint_size=None, grid=None, level_budget=None, ranking=None, subpixel=None,
///           pyramid=None, bits=None, smoothing=None, weights=None)
///
/// ``backend`` is ``"cpu"`` (every core), ``"cuda"`` (device 0), ``"cuda:N"`` or ``"auto"`` (CUDA
/// when this build has it and a device is usable, else the CPU). Without ``single_scale`` the
/// settings start from the library's defaults (``ExtractorConfig::default()``: an 8-level pyramid of
/// factor 1.2, 5000 keypoints shared among the levels as ORB shares them, 40-pixel windows,
/// sub-pixel positions); ``single_scale=True`` starts from ``ExtractorConfig::single_scale()``
/// (full resolution only, 64-pixel windows, whole-pixel positions). Every other keyword left at
/// ``None`` keeps the preset's value; given, it replaces it:
///
/// - ``threshold`` (int, 1..=254, default 20): FAST threshold.
/// - ``max_keypoints`` (int >= 1, default 5000): keep at most this many, strongest first, on an
///   image of up to one megapixel; a larger one keeps proportionally more, at most 4 times as many
///   (the library's ``DetectorConfig::budget_pixels``; not with single_scale).
/// - ``keypoint_size`` (float, default 40; 64 with single_scale): side of each keypoint's
///   descriptor window in pixels of its level.
/// - ``grid`` (int, 1..=64, default 1): spread keypoints over a grid x grid division of the image.
/// - ``level_budget`` (``"geometric"`` default, ``"global"`` or ``"area"``): how max_keypoints is
///   shared among pyramid levels.
/// - ``ranking`` (``"fast"`` default, or ``"harris"``): what orders corners.
/// - ``subpixel`` (``"score"`` default, or ``"none"``): sub-pixel positions.
/// - ``pyramid``: ``(levels, scale_factor)``, or ``False`` for full resolution only (default
///   ``(8, 1.2)``; ``False`` with single_scale).
/// - ``bits`` (multiple of 8 in 8..=512, default 512): descriptor width.
/// - ``smoothing`` (``"none"`` default, ``"binomial3"``, ``"binomial5"``): integer smoothing of the
///   image the descriptor samples.
/// - ``weights`` (64 ints, 8x8 row-major): the patch weights (default LATCH's 7x7 patch).
///
/// Invalid settings raise ``InvalidInputError``; an unusable backend ``BackendUnavailableError``.
/// An Extractor can be shared by threads: its methods release the GIL while they compute (and
/// while they copy an image that cannot be read in place). A gray image whose rows are contiguous is
/// read in place meanwhile: do not write to it from another thread during the call. Colour images are
/// RGB unless a call says ``channels="bgr"`` (``cv2.imread``). An Extractor pickles: it is rebuilt
/// from ``backend`` and ``config``.
#[pyclass(module = "clatch", frozen)]
pub struct Extractor {
    pub(crate) inner: clatch::Extractor,
}

/// `value` as an integer in `lo..=hi`, or the library's `InvalidConfig` error for `field` with
/// `reason` (the library's words for that range).
fn int_in(
    py: Python<'_>,
    field: &'static str,
    value: i64,
    (lo, hi): (i64, i64),
    reason: &'static str,
) -> PyResult<i64> {
    if (lo..=hi).contains(&value) {
        return Ok(value);
    }
    Err(clatch::Error::InvalidConfig {
        field,
        value: value.to_string(),
        reason,
    })
    .or_raise(py)
}

/// The value of option `T` named `value` (the library's names), or an `InvalidInputError` (kind
/// `InvalidConfig`) that lists them.
fn named<T: NamedOption>(py: Python<'_>, value: &str) -> PyResult<T> {
    value
        .parse()
        .map_err(|e: clatch::ParseNameError| invalid_input(py, "InvalidConfig", e.to_string()))
}

/// The Python float that prints as `value` does (`1.2`, not `1.2000000476837158`): the shortest
/// decimal that reads back as the same `f32`.
pub fn shortest(value: f32) -> f64 {
    value.to_string().parse().unwrap_or(f64::from(value))
}

/// `pyramid=`: `False` or `(levels, scale_factor)`.
fn parse_pyramid(value: &Bound<'_, PyAny>) -> PyResult<Option<Pyramid>> {
    let py = value.py();
    if let Ok(flag) = value.cast::<PyBool>() {
        if !flag.is_true() {
            return Ok(None);
        }
    } else if let Ok((levels, scale_factor)) = value.extract::<(i64, f32)>() {
        let levels = int_in(py, "pyramid.levels", levels, (1, 32), "must be in 1..=32")? as usize;
        return Ok(Some(Pyramid::new(levels, scale_factor)));
    }
    Err(invalid_input(
        py,
        "InvalidConfig",
        format!(
            "pyramid must be (levels, scale_factor) or False, got {}",
            value.repr().map(|r| r.to_string()).unwrap_or_default()
        ),
    ))
}

impl Extractor {
    /// The image views of `inputs`, each checked by `GrayView::new`.
    fn views<'a>(py: Python<'_>, inputs: &'a [ImageInput<'_>]) -> PyResult<Vec<GrayView<'a>>> {
        inputs
            .iter()
            .map(|i| i.view().or_raise(py))
            .collect::<PyResult<Vec<_>>>()
    }

    /// `(keypoints, descriptors, index)` of a description of the caller's keypoints.
    fn described_out<'py>(
        py: Python<'py>,
        features: clatch::Features,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let index: Vec<i64> = features.keypoint_index.iter().map(|&i| i as i64).collect();
        let index = numpy::IntoPyArray::into_pyarray(index, py);
        let pair = Self::features_out(py, features)?;
        PyTuple::new(py, [pair.get_item(0)?, pair.get_item(1)?, index.into_any()])
    }

    /// `(keypoints, descriptors)` of one image's features.
    fn features_out<'py>(
        py: Python<'py>,
        features: clatch::Features,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let descriptors = descriptors_out(py, &features.descriptors)?;
        let keypoints = keypoints_out(py, features.keypoints);
        PyTuple::new(py, [keypoints.into_any(), descriptors])
    }
}

#[pymethods]
impl Extractor {
    #[new]
    #[pyo3(signature = (
        backend = "cpu".to_string(),
        *,
        single_scale = false,
        threshold = None,
        max_keypoints = None,
        keypoint_size = None,
        grid = None,
        level_budget = None,
        ranking = None,
        subpixel = None,
        pyramid = None,
        bits = None,
        smoothing = None,
        weights = None,
    ),
    text_signature = "(backend='cpu', *, single_scale=False, threshold=None, max_keypoints=None, \
        keypoint_size=None, grid=None, level_budget=None, ranking=None, subpixel=None, pyramid=None, \
        bits=None, smoothing=None, weights=None)")]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = args::backend)] backend: String,
        #[pyo3(from_py_with = args::single_scale)] single_scale: bool,
        #[pyo3(from_py_with = args::threshold)] threshold: Option<i64>,
        #[pyo3(from_py_with = args::max_keypoints)] max_keypoints: Option<i64>,
        #[pyo3(from_py_with = args::keypoint_size)] keypoint_size: Option<f32>,
        #[pyo3(from_py_with = args::grid)] grid: Option<i64>,
        #[pyo3(from_py_with = args::level_budget)] level_budget: Option<String>,
        #[pyo3(from_py_with = args::ranking)] ranking: Option<String>,
        #[pyo3(from_py_with = args::subpixel)] subpixel: Option<String>,
        pyramid: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = args::bits)] bits: Option<i64>,
        #[pyo3(from_py_with = args::smoothing)] smoothing: Option<String>,
        #[pyo3(from_py_with = args::weights)] weights: Option<Vec<i64>>,
    ) -> PyResult<Self> {
        let backend = parse_backend(py, &backend)?;
        let mut config = if single_scale {
            ExtractorConfig::single_scale()
        } else {
            ExtractorConfig::default()
        };
        let detector = &mut config.detector;
        if let Some(t) = threshold {
            detector.threshold = int_in(py, "threshold", t, (1, 254), "must be in 1..=254")? as u8;
        }
        if let Some(n) = max_keypoints {
            let range = (1, i64::MAX);
            detector.max_keypoints =
                int_in(py, "max_keypoints", n, range, "must be at least 1")? as usize;
        }
        if let Some(size) = keypoint_size {
            detector.keypoint_size = size;
        }
        if let Some(g) = grid {
            detector.grid = int_in(py, "grid", g, (1, 64), "must be in 1..=64")? as usize;
        }
        if let Some(b) = level_budget {
            detector.level_budget = named(py, &b)?;
        }
        if let Some(r) = ranking {
            detector.ranking = named(py, &r)?;
        }
        if let Some(s) = subpixel {
            detector.subpixel = named(py, &s)?;
        }
        if let Some(p) = pyramid {
            config.pyramid = parse_pyramid(p)?;
        }
        let descriptor = &mut config.descriptor;
        if let Some(b) = bits {
            let reason = "must be a multiple of 8 between 8 and 512";
            let b = int_in(py, "bits", b, (0, 4096), reason)? as usize;
            descriptor.width = DescriptorWidth::from_bits(b).or_raise(py)?;
        }
        if let Some(s) = smoothing {
            descriptor.smoothing = named(py, &s)?;
        }
        if let Some(w) = weights {
            let w: Vec<u32> = w
                .into_iter()
                .map(|v| {
                    let range = (0, i64::from(u32::MAX));
                    int_in(py, "weights", v, range, "each must be in 0..=4294967295")
                        .map(|v| v as u32)
                })
                .collect::<PyResult<_>>()?;
            descriptor.weights = PatchWeights::new(&w).or_raise(py)?;
        }
        let inner = clatch::Extractor::new(backend, config).map_err(|e| backend_error(py, e))?;
        Ok(Self { inner })
    }

    /// The backend: ``"cpu"`` or ``"cuda:N"``.
    #[getter]
    fn backend(&self) -> String {
        self.inner.backend().name()
    }

    /// The settings in effect, as the constructor's keywords (``Extractor(backend, **config)``
    /// builds an equal extractor).
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.inner.config();
        let d = PyDict::new(py);
        d.set_item("threshold", c.detector.threshold)?;
        d.set_item("max_keypoints", c.detector.max_keypoints)?;
        d.set_item("keypoint_size", shortest(c.detector.keypoint_size))?;
        d.set_item("grid", c.detector.grid)?;
        d.set_item("level_budget", c.detector.level_budget.name())?;
        d.set_item("ranking", c.detector.ranking.name())?;
        d.set_item("subpixel", c.detector.subpixel.name())?;
        match c.pyramid {
            Some(p) => d.set_item("pyramid", (p.levels, shortest(p.scale_factor)))?,
            None => d.set_item("pyramid", false)?,
        }
        d.set_item("bits", c.descriptor.width.bits())?;
        d.set_item("smoothing", c.descriptor.smoothing.name())?;
        d.set_item("weights", PyList::new(py, c.descriptor.weights.as_array())?)?;
        Ok(d)
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let config = self.config(py)?;
        let items: Vec<String> = config
            .iter()
            .filter(|(k, _)| k.to_string() != "weights")
            .map(|(k, v)| Ok(format!("{k}={}", v.repr()?)))
            .collect::<PyResult<_>>()?;
        Ok(format!(
            "Extractor({:?}, {})",
            self.backend(),
            items.join(", ")
        ))
    }

    /// Pickling: an equal extractor on the same backend, rebuilt from its settings
    /// (``Extractor(backend, **config)``), for ``multiprocessing``, Ray and ``copy``.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let newobj_ex = py.import("copyreg")?.getattr("__newobj_ex__")?;
        let this = slf.get();
        let args = PyTuple::new(py, [this.backend()])?;
        let call = (slf.get_type(), args, this.config(py)?);
        PyTuple::new(py, [newobj_ex, call.into_pyobject(py)?.into_any()])
    }

    /// detect(image, *, channels="rgb") -> keypoints
    ///
    /// FAST keypoints of ``image`` (``uint8``, 2-D gray or H x W x 3 colour: RGB, or BGR as
    /// ``cv2.imread`` gives with ``channels="bgr"``), strongest first, as a structured array of
    /// ``KEYPOINT_DTYPE`` (x, y, size, angle, response, octave), in full-resolution pixel coordinates
    /// (OpenCV's convention: pixel centres at integers, angle in degrees from +x towards +y).
    #[pyo3(signature = (image, *, channels = "rgb".to_string()), text_signature = "(self, image, *, channels='rgb')")]
    fn detect<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = args::channels)] channels: String,
    ) -> PyResult<Bound<'py, PyAny>> {
        let input = ImageInput::new(image, "image", Channels::parse(py, &channels)?)?;
        let view = input.view().or_raise(py)?;
        let keypoints = compute(py, || self.inner.detect(&view))?;
        Ok(keypoints_out(py, keypoints).into_any())
    }

    /// detect_and_describe(image, *, channels="rgb") -> (keypoints, descriptors)
    ///
    /// Keypoints (as ``detect``) and their descriptors: ``uint8``, one row of ``bits / 8`` bytes per
    /// keypoint, in OpenCV LATCH's byte order (what ``clatch extract`` writes to ``.npy``), ready
    /// for ``cv2.BFMatcher(cv2.NORM_HAMMING)``. Row i describes keypoint i.
    #[pyo3(signature = (image, *, channels = "rgb".to_string()), text_signature = "(self, image, *, channels='rgb')")]
    fn detect_and_describe<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = args::channels)] channels: String,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let input = ImageInput::new(image, "image", Channels::parse(py, &channels)?)?;
        let view = input.view().or_raise(py)?;
        let features = compute(py, || self.inner.detect_and_describe(&view))?;
        Self::features_out(py, features)
    }

    /// detect_and_describe_batch(images, *, channels="rgb") -> list[(keypoints, descriptors)]
    ///
    /// ``detect_and_describe`` of every image of a sequence, in input order, each result equal to its
    /// own call. Every image is checked before any work; the CPU spreads the images over its threads,
    /// CUDA keeps several streams busy.
    #[pyo3(signature = (images, *, channels = "rgb".to_string()), text_signature = "(self, images, *, channels='rgb')")]
    fn detect_and_describe_batch<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = args::images)] images: Vec<Bound<'py, PyAny>>,
        #[pyo3(from_py_with = args::channels)] channels: String,
    ) -> PyResult<Bound<'py, PyList>> {
        let channels = Channels::parse(py, &channels)?;
        let inputs = images
            .iter()
            .enumerate()
            .map(|(i, image)| ImageInput::new(image, &format!("images[{i}]"), channels))
            .collect::<PyResult<Vec<_>>>()?;
        let views = Self::views(py, &inputs)?;
        let all = compute(py, || self.inner.detect_and_describe_batch(&views))?;
        let out = all
            .into_iter()
            .map(|f| Self::features_out(py, f))
            .collect::<PyResult<Vec<_>>>()?;
        PyList::new(py, out)
    }

    /// describe(image, keypoints, *, channels="rgb") -> (keypoints, descriptors, index)
    ///
    /// Descriptors of your own keypoints (a 1-D array of ``KEYPOINT_DTYPE``), sampled on the full-
    /// resolution image. Keypoints whose window leaves the image are not described: the returned
    /// keypoints are those described, ``index`` (``int64``) gives each row's position in the input.
    #[pyo3(signature = (image, keypoints, *, channels = "rgb".to_string()), text_signature = "(self, image, keypoints, *, channels='rgb')")]
    fn describe<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        keypoints: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = args::channels)] channels: String,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let input = ImageInput::new(image, "image", Channels::parse(py, &channels)?)?;
        let keypoints = keypoints_in(keypoints, "keypoints")?;
        let view = input.view().or_raise(py)?;
        let features = compute(py, || self.inner.describe(&view, &keypoints))?;
        Self::described_out(py, features)
    }

    /// describe_opencv(latch, image, keypoints, *, channels="rgb") -> (keypoints, descriptors, index)
    ///
    /// OpenCV's own LATCH descriptors, bit for bit (``cv2.xfeatures2d.LATCH_create(...).compute``
    /// with ``latch``'s settings; the library's ``Extractor::describe_opencv``), of your keypoints
    /// (``KEYPOINT_DTYPE``; x, y and angle are used) on the full-resolution image. Keypoints OpenCV
    /// drops at the border are not described, nor, on purpose, the few OpenCV keeps but then reads
    /// outside the image for; ``index`` gives each returned row's position in the input. Descriptors
    /// are ``uint8`` rows of ``latch.bytes`` bytes, cv2's layout.
    #[pyo3(signature = (latch, image, keypoints, *, channels = "rgb".to_string()), text_signature = "(self, latch, image, keypoints, *, channels='rgb')")]
    fn describe_opencv<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = latch_arg)] latch: Bound<'py, OpencvLatch>,
        image: &Bound<'py, PyAny>,
        keypoints: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = args::channels)] channels: String,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let input = ImageInput::new(image, "image", Channels::parse(py, &channels)?)?;
        let keypoints = keypoints_in(keypoints, "keypoints")?;
        let view = input.view().or_raise(py)?;
        let latch = &latch.get().inner;
        let features = compute(py, || self.inner.describe_opencv(latch, &view, &keypoints))?;
        Self::described_out(py, features)
    }
}

/// `latch=`: an `OpencvLatch`, or an `ArgumentTypeError`.
fn latch_arg<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, OpencvLatch>> {
    obj.cast::<OpencvLatch>()
        .cloned()
        .map_err(|_| wrong_type(obj, "latch", "a clatch.OpencvLatch"))
}

/// OpenCV's LATCH settings (``cv2.xfeatures2d.LATCH_create(bytes, rotationInvariance,
/// half_ssd_size, sigma)``), validated: the library's ``OpencvLatch``.
///
/// OpencvLatch(bytes=32, rotation_invariance=True, half_ssd_size=3, sigma=2.0)
///
/// ``bytes`` in 1, 2, 4, 8, 16, 32, 64; ``half_ssd_size`` at most 24; ``sigma`` finite (0: no blur).
/// The defaults are OpenCV's. ``Extractor.describe_opencv(latch, image, keypoints)`` describes with
/// them, bit-exact with OpenCV. Invalid settings raise ``InvalidInputError``.
#[pyclass(module = "clatch", frozen)]
pub struct OpencvLatch {
    inner: clatch::OpencvLatch,
}

#[pymethods]
impl OpencvLatch {
    #[new]
    #[pyo3(signature = (bytes = 32, rotation_invariance = true, half_ssd_size = 3, sigma = 2.0))]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = args::bytes)] bytes: i64,
        #[pyo3(from_py_with = args::rotation_invariance)] rotation_invariance: bool,
        #[pyo3(from_py_with = args::half_ssd_size)] half_ssd_size: i64,
        #[pyo3(from_py_with = args::sigma)] sigma: f64,
    ) -> PyResult<Self> {
        let reason = "OpenCV's LATCH takes 1, 2, 4, 8, 16, 32 or 64 bytes";
        let bytes = int_in(py, "bytes", bytes, (0, 64), reason)? as usize;
        let reason = "patches may be at most 49x49 pixels (half_ssd_size <= 24)";
        let half = int_in(py, "half_ssd_size", half_ssd_size, (0, 24), reason)? as usize;
        let inner =
            clatch::OpencvLatch::new(bytes, rotation_invariance, half, sigma).or_raise(py)?;
        Ok(Self { inner })
    }

    /// Descriptor length in bytes.
    #[getter]
    fn bytes(&self) -> usize {
        self.inner.bytes()
    }

    /// Whether the sampling pattern turns with each keypoint's angle.
    #[getter]
    fn rotation_invariance(&self) -> bool {
        self.inner.rotation_invariance()
    }

    /// Half the side of each compared patch: patches are (2 h + 1) x (2 h + 1) pixels.
    #[getter]
    fn half_ssd_size(&self) -> usize {
        self.inner.half_ssd_size()
    }

    /// The Gaussian blur's sigma (0: no blur).
    #[getter]
    fn sigma(&self) -> f64 {
        self.inner.sigma()
    }

    fn __repr__(&self) -> String {
        format!(
            "OpencvLatch(bytes={}, rotation_invariance={}, half_ssd_size={}, sigma={:?})",
            self.bytes(),
            if self.rotation_invariance() {
                "True"
            } else {
                "False"
            },
            self.half_ssd_size(),
            self.sigma()
        )
    }

    /// Pickling: the same settings.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let this = slf.get();
        let args = (
            this.bytes(),
            this.rotation_invariance(),
            this.half_ssd_size(),
            this.sigma(),
        );
        PyTuple::new(
            py,
            [
                slf.get_type().into_any(),
                args.into_pyobject(py)?.into_any(),
            ],
        )
    }
}
