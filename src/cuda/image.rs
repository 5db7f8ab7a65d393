//! An image on the device: a pitched 8-bit buffer and the texture object that reads it.

use std::sync::Arc;

use std::ops::Range;

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, DevicePtr, LaunchConfig, PushKernelArg, sys,
};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::{
    CLATCH_DETECT_TILE_Y, CLATCH_PYRAMID_TILE_X, CLATCH_PYRAMID_TILE_Y, CLATCH_SMOOTH_TILE_X,
    CLATCH_SMOOTH_TILE_Y,
};
use super::kernels;
use super::memory::arena::{Lane, Scratch};
use super::memory::{band_rows, copy_rows_2d, is_pinned, upload_rows};
use crate::describe::Smoothing;
use crate::error::{Error, Result};
use crate::gray_view::GrayView;

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
        // have run: its owner (an arena's buffer) waits for its stream before replacing or dropping it.
        unsafe {
            sys::cuTexObjectDestroy(self.0);
        }
    }
}

/// A texture over a pitched device buffer of `channels` unsigned bytes per texel: point filtering,
/// integer texels, clamp addressing, unnormalised coordinates (texel `(x, y)` is read at
/// `(x + 0.5, y + 0.5)`).
fn texture_object(
    buffer: &CudaSlice<u8>,
    stream: &Arc<CudaStream>,
    (width, height, pitch): (usize, usize, usize),
    channels: u32,
) -> Result<TextureObject> {
    let (ptr, _sync) = buffer.device_ptr(stream);
    // SAFETY: plain-old-data descriptors, zero-initialised as the driver API expects.
    let mut resource: sys::CUDA_RESOURCE_DESC = unsafe { std::mem::zeroed() };
    resource.resType = sys::CUresourcetype::CU_RESOURCE_TYPE_PITCH2D;
    resource.res.pitch2D = sys::CUDA_RESOURCE_DESC_st__bindgen_ty_1__bindgen_ty_4 {
        devPtr: ptr,
        format: sys::CUarray_format::CU_AD_FORMAT_UNSIGNED_INT8,
        numChannels: channels,
        width,
        height,
        pitchInBytes: pitch,
    };
    // SAFETY: as above.
    let mut desc: sys::CUDA_TEXTURE_DESC = unsafe { std::mem::zeroed() };
    desc.addressMode = [sys::CUaddress_mode::CU_TR_ADDRESS_MODE_CLAMP; 3];
    desc.filterMode = sys::CUfilter_mode::CU_TR_FILTER_MODE_POINT;
    desc.flags = sys::CU_TRSF_READ_AS_INTEGER;
    let mut handle: sys::CUtexObject = 0;
    // SAFETY: valid descriptors; the owner keeps the buffer alive longer than the texture.
    unsafe { sys::cuTexObjectCreate(&mut handle, &resource, &desc, std::ptr::null()) }
        .result()
        .map_err(driver_error("texture object creation"))?;
    Ok(TextureObject(handle))
}

/// A gray image uploaded once, read by kernels through `texture` (one byte per texel, see
/// [`texture_object`]), and, for description, through the quad texture built by
/// `clatch_build_quads` (kernels/describe.cu): four bilinear neighbours per texel, of the pixels
/// themselves or of their smoothed copy ([`Smoothing`]). Its buffers come from a lane's arena, with
/// the texture objects over them (kept with the buffers for the next image of the same shape), and
/// are used only on that lane's stream.
#[derive(Debug)]
pub struct DeviceImage {
    texture: u64,
    quads: Option<u64>,
    pixels: Scratch<u8>,
    quad_texels: Option<Scratch<u8>>,
    /// The smoothing the quad texture was built with.
    quads_smoothing: Smoothing,
    pitch: usize,
    width: usize,
    height: usize,
    /// See [`DeviceImage::arrivals`].
    arrivals: Vec<(usize, CudaEvent)>,
    /// The lane's stream, when the image arrives on the copy stream: it waits for the last band
    /// before the buffer goes back to the arena ([`Drop`]).
    waits: Option<Arc<CudaStream>>,
}

impl Drop for DeviceImage {
    fn drop(&mut self) {
        // The pixel buffer goes back to the lane's arena after this; its next user queues on the
        // lane's stream, which must not overtake a copy still writing it on the copy stream.
        if let (Some(stream), Some((_, last))) = (&self.waits, self.arrivals.last()) {
            let _ = stream.wait(last);
        }
    }
}

/// How long the caller's image stays valid, which decides how it is uploaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ImageLife {
    /// Only during the call: copied into pinned staging buffers before the call returns.
    Call,
    /// Until the work queued with it has completed (a blocking call, or a batch whose images outlive
    /// it, both of which wait for their streams before returning, errors included): an image in
    /// page-locked memory is then read by the copy engine straight from where it is.
    Work,
}

impl DeviceImage {
    /// Copies `image` to the device with the row pitch the texture unit needs: straight from the image
    /// by the copy engine (2-D copies) when it is in page-locked memory and outlives the work
    /// ([`ImageLife::Work`]), else through pinned staging buffers ([`upload_rows`]). An image of one
    /// band is copied on `lane`'s stream. A larger one is copied band by band on the lane's copy
    /// stream, each band announced by an event ([`Self::arrivals`]), so that detection can start on
    /// the first bands while the others are still on their way; every other use of the pixels on the
    /// lane's stream waits for the last band first ([`Self::arrived`]).
    pub(crate) fn upload(
        dev: &GpuDevice,
        lane: &Lane,
        image: &GrayView,
        life: ImageLife,
    ) -> Result<Self> {
        let (width, height) = (image.width(), image.height());
        let pitch = width.div_ceil(dev.pitch_alignment) * dev.pitch_alignment;
        let mut pixels = lane.scratch::<u8>(pitch * height, "image upload")?;
        let stride = image.stride();
        let bytes = &image.data()[..stride * (height - 1) + width];
        let direct = life == ImageLife::Work && is_pinned(lane, bytes);
        let copy_band = |stream: &Arc<CudaStream>, pixels: &mut Scratch<u8>, rows: Range<usize>| {
            if direct {
                // SAFETY: ImageLife::Work: the image stays valid until the work queued after this
                // copy has completed, which the caller waits for before returning (errors included).
                unsafe {
                    copy_rows_2d(
                        stream,
                        pixels.whole_mut(),
                        pitch,
                        (bytes, width, rows, stride),
                        "image upload",
                    )
                }
            } else {
                // The copy into pinned memory is host time every queued image pays (about 0.2 ms for
                // 1080p on one core): rows in parallel.
                upload_rows(
                    stream,
                    pixels.whole_mut(),
                    (rows, pitch),
                    "image upload",
                    |y, row| {
                        row[..width].copy_from_slice(image.row(y));
                        row[width..].fill(0);
                    },
                )
            }
        };
        let bands = height.div_ceil(band_rows(pitch));
        if bands <= 1 {
            copy_band(lane, &mut pixels, 0..height)?;
            return Self::from_pixels(pixels, lane, (width, height, pitch), Vec::new());
        }
        // Bands of equal height, whole tile rows of the detector each.
        let tile = CLATCH_DETECT_TILE_Y as usize;
        let rows_per_band = height.div_ceil(bands).div_ceil(tile) * tile;
        // The buffer may come from an earlier call on the lane's stream: the copy stream writes it
        // only after that call's work there.
        let copy = lane.copy_stream();
        let free = lane
            .record_event(None)
            .map_err(driver_error("event record"))?;
        copy.wait(&free)
            .map_err(driver_error("image upload: ordering the copy stream"))?;
        #[cfg(feature = "internals")]
        hooks::BANDS.set(hooks::BANDS.get() + bands);
        let mut arrivals = Vec::with_capacity(bands);
        let mut y0 = 0;
        let mut queued = Ok(());
        while y0 < height && queued.is_ok() {
            let y1 = (y0 + rows_per_band).min(height);
            let band = copy_band(copy, &mut pixels, y0..y1).and_then(|()| {
                copy.record_event(None)
                    .map_err(driver_error("event record"))
            });
            match band {
                Ok(arrived) => {
                    arrivals.push((y1, arrived));
                    y0 = y1;
                }
                Err(e) => queued = Err(e),
            }
        }
        if queued.is_err() {
            // Part of the failed band may be queued already: one more event, after it, for the drop
            // to wait for (the rows it announces are those of the bands before).
            if let Ok(after) = copy.record_event(None) {
                arrivals.push((y0, after));
            }
        }
        // Even on an error, the image (and its arrivals so far) is built, so that dropping it makes
        // the lane's stream wait for the bands queued before the buffer goes back to the arena.
        let image = Self::from_pixels(pixels, lane, (width, height, pitch), arrivals);
        queued?;
        image
    }

    /// Wraps `height` rows of `pitch` bytes (the first `width` of each are the image) with its
    /// texture; `arrivals` as [`Self::arrivals`].
    fn from_pixels(
        mut pixels: Scratch<u8>,
        stream: &Arc<CudaStream>,
        (width, height, pitch): (usize, usize, usize),
        arrivals: Vec<(usize, CudaEvent)>,
    ) -> Result<Self> {
        let shape = (width, height, pitch);
        let texture = pixels.texture((shape, 1), |buffer| {
            texture_object(buffer, stream, shape, 1)
        });
        let image = Self {
            texture: *texture.as_ref().unwrap_or(&0),
            quads: None,
            pixels,
            quad_texels: None,
            quads_smoothing: Smoothing::None,
            pitch,
            width,
            height,
            waits: (!arrivals.is_empty()).then(|| stream.clone()),
            arrivals,
        };
        texture?;
        Ok(image)
    }

    /// The bands of the image still arriving on the copy stream: after event `e` of `(rows, e)`, the
    /// first `rows` rows are on the device. Empty when the whole image was copied on the lane's
    /// stream. Detection waits for each band in turn ([`super::detect`]).
    pub(crate) fn arrivals(&self) -> &[(usize, CudaEvent)] {
        &self.arrivals
    }

    /// Makes `stream` (the lane's) wait until the whole image has arrived: before any use of its
    /// pixels but the detector's band by band suppression. Does nothing for an image copied on the
    /// lane's stream itself.
    pub(crate) fn arrived(&self, stream: &Arc<CudaStream>) -> Result<()> {
        match self.arrivals.last() {
            Some((_, last)) => stream
                .wait(last)
                .map_err(driver_error("waiting for the image's upload")),
            None => Ok(()),
        }
    }

    /// Queues the next pyramid level: `width` x `height` pixels downscaled from this image by the 16.16
    /// factor `step` (`kernels/pyramid.cu`, reproducing [`crate::pyramid::cpu::downscale`]).
    pub(crate) fn downscale(
        &self,
        dev: &GpuDevice,
        lane: &Lane,
        step: i64,
        (width, height): (usize, usize),
    ) -> Result<Self> {
        self.arrived(lane)?;
        let pitch = width.div_ceil(dev.pitch_alignment) * dev.pitch_alignment;
        let mut pixels = lane.scratch::<u8>(pitch * height, "pyramid level")?;
        let (src_pitch, src_w, src_h) = (self.pitch as i32, self.width as i32, self.height as i32);
        let (dst_pitch, dst_w, dst_h) = (pitch as i32, width as i32, height as i32);
        let mut launch = lane.launch_builder(dev.kernel(kernels::DOWNSCALE));
        launch
            .arg(self.pixels.whole())
            .arg(&src_pitch)
            .arg(&src_w)
            .arg(&src_h)
            .arg(pixels.whole_mut())
            .arg(&dst_pitch)
            .arg(&dst_w)
            .arg(&dst_h)
            .arg(&step);
        let tile = (
            CLATCH_PYRAMID_TILE_X as usize,
            CLATCH_PYRAMID_TILE_Y as usize,
        );
        let config = LaunchConfig {
            grid_dim: (
                width.div_ceil(tile.0) as u32,
                height.div_ceil(tile.1) as u32,
                1,
            ),
            block_dim: (tile.0 as u32, tile.1 as u32, 1),
            shared_mem_bytes: 0,
        };
        // SAFETY: matches clatch_downscale's signature; the source holds at least `self.height` rows
        // of `self.pitch` bytes and every read is clamped inside them (taps are below the source
        // sides); `pixels` holds at least `height` rows of `pitch` bytes, of which the first `width`
        // are written (and only those are read, through the texture's width).
        unsafe { launch.launch(config) }.map_err(driver_error("clatch_downscale"))?;
        Self::from_pixels(pixels, lane, (width, height, pitch), Vec::new())
    }

    /// Queues a smoothed copy of the pixels (same size and pitch) on `stream`:
    /// `clatch_smooth_binomial3` or `clatch_smooth_binomial5` (kernels/describe.cu), reproducing
    /// [`crate::describe::cpu::smooth`]. `None` for [`Smoothing::None`] (the pixels themselves).
    pub(crate) fn smoothed(
        &self,
        dev: &GpuDevice,
        lane: &Lane,
        smoothing: Smoothing,
    ) -> Result<Option<Scratch<u8>>> {
        let kernel = match smoothing {
            Smoothing::None => return Ok(None),
            Smoothing::Binomial3 => kernels::SMOOTH_BINOMIAL3,
            Smoothing::Binomial5 => kernels::SMOOTH_BINOMIAL5,
        };
        self.arrived(lane)?;
        let mut smoothed = lane.scratch::<u8>(self.pitch * self.height, "smoothed image")?;
        let (pitch, width, height) = (self.pitch as i32, self.width as i32, self.height as i32);
        let mut launch = lane.launch_builder(dev.kernel(kernel));
        launch
            .arg(self.pixels.whole())
            .arg(&pitch)
            .arg(&width)
            .arg(&height)
            .arg(smoothed.whole_mut())
            .arg(&pitch);
        let tile = (CLATCH_SMOOTH_TILE_X as usize, CLATCH_SMOOTH_TILE_Y as usize);
        let config = LaunchConfig {
            grid_dim: (
                self.width.div_ceil(tile.0) as u32,
                self.height.div_ceil(tile.1) as u32,
                1,
            ),
            block_dim: (tile.0 as u32, tile.1 as u32, 1),
            shared_mem_bytes: 0,
        };
        // SAFETY: matches the kernel's signature (source, pitch, width, height, destination, pitch);
        // both buffers hold at least `height` rows of `pitch` bytes; every read is clamped inside the
        // image and only pixels with x < width, y < height are written (and read afterwards).
        unsafe { launch.launch(config) }.map_err(driver_error(kernel.name()))?;
        Ok(Some(smoothed))
    }

    /// Queues the build of the quad texture the describe kernels read (once per image), from the
    /// pixels smoothed by `smoothing` ([`Self::smoothed`]). Asking again with the same smoothing does
    /// nothing; with another one is an internal error (kernels queued earlier may still read it).
    pub fn build_quads(
        &mut self,
        dev: &GpuDevice,
        lane: &Lane,
        smoothing: Smoothing,
    ) -> Result<()> {
        if self.quads.is_some() {
            if self.quads_smoothing == smoothing {
                return Ok(());
            }
            return Err(Error::Internal {
                operation: "describe",
                message: format!(
                    "the quad texture was built with {:?}, not {smoothing:?}",
                    self.quads_smoothing
                ),
            });
        }
        self.arrived(lane)?;
        // The smoothed copy goes back to the arena when it goes out of scope below: the next user of
        // it queues on this stream, after clatch_build_quads has read it.
        let smoothed = self.smoothed(dev, lane, smoothing)?;
        let source = smoothed.as_ref().unwrap_or(&self.pixels).whole();
        let (qw, qh) = (self.width + 1, self.height + 1);
        let row_bytes = qw * 4;
        let pitch = row_bytes.div_ceil(dev.pitch_alignment) * dev.pitch_alignment;
        let mut texels = lane.scratch::<u8>(pitch * qh, "quad texture")?;
        let (pitch_i, width, height) = (self.pitch as i32, self.width as i32, self.height as i32);
        let quad_pitch = (pitch / 4) as i32;
        let mut launch = lane.launch_builder(dev.kernel(kernels::BUILD_QUADS));
        launch
            .arg(source)
            .arg(&pitch_i)
            .arg(&width)
            .arg(&height)
            .arg(texels.whole_mut())
            .arg(&quad_pitch);
        let config = LaunchConfig {
            grid_dim: (qw.div_ceil(32) as u32, qh.div_ceil(8) as u32, 1),
            block_dim: (32, 8, 1),
            shared_mem_bytes: 0,
        };
        // SAFETY: matches clatch_build_quads's signature; `source` holds at least height rows of
        // `pitch` bytes, `texels` at least (height + 1) rows of `quad_pitch` 4-byte texels, of which
        // width + 1 are written per row (pitch is a multiple of the texture pitch alignment, itself of
        // 4), and only those are read, through the texture's width.
        unsafe { launch.launch(config) }.map_err(driver_error("clatch_build_quads"))?;
        let shape = (qw, qh, pitch);
        self.quads =
            Some(texels.texture((shape, 4), |buffer| texture_object(buffer, lane, shape, 4))?);
        self.quad_texels = Some(texels);
        self.quads_smoothing = smoothing;
        Ok(())
    }

    /// The pixels read back, row-major with stride = width (waits for the stream).
    pub(crate) fn download(&self, stream: &Arc<CudaStream>) -> Result<Vec<u8>> {
        self.download_like(stream, &self.pixels)
    }

    /// `buffer`, laid out as this image's pixels (such as [`Self::smoothed`]'s), read back row-major
    /// with stride = width (waits for the stream).
    pub(crate) fn download_like(
        &self,
        stream: &Arc<CudaStream>,
        buffer: &Scratch<u8>,
    ) -> Result<Vec<u8>> {
        self.arrived(stream)?;
        let pitched = stream
            .clone_dtoh(&buffer.whole().slice(..self.pitch * self.height))
            .map_err(driver_error("reading an image back"))?;
        Ok(pitched
            .chunks_exact(self.pitch)
            .flat_map(|row| &row[..self.width])
            .copied()
            .collect())
    }

    /// The quad texture's handle, once [`Self::build_quads`] was queued.
    pub fn quads(&self) -> Option<u64> {
        self.quads
    }

    /// The texture handle for kernel arguments. Kernels that read it wait for [`Self::arrived`]
    /// first (or, the detector's suppression, for the bands they read).
    pub fn texture(&self) -> u64 {
        self.texture
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

/// Test hooks of the uploads (the `internals` feature only): not part of the API.
#[cfg(feature = "internals")]
pub mod hooks {
    thread_local! {
        pub(super) static BANDS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    }

    /// How many bands this thread's image uploads have queued on copy streams so far: images of more
    /// than one band only ([`super::DeviceImage::upload`]), so a test can check that the banded path ran.
    pub fn band_arrivals() -> usize {
        BANDS.get()
    }
}
