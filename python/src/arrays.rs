//! numpy arrays in and out: images, keypoints, descriptors and matches.
//!
//! - Images: `uint8`, 2-D gray or H x W x 3 (RGB, or BGR with `channels="bgr"`; a fourth, alpha,
//!   channel is ignored). The shape is checked first, before any pixel is read. A gray array whose rows
//!   are contiguous (C order, or a view with a positive row step, e.g. a crop) is read in place
//!   through a [`GrayView`] with its row stride; anything else is copied once, with the GIL released.
//! - Keypoints out: a structured array of [`KeyPointRecord`] (x, y, size, angle, response as
//!   `float32`, octave as `int32`), owning the library's own `Vec<KeyPoint>` (no copy).
//! - Descriptors: `uint8`, N x bytes, in OpenCV LATCH's byte order
//!   ([`clatch::DescriptorSet::to_opencv_bytes`], what the command-line tool writes to `.npy`).
//! - Matches out: a structured array of [`MatchRecord`] (query, train, distance as `uint32`), owning
//!   the library's `Vec<Match>`.

use std::mem::{offset_of, size_of};
use std::ops::Range;

use clatch::{DescriptorSet, DescriptorWidth, GrayView, KeyPoint, Match};
use numpy::ndarray::{ArrayView2, ArrayViewD, Ix2, s};
use numpy::{
    Element, IntoPyArray, PyArray1, PyArrayDescr, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods,
    PyReadonlyArray1, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyDict;

use crate::errors::{Class, OrRaise, invalid_input, raise, try_buffer, type_name};

/// A structured dtype with `fields` (name, numpy type code, byte offset) and `itemsize` bytes.
fn record_dtype<'py>(
    py: Python<'py>,
    fields: &[(&str, &str, usize)],
    itemsize: usize,
) -> PyResult<Bound<'py, PyArrayDescr>> {
    let spec = PyDict::new(py);
    spec.set_item("names", fields.iter().map(|f| f.0).collect::<Vec<_>>())?;
    spec.set_item("formats", fields.iter().map(|f| f.1).collect::<Vec<_>>())?;
    spec.set_item("offsets", fields.iter().map(|f| f.2).collect::<Vec<_>>())?;
    spec.set_item("itemsize", itemsize)?;
    PyArrayDescr::new(py, spec)
}

/// A cached dtype, built once per interpreter.
fn cached<'py>(
    py: Python<'py>,
    cell: &'static PyOnceLock<Py<PyArrayDescr>>,
    make: fn(Python<'py>) -> PyResult<Bound<'py, PyArrayDescr>>,
) -> Bound<'py, PyArrayDescr> {
    cell.get_or_try_init(py, || make(py).map(Bound::unbind))
        // The spec is fixed and valid: numpy accepts it on every version (checked by the tests).
        .expect("numpy accepts the record dtype")
        .bind(py)
        .clone()
}

/// One keypoint as a numpy record: the library's `KeyPoint`, whose `#[repr(C)]` layout the dtype
/// describes field by field (offsets taken from the Rust type, not assumed).
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct KeyPointRecord(pub KeyPoint);

fn keypoint_dtype(py: Python<'_>) -> PyResult<Bound<'_, PyArrayDescr>> {
    record_dtype(
        py,
        &[
            ("x", "<f4", offset_of!(KeyPoint, x)),
            ("y", "<f4", offset_of!(KeyPoint, y)),
            ("size", "<f4", offset_of!(KeyPoint, size)),
            ("angle", "<f4", offset_of!(KeyPoint, angle)),
            ("response", "<f4", offset_of!(KeyPoint, response)),
            ("octave", "<i4", offset_of!(KeyPoint, octave)),
        ],
        size_of::<KeyPoint>(),
    )
}

// SAFETY: `KeyPointRecord` is `repr(transparent)` over `KeyPoint`, a `#[repr(C)]` struct of five `f32`
// and one `i32` (little-endian on every target abi3 wheels are built for), and the dtype lists exactly
// those fields at their `offset_of!` offsets with `size_of` as the item size. It is plain data.
unsafe impl Element for KeyPointRecord {
    const IS_COPY: bool = true;

    fn get_dtype(py: Python<'_>) -> Bound<'_, PyArrayDescr> {
        static DTYPE: PyOnceLock<Py<PyArrayDescr>> = PyOnceLock::new();
        cached(py, &DTYPE, keypoint_dtype)
    }

    fn clone_ref(&self, _py: Python<'_>) -> Self {
        *self
    }
}

/// One match as a numpy record: the library's `#[repr(C)]` `Match`.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct MatchRecord(pub Match);

fn match_dtype(py: Python<'_>) -> PyResult<Bound<'_, PyArrayDescr>> {
    record_dtype(
        py,
        &[
            ("query", "<u4", offset_of!(Match, query)),
            ("train", "<u4", offset_of!(Match, train)),
            ("distance", "<u4", offset_of!(Match, distance)),
        ],
        size_of::<Match>(),
    )
}

// SAFETY: as for `KeyPointRecord`: `Match` is `#[repr(C)]` with three `u32` fields, described at their
// offsets.
unsafe impl Element for MatchRecord {
    const IS_COPY: bool = true;

    fn get_dtype(py: Python<'_>) -> Bound<'_, PyArrayDescr> {
        static DTYPE: PyOnceLock<Py<PyArrayDescr>> = PyOnceLock::new();
        cached(py, &DTYPE, match_dtype)
    }

    fn clone_ref(&self, _py: Python<'_>) -> Self {
        *self
    }
}

/// Keypoints as a structured array that takes over the vector (no copy: the map is done in place).
pub fn keypoints_out(
    py: Python<'_>,
    keypoints: Vec<KeyPoint>,
) -> Bound<'_, PyArray1<KeyPointRecord>> {
    keypoints
        .into_iter()
        .map(KeyPointRecord)
        .collect::<Vec<_>>()
        .into_pyarray(py)
}

/// Matches as a structured array that takes over the vector.
pub fn matches_out(py: Python<'_>, matches: Vec<Match>) -> Bound<'_, PyArray1<MatchRecord>> {
    matches
        .into_iter()
        .map(MatchRecord)
        .collect::<Vec<_>>()
        .into_pyarray(py)
}

/// Descriptors as an N x bytes `uint8` array in OpenCV LATCH's byte order.
pub fn descriptors_out<'py>(py: Python<'py>, set: &DescriptorSet) -> PyResult<Bound<'py, PyAny>> {
    let bytes = set.to_opencv_bytes();
    Ok(bytes
        .into_pyarray(py)
        .reshape([set.len(), set.width().bytes()])?
        .into_any())
}

/// The `numpy.ndarray` in `obj`, or an `InvalidInputError` naming `what`.
pub(crate) fn ndarray<'a, 'py>(
    obj: &'a Bound<'py, PyAny>,
    what: &str,
) -> PyResult<&'a Bound<'py, PyUntypedArray>> {
    obj.cast::<PyUntypedArray>().map_err(|_| {
        let type_name = type_name(obj);
        invalid_input(
            obj.py(),
            "NotAnArray",
            format!("{what} must be a numpy.ndarray, got {type_name}"),
        )
    })
}

/// `obj` as a `uint8` array (read-only borrow), or an `InvalidInputError` naming `what`.
fn uint8_array<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<PyReadonlyArrayDyn<'py, u8>> {
    let py = obj.py();
    let array = ndarray(obj, what)?;
    let dtype = array.dtype();
    if !dtype.is_equiv_to(&numpy::dtype::<u8>(py)) {
        return Err(invalid_input(
            py,
            "WrongDtype",
            format!("{what} must have dtype uint8, got {dtype}"),
        ));
    }
    let typed = array.cast::<PyArrayDyn<u8>>()?;
    typed.try_readonly().map_err(|e| {
        invalid_input(
            py,
            "ArrayBorrowed",
            format!("{what} cannot be read now: {e}"),
        )
    })
}

/// The colour order of an H x W x 3 (or x 4) image: `channels="rgb"` (the default) or `"bgr"`
/// (OpenCV's `cv2.imread`). A gray image has none.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channels {
    Rgb,
    Bgr,
}

impl Channels {
    /// `channels=` of a call, or an `InvalidInputError` (kind `InvalidConfig`) listing the names.
    pub fn parse(py: Python<'_>, name: &str) -> PyResult<Self> {
        match name {
            "rgb" => Ok(Self::Rgb),
            "bgr" => Ok(Self::Bgr),
            _ => Err(invalid_input(
                py,
                "InvalidConfig",
                format!("channels must be one of \"rgb\", \"bgr\", got {name:?}"),
            )),
        }
    }

    /// The offsets of red, green and blue within a pixel.
    fn offsets(self) -> [usize; 3] {
        match self {
            Self::Rgb => [0, 1, 2],
            Self::Bgr => [2, 1, 0],
        }
    }
}

/// A numpy shape as numpy writes it: `(63, 200)`, `(5,)`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Refuses, from the shape alone (before any pixel is read or copied), an image with no pixels or a
/// side above the library's `MAX_IMAGE_SIDE`, naming the numpy shape `(H, W)`.
fn check_shape(py: Python<'_>, what: &str, shape: &[usize]) -> PyResult<()> {
    let (height, width) = (shape[0], shape[1]);
    let shape = shape_text(shape);
    if height == 0 || width == 0 {
        return Err(raise(
            py,
            Class::InvalidInput,
            "EmptyImage",
            format!("{what} is empty: shape {shape}; height and width must both be at least 1"),
        ));
    }
    let max = clatch::MAX_IMAGE_SIDE;
    if height > max || width > max {
        return Err(raise(
            py,
            Class::InvalidInput,
            "ImageTooLarge",
            format!("{what} of shape {shape} exceeds the largest supported side of {max} pixels"),
        ));
    }
    Ok(())
}

/// An image from Python: borrowed array memory (read in place) or a converted copy.
pub struct ImageInput<'py> {
    /// Keeps the array alive and registered as read-only borrowed while its memory is used.
    _array: Option<PyReadonlyArrayDyn<'py, u8>>,
    /// Start of the pixels (`len` bytes, rows `stride` apart): the array's memory, or `owned`.
    ptr: *const u8,
    len: usize,
    owned: Vec<u8>,
    width: usize,
    height: usize,
    stride: usize,
}

impl<'py> ImageInput<'py> {
    /// Reads `obj` (see the module docs) with the colour order `channels`. `what` names it in
    /// errors. The shape is checked before anything is copied; a copy (a gray image whose rows are
    /// not contiguous, a colour image) is made with the GIL released, from the array's memory, which
    /// the borrow of the array keeps alive meanwhile.
    pub fn new(obj: &Bound<'py, PyAny>, what: &str, channels: Channels) -> PyResult<Self> {
        let py = obj.py();
        let array = uint8_array(obj, what)?;
        let shape = array.shape().to_vec();
        let gray = match *shape.as_slice() {
            [_, _] => true,
            [_, _, 3 | 4] => false,
            _ => {
                return Err(invalid_input(
                    py,
                    "WrongShape",
                    format!(
                        "{what} must be 2-D (gray, shape (H, W)) or 3-D with 3 or 4 channels (RGB, BGR \
                         or with alpha, shape (H, W, C)), got shape {}",
                        shape_text(&shape)
                    ),
                ));
            }
        };
        check_shape(py, what, &shape)?;
        let (height, width) = (shape[0], shape[1]);
        let view = array.as_array();
        if gray && let Some((ptr, len, stride)) = rows_in_place(&view) {
            return Ok(Self {
                ptr,
                len,
                stride,
                _array: Some(array),
                owned: Vec::new(),
                width,
                height,
            });
        }
        let mut owned = try_buffer(py, height * width, what)?;
        py.detach(|| {
            owned.resize(height * width, 0);
            if gray {
                // Rows not contiguous (a transposed view, a column step, a broadcast): one
                // row-major copy.
                gray_copy(view, &mut owned)
            } else {
                to_luma(view, channels, &mut owned)
            }
        });
        Ok(Self::owned(owned, width, height))
    }

    fn owned(owned: Vec<u8>, width: usize, height: usize) -> Self {
        Self {
            _array: None,
            ptr: owned.as_ptr(),
            len: owned.len(),
            owned,
            width,
            height,
            stride: width,
        }
    }

    /// Whether the pixels are read in place (no copy was made).
    pub fn zero_copy(&self) -> bool {
        self._array.is_some()
    }

    /// The image as the library sees it (its sizes checked by `GrayView::new`).
    pub fn view(&self) -> clatch::Result<GrayView<'_>> {
        let data: &[u8] = if self.len == 0 {
            &[]
        } else if self._array.is_none() {
            &self.owned
        } else {
            // SAFETY: `ptr` and `len` cover `stride * (height - 1) + width` bytes of the array's
            // buffer (rows_in_place), which `_array` keeps alive and borrowed read-only for as long as
            // `self`, and so the returned view, lives.
            unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
        };
        GrayView::new(data, self.width, self.height, self.stride)
    }

    /// The gray pixels, row-major (a copy when read in place), made with the GIL released.
    pub fn to_vec(&self, py: Python<'_>) -> PyResult<Vec<u8>> {
        let view = self.view().or_raise(py)?;
        let (width, height) = (view.width(), view.height());
        let mut out = try_buffer(py, width * height, "image")?;
        py.detach(|| {
            out.resize(width * height, 0);
            for (y, line) in out.chunks_exact_mut(width).enumerate() {
                line.copy_from_slice(view.get_row(y).unwrap_or_default());
            }
        });
        Ok(out)
    }
}

/// The gray image of an H x W x C (C = 3 or 4) colour image whose colours lie in `channels` order,
/// with OpenCV's integer weights (`clatch::decode::luma`), any strides, into `out` (H x W).
fn to_luma(view: ArrayViewD<'_, u8>, channels: Channels, out: &mut [u8]) {
    let [r, g, b] = channels.offsets();
    if let Some(packed) = view.as_slice() {
        let c = view.shape()[2];
        for (o, p) in out.iter_mut().zip(packed.chunks_exact(c)) {
            *o = clatch::decode::luma(p[r], p[g], p[b]);
        }
        return;
    }
    let (height, width) = (view.shape()[0], view.shape()[1]);
    for_tiles(height, width, |rows, columns| {
        let tile = view.slice(s![rows.clone(), columns.clone(), ..]);
        for (y, row) in rows.zip(tile.outer_iter()) {
            let line = &mut out[y * width..][columns.clone()];
            for (value, pixel) in line.iter_mut().zip(row.outer_iter()) {
                *value = clatch::decode::luma(pixel[r], pixel[g], pixel[b]);
            }
        }
    });
}

/// A 2-D `uint8` array's pixels into `out`, row-major, whatever its strides.
fn gray_copy(view: ArrayViewD<'_, u8>, out: &mut [u8]) {
    let (height, width) = (view.shape()[0], view.shape()[1]);
    for_tiles(height, width, |rows, columns| {
        let tile = view.slice(s![rows.clone(), columns.clone()]);
        for (y, row) in rows.zip(tile.outer_iter()) {
            let line = &mut out[y * width..][columns.clone()];
            line.iter_mut().zip(row).for_each(|(o, &v)| *o = v);
        }
    });
}

/// Calls `f(rows, columns)` for the 64 x 64 tiles of a `height` x `width` image, row by row: a
/// transposed or Fortran-order array is then read a cache-sized block at a time, not a column of
/// cache misses per row.
fn for_tiles(height: usize, width: usize, mut f: impl FnMut(Range<usize>, Range<usize>)) {
    const TILE: usize = 64;
    for y in (0..height).step_by(TILE) {
        for x in (0..width).step_by(TILE) {
            f(y..(y + TILE).min(height), x..(x + TILE).min(width));
        }
    }
}

/// Where a 2-D `uint8` array's rows lie when each row is contiguous and rows follow at a positive
/// step: the first pixel, the bytes spanned, and the row stride. `None` when the array must be copied.
fn rows_in_place(view: &ArrayViewD<'_, u8>) -> Option<(*const u8, usize, usize)> {
    let (height, width) = (view.shape()[0], view.shape()[1]);
    if height == 0 || width == 0 {
        return None;
    }
    let strides = view.strides();
    if width > 1 && strides[1] != 1 {
        return None;
    }
    let stride = if height == 1 {
        width
    } else {
        usize::try_from(strides[0]).ok().filter(|&s| s >= width)?
    };
    let len = stride.checked_mul(height - 1)?.checked_add(width)?;
    Some((view.as_ptr(), len, stride))
}

/// Descriptors from an N x bytes `uint8` array in OpenCV LATCH's byte order (any strides). `what`
/// names the array in errors.
pub fn descriptors_in(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<DescriptorSet> {
    let py = obj.py();
    let array = uint8_array(obj, what)?;
    let view = array.as_array();
    let view: ArrayView2<'_, u8> = view.into_dimensionality::<Ix2>().map_err(|_| {
        invalid_input(
            py,
            "WrongShape",
            format!(
                "{what} must be 2-D (one row of bytes per descriptor), got shape {}; \
                 a single descriptor is descriptors.reshape(1, -1)",
                shape_text(array.shape())
            ),
        )
    })?;
    let width = DescriptorWidth::from_bytes(view.ncols()).or_raise(py)?;
    let rows = view.nrows();
    // Matches index descriptors with 32 bits (`Match`), and a Rust allocation failure would abort
    // the interpreter: both checked before any copy.
    if u32::try_from(rows).is_err() {
        return Err(invalid_input(
            py,
            "TooManyDescriptors",
            format!(
                "{what} has {rows} descriptors; matches index at most {} (u32)",
                u32::MAX
            ),
        ));
    }
    // The library's conversion holds each row as a 64-byte descriptor, then the packed words; a
    // strided array is copied first. Reserved (never touched) and freed again: whether the memory is
    // there, asked of the allocator that would otherwise abort.
    let needed = rows.saturating_mul(64 + 8 * width.words() + width.bytes());
    drop(try_buffer(py, needed, what)?);
    // With the GIL released: the conversion reads every byte (a large set takes milliseconds).
    let set = py.detach(|| match view.as_slice() {
        // C order (what numpy and the extractor give): the rows as they lie.
        Some(packed) => DescriptorSet::from_opencv_bytes(width, packed),
        // Any other strides: the bytes in row order first (`iter` walks in logical order).
        None => DescriptorSet::from_opencv_bytes(width, &view.iter().copied().collect::<Vec<u8>>()),
    });
    set.or_raise(py)
}

/// The records of a 1-D structured array of `R`'s dtype (`dtype_name` in errors), copied out.
fn records_in<R: Element + Copy>(
    obj: &Bound<'_, PyAny>,
    what: &str,
    dtype_name: &str,
) -> PyResult<Vec<R>> {
    let py = obj.py();
    let array = ndarray(obj, what)?;
    let expected = R::get_dtype(py);
    if !array.dtype().is_equiv_to(&expected) || array.ndim() != 1 {
        return Err(invalid_input(
            py,
            "WrongDtype",
            format!(
                "{what} must be a 1-D array of dtype {dtype_name} {expected}, got {}-D {}",
                array.ndim(),
                array.dtype()
            ),
        ));
    }
    let typed: PyReadonlyArray1<'_, R> = array
        .cast::<PyArray1<R>>()?
        .try_readonly()
        .map_err(|e| invalid_input(py, "ArrayBorrowed", format!("{what}: {e}")))?;
    Ok(typed.as_array().iter().copied().collect())
}

/// Keypoints from a structured array of the keypoint dtype (`clatch.KEYPOINT_DTYPE`).
pub fn keypoints_in(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<KeyPoint>> {
    let records: Vec<KeyPointRecord> = records_in(obj, what, "clatch.KEYPOINT_DTYPE")?;
    Ok(records.into_iter().map(|k| k.0).collect())
}

/// Matches from a structured array of the match dtype (`clatch.MATCH_DTYPE`).
pub fn matches_in(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Match>> {
    let records: Vec<MatchRecord> = records_in(obj, what, "clatch.MATCH_DTYPE")?;
    Ok(records.into_iter().map(|m| m.0).collect())
}
