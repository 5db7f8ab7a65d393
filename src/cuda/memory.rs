//! Device allocations and uploads that report failures as typed errors, and the pinned host staging
//! buffers uploads go through.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, DeviceRepr, PinnedHostSlice, ValidAsZeroBits,
};

use super::device::driver_error;
use crate::error::{Error, Result};

// With the `internals` feature, tests can make the `n`-th device allocation of a thread fail
// ([`hooks::fail_allocation`]), so that every allocation site's error path runs on a real device.
#[cfg(feature = "internals")]
thread_local! {
    static FAIL_AFTER: std::cell::Cell<Option<usize>> = const { std::cell::Cell::new(None) };
}

/// The failure injected at this allocation, if any (always none without the `internals` feature).
fn injected_failure(operation: &str, bytes: usize) -> Result<()> {
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

/// Uploads `len` bytes written by `fill` into a pinned staging buffer, then copied to a new device
/// buffer on `stream`. The staging buffer returns to the pool with an event recorded after the copy; a
/// later user takes it only once that event is complete. Nothing else waits for the copy: with event
/// tracking off (`device.rs`) cudarc never records the buffer's own event, so its `as_mut_slice` and
/// drop return at once; a buffer the pool has no room for is dropped only after the copy's event.
pub(crate) fn upload_staged(
    stream: &Arc<CudaStream>,
    len: usize,
    operation: &str,
    fill: impl FnOnce(&mut [u8]),
) -> Result<CudaSlice<u8>> {
    injected_failure(operation, len)?;
    let ctx = stream.context();
    let key = (ctx.ordinal(), len);
    let reused = pool()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get_mut(&key)
        .and_then(|kept| {
            let idle = kept.iter().position(|(_, copied)| copied.is_complete())?;
            Some(kept.swap_remove(idle).0)
        });
    let mut staging = match reused {
        Some(buffer) => buffer,
        // SAFETY: the buffer is fully written by `fill` below before it is read.
        None => unsafe { ctx.alloc_pinned::<u8>(len) }
            .map_err(|e| with_bytes(driver_error("pinned staging allocation")(e), len))?,
    };
    let host = staging
        .as_mut_slice()
        .map_err(driver_error("waiting for a staging buffer"))?;
    fill(host);
    let device = stream
        .clone_htod(&staging)
        .map_err(|e| with_bytes(driver_error(operation)(e), len))?;
    let copied = match stream.record_event(None) {
        Ok(copied) => copied,
        Err(e) => {
            // No event to wait on before the buffer is freed: wait for the stream instead, and leak
            // the buffer if that fails too (the copy may still be pending).
            if stream.synchronize().is_err() {
                std::mem::forget(staging);
            }
            return Err(driver_error("event record")(e));
        }
    };
    let mut pool = pool().lock().unwrap_or_else(|p| p.into_inner());
    let kept = pool.entry(key).or_default();
    if kept.len() < kept_for(len) {
        kept.push((staging, copied));
        return Ok(device);
    }
    drop(pool);
    // No room: the buffer is freed, but only once the copy has read it.
    if let Err(e) = copied.synchronize() {
        // The copy may still be pending on a broken context: leak the page-locked memory rather than
        // free it under the DMA.
        std::mem::forget(staging);
        return Err(driver_error(operation)(e));
    }
    Ok(device)
}

#[cfg(feature = "internals")]
pub mod hooks;
