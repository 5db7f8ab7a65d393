//! Page-locked staging buffers that uploads from pageable memory go through, kept per device and
//! reused, so that repeated uploads are asynchronous DMA without a fresh `cuMemHostAlloc` each.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::{CudaEvent, CudaSlice, CudaStream, DevicePtrMut, PinnedHostSlice};

use super::alloc_pinned;
use crate::cuda::error::driver_error;
use crate::error::Result;
use crate::parallel::*;

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

/// The most rows of `pitch` bytes one band of an upload holds (at least one).
pub(crate) fn band_rows(pitch: usize) -> usize {
    (BAND_BYTES / pitch.max(1)).max(1)
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
    crate::cuda::invariant(
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

/// Drops the idle staging buffers of device `ordinal`, each once its copy has run:
/// [`crate::cuda::release_cached_memory`]. Buffers of uploads in progress come back later.
pub(crate) fn release_idle_staging(ordinal: usize) {
    let idle = {
        let mut pool = pool().lock().unwrap_or_else(|p| p.into_inner());
        let idle = pool.idle.remove(&ordinal).unwrap_or_default();
        *pool.made.entry(ordinal).or_default() -= idle.len();
        idle
    };
    // Dropped outside the lock: each waits for its last copy.
    drop(idle);
}

/// The staging buffers of device `ordinal` (idle or in use) and, of them, the idle ones.
#[cfg(feature = "internals")]
pub(crate) fn staging_buffers(ordinal: usize) -> (usize, usize) {
    let pool = pool().lock().unwrap_or_else(|p| p.into_inner());
    let made = pool.made.get(&ordinal).copied().unwrap_or(0);
    (made, pool.idle.get(&ordinal).map_or(0, Vec::len))
}
