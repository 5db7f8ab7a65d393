//! Scratch memory reused across calls: each stream's device buffers and pinned host buffers, kept
//! after a call and handed to the next call on the same stream, so that a steady state of calls of
//! similar size allocates nothing.
//!
//! Why reuse is safe: a device buffer of a stream's [`Arena`] is only ever used by work queued on that
//! stream (kernels and copies); clatch never lets one hop to another stream (the reason event tracking
//! is off, `device.rs`). Returning it to the arena when its owner drops, even while that work is still
//! queued, is therefore safe: whoever takes it next queues its own work on the same stream, after. This
//! is the argument of cudarc's stream-ordered free. Pinned host buffers are read and written by the
//! host too, so each carries cudarc's event of its last copy, and the host waits for it before touching
//! the buffer ([`cudarc::driver::PinnedHostSlice::as_slice`] synchronises on it).
//!
//! Buffers grow geometrically (capacities rounded up to eighths of a power of two) and never shrink; a
//! call takes the smallest free buffer that holds what it asks for. Everything is freed with the arena,
//! i.e. with the stream ([`Lane`]).

use std::ops::Deref;
use std::sync::{Arc, Mutex};

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, CudaView, CudaViewMut, DevicePtr, DevicePtrMut, DeviceRepr,
    DriverError, PinnedHostSlice, ValidAsZeroBits,
};

use super::device::{GpuDevice, driver_error};
use super::memory::{alloc_pinned, alloc_zeros};
use super::texture::TextureObject;
use crate::error::Result;
use crate::keypoint::KeyPoint;

/// The shape a texture object was created with over a buffer: (width, height, pitch) and channels.
pub(crate) type TextureKey = ((usize, usize, usize), u32);

/// A free device buffer, with the texture object last created over it (kept: creating one is a driver
/// call per level and per image).
pub(crate) struct KeptDevice<T> {
    // Declared before the buffer: the texture is destroyed first.
    texture: Option<(TextureKey, TextureObject)>,
    buffer: CudaSlice<T>,
}

/// A free pinned host buffer and the event recorded after the last copy queued on it.
pub(crate) struct KeptHost<T> {
    buffer: PinnedHostSlice<T>,
    copied: CudaEvent,
}

impl<T> Drop for KeptHost<T> {
    fn drop(&mut self) {
        // The buffer is freed after this: a copy still queued on it must have run.
        let _ = self.copied.synchronize();
    }
}

/// The free buffers of one element type.
pub(crate) struct Lists<T> {
    device: Vec<KeptDevice<T>>,
    host: Vec<KeptHost<T>>,
}

impl<T> Default for Lists<T> {
    fn default() -> Self {
        Self {
            device: Vec::new(),
            host: Vec::new(),
        }
    }
}

/// Free buffers of every element type the extraction path uses.
#[derive(Default)]
pub(crate) struct Free {
    bytes: Lists<u8>,
    words: Lists<u32>,
    ints: Lists<i32>,
    longs: Lists<u64>,
    keypoints: Lists<KeyPoint>,
}

/// An element type an [`Arena`] keeps buffers of.
pub(crate) trait Pooled: DeviceRepr + ValidAsZeroBits + Copy + Send + 'static {
    #[doc(hidden)]
    fn lists(free: &mut Free) -> &mut Lists<Self>;
}

macro_rules! pooled {
    ($($t:ty => $field:ident),* $(,)?) => {$(
        impl Pooled for $t {
            fn lists(free: &mut Free) -> &mut Lists<Self> {
                &mut free.$field
            }
        }
    )*};
}
pooled!(u8 => bytes, u32 => words, i32 => ints, u64 => longs, KeyPoint => keypoints);

/// The capacity a buffer of at least `len` elements is allocated with: `len` rounded up to an eighth
/// of its power of two, so that growth is geometric and a slightly larger call of a similar size
/// reuses what an earlier one allocated.
pub(crate) fn capacity_for(len: usize) -> usize {
    let len = len.max(1);
    let power = len
        .checked_next_power_of_two()
        .unwrap_or(1 << (usize::BITS - 1));
    let unit = (power / 8).max(1);
    len.div_ceil(unit).saturating_mul(unit)
}

/// The buffers one stream keeps between calls.
#[derive(Default)]
pub(crate) struct Arena {
    free: Mutex<Free>,
}

impl std::fmt::Debug for Arena {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Arena").finish_non_exhaustive()
    }
}

impl Drop for Arena {
    fn drop(&mut self) {
        // Texture objects are destroyed with their buffers: work queued on the stream may still read
        // them (a pending result dropped unwaited), so wait for the stream first. All buffers of an
        // arena belong to one stream.
        let free = self.free.get_mut().unwrap_or_else(|p| p.into_inner());
        if let Some(kept) = free.bytes.device.iter().find(|k| k.texture.is_some()) {
            let _ = kept.buffer.stream().synchronize();
        }
    }
}

impl Arena {
    fn lock(&self) -> std::sync::MutexGuard<'_, Free> {
        self.free.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// A stream and the arena of its buffers. Derefs to the stream, so it goes wherever a stream does;
/// clones share both.
#[derive(Clone, Debug)]
pub(crate) struct Lane {
    stream: Arc<CudaStream>,
    /// Copies of large images go here, so that detection on their first bands overlaps the copy of
    /// the rest (`DeviceImage::upload`); ordered against `stream` by events only.
    copy: Arc<CudaStream>,
    arena: Arc<Arena>,
}

impl Deref for Lane {
    type Target = Arc<CudaStream>;
    fn deref(&self) -> &Arc<CudaStream> {
        &self.stream
    }
}

impl Lane {
    /// A new stream on `dev` with an empty arena.
    pub(crate) fn new(dev: &GpuDevice) -> Result<Self> {
        Ok(Self {
            stream: dev.new_stream()?,
            copy: dev.new_stream()?,
            arena: Arc::default(),
        })
    }

    /// The lane's copy stream (see the field).
    pub(crate) fn copy_stream(&self) -> &Arc<CudaStream> {
        &self.copy
    }

    /// Waits until everything queued on the lane (its stream and its copy stream) has run.
    pub(crate) fn synchronize_all(&self) -> Result<()> {
        self.copy
            .synchronize()
            .map_err(driver_error("copy stream synchronisation"))?;
        self.stream
            .synchronize()
            .map_err(driver_error("stream synchronisation"))
    }

    /// A device buffer of `len` elements (at least one) for work queued on this lane's stream: a free
    /// one of the arena, else a new one of [`capacity_for`]`(len)` (zeroed once, when allocated: its
    /// contents are whatever the last call on this stream left; every kernel writes what it reads).
    pub(crate) fn scratch<T: Pooled>(&self, len: usize, operation: &str) -> Result<Scratch<T>> {
        let len = len.max(1);
        let reused = {
            let mut free = self.arena.lock();
            let list = &mut T::lists(&mut free).device;
            best_fit(list.iter().map(|k| k.buffer.len()), len).map(|i| list.swap_remove(i))
        };
        let kept = match reused {
            Some(kept) => kept,
            None => KeptDevice {
                texture: None,
                buffer: alloc_zeros::<T>(&self.stream, capacity_for(len), operation)?,
            },
        };
        Ok(Scratch {
            kept: Some(kept),
            len,
            arena: self.arena.clone(),
        })
    }

    /// A pinned host buffer of at least `len` elements (at least one), taken from the arena until the
    /// returned guard drops. Its contents are stale; the host touches it only through
    /// [`PinnedScratch::host`] and [`PinnedScratch::wait`], which wait for the copies queued on it.
    pub(crate) fn pinned<T: Pooled>(
        &self,
        len: usize,
        operation: &str,
    ) -> Result<PinnedScratch<T>> {
        let len = len.max(1);
        let reused = {
            let mut free = self.arena.lock();
            let list = &mut T::lists(&mut free).host;
            best_fit(list.iter().map(|k| k.buffer.len()), len).map(|i| list.swap_remove(i))
        };
        let kept = match reused {
            Some(kept) => kept,
            None => KeptHost {
                // Read by the host (results) or written once (selections): cached memory.
                buffer: alloc_pinned::<T>(&self.stream, capacity_for(len), false, operation)?,
                copied: self
                    .stream
                    .context()
                    .new_event(None)
                    .map_err(driver_error("event creation"))?,
            },
        };
        Ok(PinnedScratch {
            kept: Some(kept),
            stream: self.stream.clone(),
            arena: self.arena.clone(),
        })
    }
}

/// `result`, after waiting for `lane`'s stream when it is an error: work queued before the error may
/// still read the caller's image ([`super::texture::ImageLife::Work`]), which must not be released
/// before that work has run. (On success the caller's last read-back has waited already.)
pub(crate) fn settled<T>(lane: &Lane, result: Result<T>) -> Result<T> {
    if result.is_err() {
        // The error being returned is the one that matters; a failed wait says the same thing.
        let _ = lane.synchronize_all();
    }
    result
}

/// The index of the smallest capacity of `capacities` that holds `len`, if any.
fn best_fit(capacities: impl Iterator<Item = usize>, len: usize) -> Option<usize> {
    capacities
        .enumerate()
        .filter(|&(_, capacity)| capacity >= len)
        .min_by_key(|&(_, capacity)| capacity)
        .map(|(i, _)| i)
}

/// A device buffer borrowed from a lane's arena for `len` elements; back to the arena on drop. Used
/// only on that lane's stream.
pub(crate) struct Scratch<T: Pooled> {
    kept: Option<KeptDevice<T>>,
    len: usize,
    arena: Arc<Arena>,
}

impl<T: Pooled> std::fmt::Debug for Scratch<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scratch").field("len", &self.len).finish()
    }
}

impl<T: Pooled> Scratch<T> {
    fn kept(&self) -> &KeptDevice<T> {
        self.kept.as_ref().expect("present until dropped")
    }

    fn kept_mut(&mut self) -> &mut KeptDevice<T> {
        self.kept.as_mut().expect("present until dropped")
    }

    /// The whole buffer, at least [`Self::len`] elements (for kernels whose bounds are arguments).
    pub(crate) fn whole(&self) -> &CudaSlice<T> {
        &self.kept().buffer
    }

    /// The whole buffer, mutable (see [`Self::whole`]).
    pub(crate) fn whole_mut(&mut self) -> &mut CudaSlice<T> {
        &mut self.kept_mut().buffer
    }

    /// The first [`Self::len`] elements.
    pub(crate) fn view(&self) -> CudaView<'_, T> {
        self.kept().buffer.slice(..self.len)
    }

    /// The first [`Self::len`] elements, mutable.
    pub(crate) fn view_mut(&mut self) -> CudaViewMut<'_, T> {
        let len = self.len;
        self.kept_mut().buffer.slice_mut(..len)
    }

    /// The texture kept with this buffer if it was made for `key`, else `make()`'s, kept from now on.
    pub(crate) fn texture(
        &mut self,
        key: TextureKey,
        make: impl FnOnce(&CudaSlice<T>) -> Result<TextureObject>,
    ) -> Result<u64> {
        let kept = self.kept_mut();
        match &kept.texture {
            Some((k, texture)) if *k == key => Ok(texture.handle()),
            _ => {
                // The old texture (if any) is destroyed here: kernels queued earlier that read it
                // belong to calls on this stream whose owners dropped this buffer; destroying a texture
                // object while queued work uses it is allowed only after that work, so wait for it.
                if kept.texture.is_some() {
                    kept.buffer
                        .stream()
                        .synchronize()
                        .map_err(super::device::driver_error("replacing a texture object"))?;
                }
                let texture = make(&kept.buffer)?;
                let handle = texture.handle();
                kept.texture = Some((key, texture));
                Ok(handle)
            }
        }
    }
}

impl<T: Pooled> Drop for Scratch<T> {
    fn drop(&mut self) {
        if let Some(kept) = self.kept.take() {
            T::lists(&mut self.arena.lock()).device.push(kept);
        }
    }
}

/// A pinned host buffer borrowed from a lane's arena; back to the arena on drop, with the event of
/// the last copy queued on it, which the next user's host access waits for.
pub(crate) struct PinnedScratch<T: Pooled> {
    kept: Option<KeptHost<T>>,
    stream: Arc<CudaStream>,
    arena: Arc<Arena>,
}

impl<T: Pooled> PinnedScratch<T> {
    fn kept(&mut self) -> &mut KeptHost<T> {
        self.kept.as_mut().expect("present until dropped")
    }

    /// The whole buffer for the host to write or read, once every copy queued on it has run.
    pub(crate) fn host(&mut self) -> Result<&mut [T]> {
        let kept = self.kept();
        kept.copied
            .synchronize()
            .map_err(driver_error("waiting for a copy"))?;
        kept.buffer
            .as_mut_slice()
            .map_err(driver_error("waiting for a copy"))
    }

    /// Waits for the copies queued on the buffer, then gives its first `len` elements.
    pub(crate) fn wait(&mut self, len: usize) -> Result<&[T]> {
        let host = self.host()?;
        let capacity = host.len();
        super::invariant(len <= capacity, "reading results back", || {
            format!("{len} elements of a {capacity}-element buffer")
        })?;
        Ok(&host[..len])
    }

    /// Queues `copy(host, stream)` on the lane's stream, `host` pointing at element `at` of the
    /// buffer with room for `len` more, then records the buffer's event after it. (Raw pointers:
    /// cudarc's copies to and from a `PinnedHostSlice` move the whole buffer, not a range.)
    fn queue_copy(
        &mut self,
        (at, len): (usize, usize),
        operation: &'static str,
        copy: impl FnOnce(*mut T, &Arc<CudaStream>) -> std::result::Result<(), DriverError>,
    ) -> Result<()> {
        let stream = self.stream.clone();
        let kept = self.kept();
        let capacity = kept.buffer.len();
        super::invariant(at + len <= capacity, operation, || {
            format!("{len} elements at {at} of a {capacity}-element pinned buffer")
        })?;
        if len == 0 {
            return Ok(());
        }
        // Raw driver calls: the stream's context must be this thread's current one.
        stream
            .context()
            .bind_to_thread()
            .map_err(driver_error(operation))?;
        let host = kept
            .buffer
            .as_mut_ptr()
            .map_err(driver_error("waiting for a copy"))?;
        let span = super::spans::Span::open(&stream);
        // SAFETY: element `at` is inside the buffer (checked above).
        copy(unsafe { host.add(at) }, &stream).map_err(driver_error(operation))?;
        drop(span);
        kept.copied
            .record(&stream)
            .map_err(driver_error("event record"))
    }

    /// Queues a copy of `src` into elements `at..at + src.len()` of the buffer on the lane's stream
    /// (the one `src` belongs to). The host reads them after [`Self::wait`].
    pub(crate) fn queue_download(&mut self, at: usize, src: &CudaView<'_, T>) -> Result<()> {
        let stream = self.stream.clone();
        let (ptr, _sync) = src.device_ptr(&stream);
        let len = src.len();
        self.queue_copy((at, len), "copying results back", |host, stream| {
            // SAFETY: `len` elements from `host` are in the pinned buffer (checked by queue_copy),
            // which stays allocated and untouched by the host until the event recorded after this
            // copy completes: it is only reachable through this guard and the arena, and both wait
            // for that event first. `ptr` holds `len` elements of T on this stream's device.
            unsafe {
                let range = std::slice::from_raw_parts_mut(host, len);
                cudarc::driver::result::memcpy_dtoh_async(range, ptr, stream.cu_stream())
            }
        })
    }

    /// Queues a copy of elements `at..at + dst.len()` of the buffer (written by the host through
    /// [`Self::host`]) into `dst` on the lane's stream.
    pub(crate) fn queue_upload(&mut self, at: usize, dst: &mut CudaViewMut<'_, T>) -> Result<()> {
        let stream = self.stream.clone();
        let len = dst.len();
        let (ptr, _sync) = dst.device_ptr_mut(&stream);
        self.queue_copy((at, len), "uploading keypoints", |host, stream| {
            // SAFETY: as in `queue_download`: the range is inside the buffer, which the host does
            // not write again before the event recorded after this copy completes; `ptr` holds
            // `len` elements of T on this stream's device.
            unsafe {
                let range = std::slice::from_raw_parts(host.cast_const(), len);
                cudarc::driver::result::memcpy_htod_async(ptr, range, stream.cu_stream())
            }
        })
    }
}

impl<T: Pooled> Drop for PinnedScratch<T> {
    fn drop(&mut self) {
        if let Some(kept) = self.kept.take() {
            T::lists(&mut self.arena.lock()).host.push(kept);
        }
    }
}

/// Idle lanes a device keeps for its blocking calls and batches.
const KEPT_LANES: usize = 32;

/// The idle lanes of one device.
#[derive(Debug, Default)]
pub(crate) struct LanePool {
    idle: Mutex<Vec<Lane>>,
}

impl LanePool {
    /// An idle lane (its arena warm from earlier calls), or a new one.
    pub(crate) fn take(&self, dev: &GpuDevice) -> Result<Lane> {
        let idle = self.idle.lock().unwrap_or_else(|p| p.into_inner()).pop();
        match idle {
            Some(lane) => Ok(lane),
            None => Lane::new(dev),
        }
    }

    /// Gives `lane` back (work it queued may still run: whoever takes it next queues after it).
    pub(crate) fn give(&self, lane: Lane) {
        let mut idle = self.idle.lock().unwrap_or_else(|p| p.into_inner());
        if idle.len() < KEPT_LANES {
            idle.push(lane);
        }
    }

    /// Drops every idle lane and its buffers (test hooks: a cold start).
    #[cfg(feature = "internals")]
    pub(crate) fn clear(&self) {
        self.idle.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }
}

/// A lane of the device's pool, given back when dropped.
pub(crate) struct Leased<'a> {
    lane: Option<Lane>,
    dev: &'a GpuDevice,
}

impl<'a> Leased<'a> {
    /// An idle lane of `dev`'s pool.
    pub(crate) fn take(dev: &'a GpuDevice) -> Result<Self> {
        Ok(Self {
            lane: Some(dev.lanes.take(dev)?),
            dev,
        })
    }
}

impl Deref for Leased<'_> {
    type Target = Lane;
    fn deref(&self) -> &Lane {
        self.lane.as_ref().expect("present until dropped")
    }
}

impl Drop for Leased<'_> {
    fn drop(&mut self) {
        if let Some(lane) = self.lane.take() {
            self.dev.lanes.give(lane);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capacities_grow_geometrically_and_hold_the_request() {
        for len in [
            0usize,
            1,
            2,
            7,
            8,
            9,
            100,
            1000,
            1 << 20,
            (1 << 20) + 1,
            21_026_304,
        ] {
            let c = capacity_for(len);
            assert!(c >= len.max(1), "{len}");
            assert!(c as f64 <= len.max(1) as f64 * 1.25 + 1.0, "{len} -> {c}");
        }
        assert_eq!(capacity_for(1000), 1024);
        assert_eq!(capacity_for(1025), 1280);
        // Sizes close together share a capacity.
        assert_eq!(capacity_for(2_000_000), capacity_for(2_090_000));
    }

    #[test]
    fn best_fit_takes_the_smallest_that_holds() {
        let caps = [64usize, 16, 32, 8];
        assert_eq!(best_fit(caps.into_iter(), 20), Some(2));
        assert_eq!(best_fit(caps.into_iter(), 8), Some(3));
        assert_eq!(best_fit(caps.into_iter(), 65), None);
    }
}
