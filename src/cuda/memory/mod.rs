//! Device allocations and uploads that report failures as typed errors, and the pinned host staging
//! buffers uploads go through.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, DevicePtrMut, DeviceRepr, PinnedHostSlice, ValidAsZeroBits,
    sys,
};

pub(crate) mod arena;

use super::error::driver_error;
use crate::error::{Error, Result};
use crate::parallel::*;

// With the `internals` feature, tests can make the `n`-th device allocation of a thread fail
// ([`hooks::fail_allocation`]), so that every allocation site's error path runs on a real device.
// They also count this thread's allocations ([`hooks::allocations`]), so that tests can check that a
// warm steady state allocates nothing.
#[cfg(feature = "internals")]
thread_local! {
    static FAIL_AFTER: std::cell::Cell<Option<usize>> = const { std::cell::Cell::new(None) };
    static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    static DEVICE_ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Counts a device allocation for [`hooks::device_allocations`] (nothing without `internals`).
fn count_device() {
    #[cfg(feature = "internals")]
    DEVICE_ALLOCATIONS.set(DEVICE_ALLOCATIONS.get() + 1);
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
    count_device();
    stream
        .alloc_zeros::<T>(len)
        .map_err(|e| with_bytes(driver_error(operation)(e), bytes))
}

/// `len` elements of page-locked host memory for copies queued on `stream`'s device (contents unset:
/// the caller writes before any copy reads, or reads only what a copy wrote). `write_combined` for
/// buffers the host only writes (uploads: faster writes and copies, very slow host reads).
pub(crate) fn alloc_pinned<T: DeviceRepr>(
    stream: &Arc<CudaStream>,
    len: usize,
    write_combined: bool,
    operation: &str,
) -> Result<PinnedHostSlice<T>> {
    let len = len.max(1);
    let bytes = len.saturating_mul(size_of::<T>());
    if bytes >= isize::MAX as usize {
        // cudarc asserts below this size: refuse it as a typed error first.
        return Err(Error::DeviceOutOfMemory {
            operation: operation.to_string(),
            bytes,
        });
    }
    injected_failure(operation, bytes)?;
    let flags = if write_combined {
        sys::CU_MEMHOSTALLOC_WRITECOMBINED
    } else {
        0
    };
    // SAFETY: every user of the buffer writes it (or lets a copy write it) before reading it; pinned
    // buffers only hold plain old data (`ValidAsZeroBits` at the read sites).
    unsafe { stream.context().alloc_pinned_with_flags::<T>(len, flags) }
        .map_err(|e| with_bytes(driver_error(operation)(e), bytes))
}

/// A copy of `data` on the device, queued on `stream` (from pageable memory: for small uploads).
pub(crate) fn upload<T: DeviceRepr>(
    stream: &Arc<CudaStream>,
    data: &[T],
    operation: &str,
) -> Result<CudaSlice<T>> {
    injected_failure(operation, size_of_val(data))?;
    count_device();
    stream
        .clone_htod(data)
        .map_err(|e| with_bytes(driver_error(operation)(e), size_of_val(data)))
}

/// Rows of a band of a staged upload: at most this many bytes, so that the host fills band `k + 1`
/// into one staging buffer while the copy engine moves band `k` out of another. Every staging buffer
/// has this size (a row is at most 32 KiB, so a band holds at least 128 rows), so any buffer serves
/// any upload and a steady state allocates none.
const BAND_BYTES: usize = 4 << 20;

/// Most staging buffers a process keeps (128 MiB): enough for the bands of the images commonly in
/// flight at once; when all are in use and none idle has finished its copy, an upload waits for the
/// oldest idle one rather than allocating more.
const KEPT_STAGING: usize = 32;

/// A staging buffer and the event recorded after the last copy out of it.
struct Staging {
    buffer: PinnedHostSlice<u8>,
    copied: CudaEvent,
}

impl Drop for Staging {
    fn drop(&mut self) {
        // The buffer is freed after this: its copy must have read it. (A copy queued without its
        // event is waited for by `upload_rows` before the buffer gets here.)
        let _ = self.copied.synchronize();
    }
}

/// Reusable page-locked staging buffers, per device: repeated uploads are true asynchronous DMA
/// without a fresh `cuMemHostAlloc` each time. A caller takes a buffer whose copy has finished
/// instead of waiting for the one just queued (which made images in flight queue one upload at a
/// time).
#[derive(Default)]
struct Pool {
    idle: HashMap<usize, Vec<Staging>>,
    /// Buffers of each device, idle or in use.
    made: HashMap<usize, usize>,
}

fn pool() -> &'static Mutex<Pool> {
    static POOL: OnceLock<Mutex<Pool>> = OnceLock::new();
    POOL.get_or_init(Default::default)
}

/// A staging buffer of `BAND_BYTES` for device `stream`'s: an idle one whose copy has finished, else
/// a new one while fewer than `KEPT_STAGING` exist, else the oldest idle one once its copy finishes.
fn staging(stream: &Arc<CudaStream>, operation: &str) -> Result<Staging> {
    let ordinal = stream.context().ordinal();
    let waited = {
        let mut pool = pool().lock().unwrap_or_else(|p| p.into_inner());
        let made = pool.made.get(&ordinal).copied().unwrap_or(0);
        let idle = pool.idle.entry(ordinal).or_default();
        if let Some(i) = idle.iter().position(|s| s.copied.is_complete()) {
            return Ok(idle.swap_remove(i));
        }
        if made >= KEPT_STAGING && !idle.is_empty() {
            Some(idle.remove(0))
        } else {
            None
        }
    };
    if let Some(staging) = waited {
        staging
            .copied
            .synchronize()
            .map_err(driver_error("waiting for a staging buffer"))?;
        return Ok(staging);
    }
    let buffer = alloc_pinned::<u8>(stream, BAND_BYTES, true, operation)?;
    let copied = stream
        .context()
        .new_event(None)
        .map_err(driver_error("event creation"))?;
    *pool()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .made
        .entry(ordinal)
        .or_default() += 1;
    Ok(Staging { buffer, copied })
}

/// Gives `staging` back to the pool (its copy may still run: the next user waits for its event).
fn give_back(ordinal: usize, staging: Staging) {
    let mut pool = pool().lock().unwrap_or_else(|p| p.into_inner());
    let idle = pool.idle.entry(ordinal).or_default();
    if idle.len() < KEPT_STAGING {
        idle.push(staging);
    } else {
        // Kept no longer (dropped after its copy).
        *pool.made.entry(ordinal).or_default() -= 1;
        drop(pool);
        drop(staging);
    }
}

/// Copies rows `rows` of `pitch` bytes, each written by `fill(y, row)`, into the same rows of `dst`
/// (at least `rows.end * pitch` bytes) on `stream`, in bands through pinned staging buffers: the host
/// fills a band (rows in parallel) while the copies of the bands before it run. The staging buffers
/// return to the pool with the event of their copy. Returns when every band is queued, with the
/// copies in flight.
pub(crate) fn upload_rows(
    stream: &Arc<CudaStream>,
    dst: &mut CudaSlice<u8>,
    (rows, pitch): (std::ops::Range<usize>, usize),
    operation: &str,
    fill: impl Fn(usize, &mut [u8]) + Sync,
) -> Result<()> {
    super::invariant(
        pitch > 0 && pitch <= BAND_BYTES && dst.len() >= rows.end * pitch,
        "image upload",
        || format!("rows {rows:?} of {pitch} bytes into {} bytes", dst.len()),
    )?;
    let ordinal = stream.context().ordinal();
    let band_rows = BAND_BYTES / pitch;
    let mut y0 = rows.start;
    while y0 < rows.end {
        let y1 = (y0 + band_rows).min(rows.end);
        let len = (y1 - y0) * pitch;
        let mut staged = staging(stream, "pinned staging allocation")?;
        let host = staged
            .buffer
            .as_mut_slice()
            .map_err(driver_error("waiting for a staging buffer"))?;
        host[..len]
            .par_chunks_exact_mut(pitch)
            .with_min_len(16)
            .enumerate()
            .for_each(|(i, row)| fill(y0 + i, row));
        let band = &host[..len];
        let result = (|| -> Result<()> {
            stream
                .context()
                .bind_to_thread()
                .map_err(driver_error(operation))?;
            let mut target = dst.slice_mut(y0 * pitch..y1 * pitch);
            let (device, _sync) = target.device_ptr_mut(stream);
            // SAFETY: `band` and the target range are both `len` bytes; the staging buffer is not
            // written again before `copied` (recorded next) completes: every user of a pooled
            // buffer waits for it first, and dropping one waits too.
            unsafe { cudarc::driver::result::memcpy_htod_async(device, band, stream.cu_stream()) }
                .map_err(driver_error(operation))?;
            staged
                .copied
                .record(stream)
                .map_err(driver_error("event record"))
        })();
        if result.is_err() && stream.synchronize().is_err() {
            // The copy may have been queued without its event: with the stream broken too, leak the
            // page-locked band rather than hand it out (or free it) while the copy may still read it.
            std::mem::forget(staged);
        } else {
            give_back(ordinal, staged);
        }
        result?;
        y0 = y1;
    }
    Ok(())
}

/// Whether `bytes` lies in page-locked host memory the driver knows (allocated with
/// `cuMemHostAlloc` or registered with `cuMemHostRegister`, by clatch or anyone else in the
/// process): its first and last byte are both host memory of the unified address space.
pub(crate) fn is_pinned(stream: &Arc<CudaStream>, bytes: &[u8]) -> bool {
    let (Some(first), Some(last)) = (bytes.first(), bytes.last()) else {
        return false;
    };
    if stream.context().bind_to_thread().is_err() {
        return false;
    }
    [first as *const u8, last as *const u8].iter().all(|&p| {
        let mut kind: u32 = 0;
        let mut attribute = sys::CUpointer_attribute::CU_POINTER_ATTRIBUTE_MEMORY_TYPE;
        let mut data = [(&mut kind as *mut u32).cast::<std::ffi::c_void>()];
        // SAFETY: asks the driver about an address (never dereferenced); `kind` receives one
        // CUmemorytype value. The plural call answers memory the driver does not know with type 0
        // and success, where cuPointerGetAttribute returns an error that compute-sanitizer's memcheck
        // reports for every pageable image.
        let answered = unsafe {
            sys::cuPointerGetAttributes(1, &mut attribute, data.as_mut_ptr(), p as sys::CUdeviceptr)
        };
        answered == sys::cudaError_enum::CUDA_SUCCESS
            && kind == sys::CUmemorytype::CU_MEMORYTYPE_HOST as u32
    })
}

/// The most rows of `pitch` bytes one band of an upload holds (at least one).
pub(crate) fn band_rows(pitch: usize) -> usize {
    (BAND_BYTES / pitch.max(1)).max(1)
}

/// Queues one 2-D copy of rows `rows` (each `width` bytes, `stride` apart from `src` on the host)
/// into the same rows of `dst` (rows `pitch` apart) on `stream`: the copy engine reads the host memory
/// directly.
///
/// # Safety
/// `src` must stay valid and unchanged until the copy has run (the caller waits for the stream, or
/// keeps the memory alive until work queued after the copy has completed). Page-locked memory makes
/// the copy asynchronous; pageable memory is correct too, just slower.
pub(crate) unsafe fn copy_rows_2d(
    stream: &Arc<CudaStream>,
    dst: &mut CudaSlice<u8>,
    pitch: usize,
    (src, width, rows, stride): (&[u8], usize, std::ops::Range<usize>, usize),
    operation: &str,
) -> Result<()> {
    super::invariant(
        rows.start < rows.end
            && width <= pitch
            && width <= stride
            && src.len() >= stride * (rows.end - 1) + width
            && dst.len() >= pitch * rows.end,
        "image upload",
        || {
            format!(
                "rows {rows:?} of {width} bytes (stride {stride}, {} bytes) into {} bytes of pitch {pitch}",
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
        // Row `rows.start` of the source, in bounds: checked above.
        srcHost: src[rows.start * stride..].as_ptr().cast(),
        srcDevice: 0,
        srcArray: std::ptr::null_mut(),
        srcPitch: stride,
        dstXInBytes: 0,
        dstY: 0,
        dstMemoryType: sys::CUmemorytype::CU_MEMORYTYPE_DEVICE,
        dstHost: std::ptr::null_mut(),
        dstDevice: device + (rows.start * pitch) as sys::CUdeviceptr,
        dstArray: std::ptr::null_mut(),
        dstPitch: pitch,
        WidthInBytes: width,
        Height: rows.end - rows.start,
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
    let mut pool = pool().lock().unwrap_or_else(|p| p.into_inner());
    for (ordinal, idle) in std::mem::take(&mut pool.idle) {
        *pool.made.entry(ordinal).or_default() -= idle.len();
    }
}

#[cfg(feature = "internals")]
pub mod hooks;
