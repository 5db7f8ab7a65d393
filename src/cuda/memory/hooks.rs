//! Test and bench hooks of `cuda/memory/` (the `internals` feature only): not part of the API.

use super::*;

/// Asks for `bytes` of device memory and frees them again: lets tests check that exhaustion is a
/// typed error and that the context stays usable afterwards.
pub fn probe_allocation(ordinal: usize, bytes: usize) -> Result<()> {
    let dev = crate::cuda::device(ordinal)?;
    let stream = dev.new_stream()?;
    let buffer = alloc_zeros::<u8>(&stream, bytes, "probe allocation")?;
    stream
        .synchronize()
        .map_err(driver_error("probe allocation"))?;
    drop(buffer);
    Ok(())
}

/// Makes the allocation after `after` more of this thread's device allocations fail with
/// `Error::DeviceOutOfMemory` (once; `None` clears it). Returns whether the last injected failure was
/// used up, i.e. whether the calls since the previous setting reached that allocation.
pub fn fail_allocation(after: Option<usize>) -> bool {
    let used = FAIL_AFTER.get().is_none();
    FAIL_AFTER.set(after);
    used
}

/// Free and total device memory of device `ordinal`, in bytes (`cuMemGetInfo`).
pub fn device_memory(ordinal: usize) -> Result<(usize, usize)> {
    let dev = crate::cuda::device(ordinal)?;
    dev.ctx
        .mem_get_info()
        .map_err(driver_error("reading free device memory"))
}

/// How many device and pinned host allocations this thread's calls have made so far (every
/// allocation site of the crate counts, arena growth included): a warm steady state adds none.
pub fn allocations() -> usize {
    ALLOCATIONS.get()
}

/// Of [`allocations`], those of device memory (arena growth, uploads of tables), not pinned host
/// memory.
pub fn device_allocations() -> usize {
    DEVICE_ALLOCATIONS.get()
}

/// Frees every buffer the crate keeps between calls on device `ordinal` that no call holds now: the
/// device's idle streams with their scratch arenas, the pinned staging buffers and the descriptor
/// weight tables. The next call starts cold and allocates again (so allocation-failure tests reach
/// every site). Meant for between calls: a call in flight keeps what it holds (its lane's buffers,
/// and the weight table its describe kernels read, which its lane keeps alive until they have run).
pub fn release_cached_memory(ordinal: usize) -> Result<()> {
    let dev = crate::cuda::device(ordinal)?;
    let sync = || {
        dev.ctx
            .synchronize()
            .map_err(driver_error("releasing cached memory"))
    };
    sync()?;
    dev.lanes.clear();
    release_idle_staging(ordinal);
    dev.clear_weights();
    sync()
}

/// Drops the device's own references to its descriptor weight tables at once, without waiting for
/// anything: work queued with a table must still read it (its lane keeps it alive).
pub fn forget_weight_tables(ordinal: usize) -> Result<()> {
    crate::cuda::device(ordinal)?.clear_weights();
    Ok(())
}

/// The page-locked staging buffers of device `ordinal`: all of them (idle or in use), and the idle.
pub fn staging_buffers(ordinal: usize) -> (usize, usize) {
    staging::staging_buffers(ordinal)
}

/// Page-locked host bytes (tests and benches: images in pinned memory, as a camera or a decoder
/// writing into `cuMemHostAlloc` memory would hold them). Counts as an allocation.
pub struct PinnedBytes(PinnedHostSlice<u8>);

impl PinnedBytes {
    /// `len` bytes (at least one) of cached page-locked memory for device `ordinal`, zeroed.
    pub fn new(ordinal: usize, len: usize) -> Result<Self> {
        let dev = crate::cuda::device(ordinal)?;
        let stream = dev.ctx.default_stream();
        let mut bytes = alloc_pinned::<u8>(&stream, len, false, "pinned host buffer")?;
        bytes
            .as_mut_slice()
            .map_err(driver_error("pinned host buffer"))?
            .fill(0);
        Ok(Self(bytes))
    }

    /// The bytes.
    pub fn as_slice(&self) -> Result<&[u8]> {
        self.0
            .as_slice()
            .map_err(driver_error("pinned host buffer"))
    }

    /// The bytes, to write.
    pub fn as_mut_slice(&mut self) -> Result<&mut [u8]> {
        self.0
            .as_mut_slice()
            .map_err(driver_error("pinned host buffer"))
    }
}

/// Whether the GPU upload would read `bytes` straight from where they are (page-locked memory the
/// driver knows), for device `ordinal`.
pub fn is_pinned_for_upload(ordinal: usize, bytes: &[u8]) -> Result<bool> {
    let dev = crate::cuda::device(ordinal)?;
    Ok(is_pinned(&dev.ctx.default_stream(), bytes))
}
