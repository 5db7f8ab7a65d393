//! An image on the device: a pitched 8-bit buffer and the texture object that reads it.

use std::sync::Arc;

use cudarc::driver::{CudaSlice, CudaStream, DevicePtr, sys};

use super::device::{GpuDevice, driver_error};
use super::memory::upload_staged;
use crate::error::Result;
use crate::image::GrayView;

/// A texture object; destroyed on drop.
#[derive(Debug)]
pub struct TextureObject(sys::CUtexObject);

impl TextureObject {
    /// The handle kernels take as `cudaTextureObject_t`.
    pub fn handle(&self) -> u64 {
        self.0
    }
}

impl Drop for TextureObject {
    fn drop(&mut self) {
        // SAFETY: the handle came from cuTexObjectCreate and is destroyed once. Launches that use it
        // were synchronised by the owner before dropping (DeviceImage keeps the buffer alive longer).
        unsafe {
            sys::cuTexObjectDestroy(self.0);
        }
    }
}

/// A gray image uploaded once, read by kernels through `texture` (point filtering, integer texels,
/// clamp addressing, unnormalised coordinates: texel `(x, y)` is read at `(x + 0.5, y + 0.5)`).
#[derive(Debug)]
pub struct DeviceImage {
    // Declared before `pixels` so it is destroyed first.
    texture: TextureObject,
    #[allow(dead_code)]
    pixels: CudaSlice<u8>,
    width: usize,
    height: usize,
}

impl DeviceImage {
    /// Copies `image` to the device on `stream` with the row pitch the texture unit needs.
    pub fn upload(dev: &GpuDevice, stream: &Arc<CudaStream>, image: &GrayView) -> Result<Self> {
        let (width, height) = (image.width(), image.height());
        let pitch = width.div_ceil(dev.pitch_alignment) * dev.pitch_alignment;
        let pixels = upload_staged(stream, pitch * height, "image upload", |staged| {
            for (y, row) in staged.chunks_exact_mut(pitch).enumerate() {
                row[..width].copy_from_slice(image.row(y));
                row[width..].fill(0);
            }
        })?;
        let texture = {
            let (ptr, _sync) = pixels.device_ptr(stream);
            // SAFETY: plain-old-data descriptors, zero-initialised as the driver API expects.
            let mut resource: sys::CUDA_RESOURCE_DESC = unsafe { std::mem::zeroed() };
            resource.resType = sys::CUresourcetype::CU_RESOURCE_TYPE_PITCH2D;
            resource.res.pitch2D = sys::CUDA_RESOURCE_DESC_st__bindgen_ty_1__bindgen_ty_4 {
                devPtr: ptr,
                format: sys::CUarray_format::CU_AD_FORMAT_UNSIGNED_INT8,
                numChannels: 1,
                width,
                height,
                pitchInBytes: pitch,
            };
            let mut desc: sys::CUDA_TEXTURE_DESC = unsafe { std::mem::zeroed() };
            desc.addressMode = [sys::CUaddress_mode::CU_TR_ADDRESS_MODE_CLAMP; 3];
            desc.filterMode = sys::CUfilter_mode::CU_TR_FILTER_MODE_POINT;
            desc.flags = sys::CU_TRSF_READ_AS_INTEGER;
            let mut handle: sys::CUtexObject = 0;
            // SAFETY: valid descriptors; the buffer outlives the texture (field order).
            unsafe { sys::cuTexObjectCreate(&mut handle, &resource, &desc, std::ptr::null()) }
                .result()
                .map_err(driver_error("texture object creation"))?;
            TextureObject(handle)
        };
        Ok(Self {
            texture,
            pixels,
            width,
            height,
        })
    }

    /// The texture handle for kernel arguments.
    pub fn texture(&self) -> u64 {
        self.texture.handle()
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }
}
