//! Test and bench hooks of `cuda/matching_tensor/` (the `internals` feature only): not part of the API.

use super::*;
use crate::cuda::device::time_launches;

/// The device's int8 `mma.sync` rate in multiply-adds per second, measured by `clatch_mma_s8_rate`
/// (8 warps a block, `blocks_per_sm` blocks per multiprocessor, CUDA events, median of 5 after a
/// warm-up): the bound of the tensor kNN, which issues the same instruction (with 1 block per
/// multiprocessor: its own occupancy).
pub fn measure_mma_s8_rate(dev: &GpuDevice, blocks_per_sm: usize) -> Result<f64> {
    dev.load_bench_kernels()?;
    if !dev.has_tensor_matcher() {
        return Err(dev
            .check_match_kernel(MatchKernel::Tensor, 1)
            .expect_err("no tensor cores"));
    }
    const ITERATIONS: u32 = 20_000;
    let stream = dev.new_stream()?;
    let mut sink = alloc_zeros::<i32>(&stream, THREADS as usize, "mma rate sink")?;
    let blocks = (blocks_per_sm.max(1) * dev.multiprocessors) as u32;
    let times = time_launches(dev, &stream, 1, 5, || {
        let mut launch = stream.launch_builder(dev.kernel(crate::cuda::kernels::MMA_S8_RATE));
        launch.arg(&ITERATIONS).arg(&mut sink);
        // SAFETY: matches clatch_mma_s8_rate(unsigned, int*); `sink` holds THREADS ints.
        unsafe {
            launch.launch(LaunchConfig {
                grid_dim: (blocks, 1, 1),
                block_dim: (THREADS, 1, 1),
                shared_mem_bytes: 0,
            })
        }
        .map_err(driver_error("clatch_mma_s8_rate"))?;
        Ok(())
    })?;
    let mut times = times;
    times.sort_by(f32::total_cmp);
    let seconds = times[times.len() / 2] as f64 * 1e-3;
    // Per warp and iteration: 8 MMAs of 16 x 8 x 32 multiply-adds.
    let macs = blocks as f64 * CLATCH_TENSOR_WARPS as f64 * ITERATIONS as f64 * 8.0 * 4096.0;
    Ok(macs / seconds)
}
