//! Test and bench hooks of `cuda/pyramid/` (the `internals` feature only): not part of the API.

use super::*;
use crate::cuda::image::ImageLife;

/// The pyramid levels of `image` for a detector margin of `margin` as the GPU builds them, level 0
/// first, each row-major with stride = width: for comparing with [`crate::pyramid::cpu::build_levels`].
pub fn debug_pyramid_levels(
    dev: &GpuDevice,
    image: &GrayView,
    p: &Pyramid,
    margin: usize,
) -> Result<Vec<Vec<u8>>> {
    let stream = Leased::take(dev)?;
    let plan = Plan::new(p, image.width(), image.height(), margin);
    let mut level = DeviceImage::upload(dev, &stream, image, ImageLife::Call)?;
    let mut out = vec![level.download(&stream)?];
    for &size in &plan.sizes[1..] {
        level = level.downscale(dev, &stream, plan.step, size)?;
        out.push(level.download(&stream)?);
    }
    Ok(out)
}
