//! Device allocations and uploads that report failures as typed errors, and the pinned host staging
//! buffers uploads go through.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, DevicePtrMut, DeviceRepr, PinnedHostSlice, ValidAsZeroBits,
    sys,
};

use super::device::driver_error;
use crate::parallel::*;
use crate::error::{Error, Result};

// With the `internals` feature, tests can make the `n`-th device allocation of a thread fail
// ([`hooks::fail_allocation`]), so that every allocation site's error path runs on a real device.
// They also count this thread's allocations ([`hooks::allocations`]), so that tests can check that a
// warm steady state allocates nothing.
#[cfg(feature = "internals")]
thread_local! {
    static FAIL_AFTER: std::cell::Cell<Option<usize>> = const { std::cell::Cell::new(None) };
    static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The failure injected at this allocation, if any (always none without the `internals` feature).
/// Every device and pinned host allocation of the crate passes here first.
fn injected_failure(operation: &str, bytes: usize) -> Result<()> {
    #[cfg(feature = "internals")]
    ALLOCATIONS.set(ALLOCATIONS.get() + 1);
    #[cfg(feature = "internals")]
    if let Some(remaining) = FAIL_AFTER.get() {
        if remaining == 0 {
            FAIL_AFTER.set(None);
            return Err(Error::DeviceOutOfMemory {
                operation: operation.to_string(),
                bytes,
            });
        }
        FAIL_AFTER.set(Some(remaining - 1));
    }
    let _ = (operation, bytes);
    Ok(())
}

/// Adds the requested size to an out-of-memory error.
fn with_bytes(error: Error, bytes: usize) -> Error {
    match error {
        Error::DeviceOutOfMemory { operation, .. } => Error::DeviceOutOfMemory { operation, bytes },
        other => other,
    }
}

/// `len` zeroed elements (at least one, so no launch ever sees a null buffer) on the device, queued on
/// `stream`; out of memory is reported with the size asked for.
pub(crate) fn alloc_zeros<T: DeviceRepr + ValidAsZeroBits>(
    stream: &Arc<CudaStream>,
    len: usize,
    operation: &str,
) -> Result<CudaSlice<T>> {
    let len = len.max(1);
    let bytes = len.saturating_mul(size_of::<T>());
    if bytes == usize::MAX {
        return Err(Error::DeviceOutOfMemory {
            operation: operation.to_string(),
            bytes,
        });
    }
    injected_failure(operation, bytes)?;
    stream
        .alloc_zeros::<T>(len)
        .map_err(|e| with_bytes(driver_error(operation)(e), bytes))
}

/// `len` elements of page-locked host memory for copies queued on `stream`'s device (contents unset:
/// the caller writes before any copy reads, or reads only what a copy wrote).
pub(crate) fn alloc_pinned<T: DeviceRepr>(
    stream: &Arc<CudaStream>,
    len: usize,
    operation: &str,
) -> Result<PinnedHostSlice<T>> {
    let len = len.max(1);
    let bytes = len.saturating_mul(size_of::<T>());
    injected_failure(operation, bytes)?;
    // SAFETY: every user of the buffer writes it (or lets a copy write it) before reading it; pinned
    // buffers only hold plain old data (`ValidAsZeroBits` at the read sites).
    unsafe { stream.context().alloc_pinned::<T>(len) }
        .map_err(|e| with_bytes(driver_error(operation)(e), bytes))
}

/// A copy of `data` on the device, queued on `stream` (from pageable memory: for small uploads).
pub(crate) fn upload<T: DeviceRepr>(
    stream: &Arc<CudaStream>,
    data: &[T],
    operation: &str,
) -> Result<CudaSlice<T>> {
    injected_failure(operation, size_of_val(data))?;
    stream
        .clone_htod(data)
        .map_err(|e| with_bytes(driver_error(operation)(e), size_of_val(data)))
}

/// Reusable page-locked host buffers, by exact size, so repeated uploads of same-sized images (video,
/// batches) are true asynchronous DMA without a fresh `cuMemHostAlloc` each time. Each comes with an
/// event recorded after its last copy, so a caller takes a buffer whose copy has finished instead of
/// waiting for the one just queued (which made images in flight queue one upload at a time).
type Pool = Mutex<HashMap<(usize, usize), Vec<(PinnedHostSlice<u8>, CudaEvent)>>>;

/// Most buffers kept per size, and most bytes kept per size: as many images of one size as are
/// commonly in flight keep their staging buffers (allocating and freeing pinned memory per call
/// costs more than the copy: with 4 kept, 8 images of 1080p in flight spent most of their host time
/// there); more in flight at once are allocated and dropped.
const KEPT_PER_SIZE: usize = 16;
const KEPT_BYTES_PER_SIZE: usize = 256 << 20;

/// Buffers of `len` bytes the pool keeps.
fn kept_for(len: usize) -> usize {
    (KEPT_BYTES_PER_SIZE / len.max(1)).clamp(1, KEPT_PER_SIZE)
}

fn pool() -> &'static Pool {
    static POOL: OnceLock<Pool> = OnceLock::new();
    POOL.get_or_init(Default::default)
}

/// Rows of a band of a staged upload: about this many bytes, so that the host fills band `k + 1`
/// into one staging buffer while the copy engine moves band `k` out of another.
const BAND_BYTES: usize = 1 << 20;

/// A staging buffer of `len` bytes whose last copy has finished, from the pool (with its event, to be
/// recorded again) or new.
fn staging(
    stream: &Arc<CudaStream>,
    len: usize,
    operation: &str,
) -> Result<(PinnedHostSlice<u8>, Option<CudaEvent>)> {
    let key = (stream.context().ordinal(), len);
    let reused = pool()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get_mut(&key)
        .and_then(|kept| {
            let idle = kept.iter().position(|(_, copied)| copied.is_complete())?;
            Some(kept.swap_remove(idle))
        });
    match reused {
        Some((buffer, copied)) => Ok((buffer, Some(copied))),
        None => Ok((alloc_pinned::<u8>(stream, len, operation)?, None)),
    }
}

/// Copies `rows` rows of `pitch` bytes, each written by `fill(y, row)`, into `dst` (at least
/// `rows * pitch` bytes) on `stream`, in bands through pinned staging buffers: the host fills a band
/// (rows in parallel) while the copies of the bands before it run. The staging buffers return to the
/// pool; a later user takes one once its copy has finished reading it (cudarc's own event makes any
/// user wait for that in any case). Returns when every band is queued, with the copies in flight.
pub(crate) fn upload_rows(
    stream: &Arc<CudaStream>,
    dst: &mut CudaSlice<u8>,
    (rows, pitch): (usize, usize),
    operation: &str,
    fill: impl Fn(usize, &mut [u8]) + Sync,
) -> Result<()> {
    super::invariant(
        pitch > 0 && dst.len() >= rows * pitch,
        "image upload",
        || {
            format!(
                "{rows} rows of {pitch} bytes into {} bytes",
                dst.len()
            )
        },
    )?;
    let band_rows = (BAND_BYTES / pitch).max(1);
    let mut y0 = 0;
    while y0 < rows {
        let y1 = (y0 + band_rows).min(rows);
        let len = (y1 - y0) * pitch;
        let (mut staged, event) = staging(stream, len, "pinned staging allocation")?;
        let host = staged
            .as_mut_slice()
            .map_err(driver_error("waiting for a staging buffer"))?;
        host.par_chunks_exact_mut(pitch)
            .with_min_len(64)
            .enumerate()
            .for_each(|(i, row)| fill(y0 + i, row));
        // The staging buffer is exactly `len` bytes, the destination band too: the copy's length
        // check holds.
        stream
            .memcpy_htod(&staged, &mut dst.slice_mut(y0 * pitch..y1 * pitch))
            .map_err(driver_error(operation))?;
        let copied = match event {
            Some(event) => {
                event.record(stream).map_err(driver_error("event record"))?;
                event
            }
            None => stream
                .record_event(None)
                .map_err(driver_error("event record"))?,
        };
        let mut pool = pool().lock().unwrap_or_else(|p| p.into_inner());
        let kept = pool.entry((stream.context().ordinal(), len)).or_default();
        if kept.len() < kept_for(len) {
            kept.push((staged, copied));
        }
        y0 = y1;
    }
    Ok(())
}

/// Whether `bytes` lies in page-locked host memory the driver knows (allocated with
/// `cuMemHostAlloc` or registered with `cuMemHostRegister`, by clatch or anyone else in the
/// process): its first and last byte are both host memory of the unified address space.
pub(crate) fn is_pinned(bytes: &[u8]) -> bool {
    let (Some(first), Some(last)) = (bytes.first(), bytes.last()) else {
        return false;
    };
    [first as *const u8, last as *const u8].iter().all(|&p| {
        let mut kind: u32 = 0;
        // SAFETY: asks the driver about an address (never dereferenced); `kind` receives one
        // CUmemorytype value. Memory the driver does not know is an error, i.e. "not pinned".
        let known = unsafe {
            sys::cuPointerGetAttribute(
                (&mut kind as *mut u32).cast(),
                sys::CUpointer_attribute::CU_POINTER_ATTRIBUTE_MEMORY_TYPE,
                p as sys::CUdeviceptr,
            )
        };
        known == sys::cudaError_enum::CUDA_SUCCESS
            && kind == sys::CUmemorytype::CU_MEMORYTYPE_HOST as u32
    })
}

/// Queues one 2-D copy of `rows` rows of `width` bytes, `stride` apart from `src` on the host, into
/// `dst` (rows `pitch` apart) on `stream`: the copy engine reads the host memory directly.
///
/// # Safety
/// `src` must stay valid and unchanged until the copy has run (the caller waits for the stream, or
/// keeps the memory alive until work queued after the copy has completed). Page-locked memory makes
/// the copy asynchronous; pageable memory is correct too, just slower.
pub(crate) unsafe fn copy_rows_2d(
    stream: &Arc<CudaStream>,
    dst: &mut CudaSlice<u8>,
    pitch: usize,
    (src, width, rows, stride): (&[u8], usize, usize, usize),
    operation: &str,
) -> Result<()> {
    super::invariant(
        rows > 0
            && width <= pitch
            && width <= stride
            && src.len() >= stride * (rows - 1) + width
            && dst.len() >= pitch * rows,
        "image upload",
        || {
            format!(
                "{rows} rows of {width} bytes (stride {stride}, {} bytes) into {} bytes of pitch {pitch}",
                src.len(),
                dst.len()
            )
        },
    )?;
    let (device, _sync) = dst.device_ptr_mut(stream);
    let copy = sys::CUDA_MEMCPY2D {
        srcXInBytes: 0,
        srcY: 0,
        srcMemoryType: sys::CUmemorytype::CU_MEMORYTYPE_HOST,
        srcHost: src.as_ptr().cast(),
        srcDevice: 0,
        srcArray: std::ptr::null_mut(),
        srcPitch: stride,
        dstXInBytes: 0,
        dstY: 0,
        dstMemoryType: sys::CUmemorytype::CU_MEMORYTYPE_DEVICE,
        dstHost: std::ptr::null_mut(),
        dstDevice: device,
        dstArray: std::ptr::null_mut(),
        dstPitch: pitch,
        WidthInBytes: width,
        Height: rows,
    };
    stream
        .context()
        .bind_to_thread()
        .map_err(driver_error(operation))?;
    // SAFETY: both extents were checked above; the caller keeps `src` alive (see above).
    unsafe { sys::cuMemcpy2DAsync_v2(&copy, stream.cu_stream()) }
        .result()
        .map_err(driver_error(operation))
}

/// Drops every idle staging buffer (test hooks: a cold start).
#[cfg(feature = "internals")]
pub(crate) fn clear_staging() {
    pool().lock().unwrap_or_else(|p| p.into_inner()).clear();
}

#[cfg(feature = "internals")]
pub mod hooks;
