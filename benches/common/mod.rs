//! Shared by the GPU benches: the device, or the `skipped` line when there is none.

/// CUDA device 0, or `None` after printing `skipped: no CUDA device (why)`.
#[cfg(feature = "cuda")]
pub fn device_or_skip() -> Option<std::sync::Arc<clatch::cuda::hooks::GpuDevice>> {
    match clatch::cuda::hooks::device(0) {
        Ok(dev) => Some(dev),
        Err(e) => {
            println!("skipped: no CUDA device ({e})");
            None
        }
    }
}
