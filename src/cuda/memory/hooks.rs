//! Test and bench hooks of `cuda/memory.rs` (the `internals` feature only): not part of the API.

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
