//! Device allocations and uploads that report failures as typed errors, and the pinned host staging
//! buffers uploads go through.

use std::sync::Arc;

use cudarc::driver::{
    CudaSlice, CudaStream, DevicePtrMut, DeviceRepr, PinnedHostSlice, ValidAsZeroBits, sys,
};

pub(crate) mod arena;
mod staging;

pub(crate) use staging::{band_rows, release_idle_staging, upload_rows};

use super::error::driver_error;
use crate::error::{Error, Result};

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

#[cfg(feature = "internals")]
pub mod hooks;
