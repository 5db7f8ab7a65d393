//! Scratch memory reused across calls: each stream's device buffers and pinned host buffers, kept
//! after a call and handed to the next call on the same stream, so that a steady state of calls of
//! similar size allocates nothing.
//!
//! Why reuse is safe: a device buffer of a stream's [`Arena`] is only ever used by work queued on that
//! stream (kernels and copies); clatch never lets one hop to another stream (the reason event tracking
//! is off, `device.rs`). Returning it to the arena when its owner drops, even while that work is still
//! queued, is therefore safe: whoever takes it next queues its own work on the same stream, after. This
//! is the argument of cudarc's stream-ordered free. Pinned host buffers are read and written by the
//! host too, so each carries its own event ([`KeptHost::copied`]), recorded after every copy queued on
//! it, and the host waits for that event before touching the buffer ([`PinnedScratch::host`]) or
//! freeing it. cudarc's own event in a [`cudarc::driver::PinnedHostSlice`] is no help here: with event
//! tracking off cudarc never records it, so the waits in its `as_slice` and `as_mut_ptr` return at
//! once.
//!
//! Buffers grow geometrically (capacities rounded up to eighths of a power of two); a call takes the
//! smallest free buffer that holds what it asks for. A stream's arena never shrinks by itself, but a
//! lane of the device's pool is trimmed when it goes back to the pool ([`Free::split_off`]: buffers
//! over [`KEPT_BUFFER_BYTES`], and the largest beyond [`KEPT_LANE_BYTES`] in all, and beyond what the
//! device's other idle lanes leave of [`KEPT_DEVICE_BYTES`]), so one huge image, or many streams at
//! once, do not keep gigabytes for the life of the process, while calls of a size seen before
//! allocate nothing. [`release_cached_memory`] and [`crate::cuda::GpuStream::release_cached_memory`] free what the
//! arenas hold on request. Everything is freed with the arena, i.e. with the stream ([`Lane`]).

use std::ops::Deref;
use std::sync::{Arc, Mutex};

use cudarc::driver::{
    CudaEvent, CudaSlice, CudaStream, CudaView, CudaViewMut, DevicePtr, DevicePtrMut, DeviceRepr,
    DriverError, PinnedHostSlice, ValidAsZeroBits,
};

use super::{alloc_pinned, alloc_zeros};
use crate::cuda::device::GpuDevice;
use crate::cuda::error::driver_error;
use crate::cuda::image::TextureObject;
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
    /// Recorded by [`PinnedScratch::queue_copy`] after each copy; waited for before the host touches
    /// the buffer and before it is freed (cudarc's own event in the buffer is never recorded).
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

impl<T> Lists<T> {
    /// Appends the size in bytes of every buffer to `sizes`.
    fn sizes(&self, sizes: &mut Vec<usize>) {
        let bytes = |len: usize| len * std::mem::size_of::<T>();
        sizes.extend(self.device.iter().map(|k| bytes(k.buffer.len())));
        sizes.extend(self.host.iter().map(|k| bytes(k.buffer.len())));
    }

    /// Moves every buffer of more than `keep` bytes to `out`.
    fn split_off(&mut self, keep: usize, out: &mut Self) {
        let fits = |len: usize| len * std::mem::size_of::<T>() <= keep;
        let (device, gone): (Vec<_>, Vec<_>) = std::mem::take(&mut self.device)
            .into_iter()
            .partition(|k| fits(k.buffer.len()));
        self.device = device;
        out.device.extend(gone);
        let (host, gone): (Vec<_>, Vec<_>) = std::mem::take(&mut self.host)
            .into_iter()
            .partition(|k| fits(k.buffer.len()));
        self.host = host;
        out.host.extend(gone);
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

/// The largest free buffer a lane of the device's pool keeps when it goes back to the pool (256 MiB:
/// the quad texture of a 64-megapixel image); larger ones are freed and allocated again by the next
/// image that needs them, whose own work dwarfs the allocation.
pub(crate) const KEPT_BUFFER_BYTES: usize = 256 << 20;

/// The most free bytes a lane of the device's pool keeps when it goes back to the pool, smallest buffers
/// first (512 MiB: by estimate, not measured on a device, the buffers of two 21-megapixel photos in
/// flight with the default pyramid).
pub(crate) const KEPT_LANE_BYTES: usize = 512 << 20;

/// The most free bytes all idle lanes of one device's pool keep together (2 GiB: four lanes at
/// [`KEPT_LANE_BYTES`], the streams a batch keeps busy); a lane given back when the others hold it all
/// keeps nothing.
pub(crate) const KEPT_DEVICE_BYTES: usize = 2 << 30;

impl Free {
    /// Splits off (into the returned lists) the buffers beyond what a lane keeps: every buffer of more
    /// than `largest` bytes, and of the rest those beyond the first `total` bytes, smallest kept first
    /// (a size is kept whole or not at all). `split_off(0, 0)` takes everything.
    fn split_off(&mut self, largest: usize, total: usize) -> Free {
        let keep = kept_size(self.sizes(), largest, total);
        let mut gone = Free::default();
        self.bytes.split_off(keep, &mut gone.bytes);
        self.words.split_off(keep, &mut gone.words);
        self.ints.split_off(keep, &mut gone.ints);
        self.longs.split_off(keep, &mut gone.longs);
        self.keypoints.split_off(keep, &mut gone.keypoints);
        gone
    }

    /// How many buffers (device and pinned) the lists hold.
    fn count(&self) -> usize {
        let both = |device: usize, host: usize| device + host;
        both(self.bytes.device.len(), self.bytes.host.len())
            + both(self.words.device.len(), self.words.host.len())
            + both(self.ints.device.len(), self.ints.host.len())
            + both(self.longs.device.len(), self.longs.host.len())
            + both(self.keypoints.device.len(), self.keypoints.host.len())
    }

    /// The size in bytes of every buffer the lists hold.
    fn sizes(&self) -> Vec<usize> {
        let mut sizes = Vec::new();
        self.bytes.sizes(&mut sizes);
        self.words.sizes(&mut sizes);
        self.ints.sizes(&mut sizes);
        self.longs.sizes(&mut sizes);
        self.keypoints.sizes(&mut sizes);
        sizes
    }

    /// The bytes of every buffer the lists hold.
    fn bytes(&self) -> usize {
        self.sizes().iter().sum()
    }

    /// Whether a texture object is kept with one of the device buffers.
    fn has_texture(&self) -> bool {
        self.bytes.device.iter().any(|k| k.texture.is_some())
    }
}

/// The largest buffer size (in bytes) kept of buffers of `sizes`: at most `largest`, and such that all
/// buffers of at most that size together hold at most `total` bytes (0 keeps nothing).
fn kept_size(mut sizes: Vec<usize>, largest: usize, total: usize) -> usize {
    sizes.sort_unstable();
    let mut keep = 0;
    let mut sum = 0usize;
    let mut i = 0;
    while i < sizes.len() {
        let size = sizes[i];
        let same = sizes[i..].iter().take_while(|&&s| s == size).count();
        sum = sum.saturating_add(size.saturating_mul(same));
        if size > largest || sum > total {
            break;
        }
        keep = size;
        i += same;
    }
    keep
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
    /// Device tables shared by every stream (the descriptor weights) that work queued on this stream
    /// reads, each kept alive until the stream passes the event recorded after that work: whoever else
    /// drops the table meanwhile (the device's cache, on release), the work still reads valid memory.
    tables: Mutex<Vec<(Arc<CudaSlice<i32>>, CudaEvent)>>,
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
        // Tables are released only once the work that reads them has run.
        let tables = self.tables.get_mut().unwrap_or_else(|p| p.into_inner());
        for (_, passed) in tables.drain(..) {
            let _ = passed.synchronize();
        }
    }
}

impl Arena {
    fn lock(&self) -> std::sync::MutexGuard<'_, Free> {
        self.free.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Frees the free buffers beyond `largest` and `total` bytes ([`Free::split_off`]) of this arena,
    /// whose buffers all belong to `lane`. Buffers in use stay in use. Returns whether any was freed.
    fn trim(&self, lane: &Lane, largest: usize, total: usize) -> Result<bool> {
        // Taken out first: work queued from now on cannot use them, so after the wait below nothing
        // queued reads them (or their textures).
        let gone = self.lock().split_off(largest, total);
        if gone.count() == 0 {
            return Ok(false);
        }
        #[cfg(feature = "internals")]
        hooks::FREED.set(hooks::FREED.get() + gone.count());
        if gone.has_texture() {
            // Texture objects are destroyed at once, not in stream order: queued work may read them.
            lane.synchronize_all()?;
        }
        // Device buffers: freed in stream order; pinned ones: each waits for its last copy.
        drop(gone);
        // The device's memory pool gives freed memory back to the system at a synchronisation.
        lane.synchronize_all()?;
        Ok(true)
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

    /// Keeps `table` alive until this lane's stream passes the work queued on it so far (call it after
    /// queuing the kernels that read the table). One event per table, recorded again by each call;
    /// tables whose work has run are let go.
    pub(crate) fn keep_until_passed(&self, table: &Arc<CudaSlice<i32>>) -> Result<()> {
        let mut tables = self.arena.tables.lock().unwrap_or_else(|p| p.into_inner());
        tables.retain(|(kept, passed)| Arc::ptr_eq(kept, table) || !passed.is_complete());
        if let Some((_, passed)) = tables.iter().find(|(kept, _)| Arc::ptr_eq(kept, table)) {
            return passed
                .record(&self.stream)
                .map_err(driver_error("event record"));
        }
        let passed = self
            .stream
            .context()
            .new_event(None)
            .map_err(driver_error("event creation"))?;
        passed
            .record(&self.stream)
            .map_err(driver_error("event record"))?;
        tables.push((table.clone(), passed));
        Ok(())
    }

    /// The lane's copy stream (see the field).
    pub(crate) fn copy_stream(&self) -> &Arc<CudaStream> {
        &self.copy
    }

    /// Frees every free buffer of the lane's arena (buffers held by work in flight stay with it and
    /// come back when that work's owner drops them).
    pub(crate) fn release_cached_memory(&self) -> Result<()> {
        self.arena.trim(self, 0, 0).map(|_| ())
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
            None => {
                let buffer = alloc_zeros::<T>(&self.stream, capacity_for(len), operation)?;
                #[cfg(feature = "internals")]
                hooks::GROWN_BYTES
                    .set(hooks::GROWN_BYTES.get() + buffer.len() * std::mem::size_of::<T>());
                KeptDevice {
                    texture: None,
                    buffer,
                }
            }
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
/// still read the caller's image ([`crate::cuda::image::ImageLife::Work`]), which must not be released
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
                    kept.buffer.stream().synchronize().map_err(
                        crate::cuda::error::driver_error("replacing a texture object"),
                    )?;
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
        crate::cuda::invariant(len <= capacity, "reading results back", || {
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
        crate::cuda::invariant(at + len <= capacity, operation, || {
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
        let span = crate::cuda::spans::Span::open(&stream);
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

    /// Gives `lane` back (work it queued may still run: whoever takes it next queues after it), its
    /// arena trimmed to [`KEPT_BUFFER_BYTES`], [`KEPT_LANE_BYTES`] and what the idle lanes leave of
    /// [`KEPT_DEVICE_BYTES`] (lanes given back at the same moment may each take the same room: the
    /// budget holds to within their number times [`KEPT_LANE_BYTES`]).
    ///
    /// While the thread panics, the lane is waited for first: the call that held it may have queued a
    /// copy that reads the caller's image straight from its memory ([`crate::cuda::image::ImageLife::Work`]),
    /// which the unwinding may release next.
    pub(crate) fn give(&self, lane: Lane) {
        if std::thread::panicking() {
            let _ = lane.synchronize_all();
        }
        let others: usize = {
            let idle = self.idle.lock().unwrap_or_else(|p| p.into_inner());
            idle.iter().map(|l| l.arena.lock().bytes()).sum()
        };
        let room = KEPT_DEVICE_BYTES
            .saturating_sub(others)
            .min(KEPT_LANE_BYTES);
        // A failed wait while trimming leaves the lane as it is: its next user meets the same error.
        // (Trimmed outside the pool's lock: it may wait for the lane's stream.)
        let _ = lane.arena.trim(&lane, KEPT_BUFFER_BYTES, room);
        let mut idle = self.idle.lock().unwrap_or_else(|p| p.into_inner());
        if idle.len() < KEPT_LANES {
            idle.push(lane);
        }
    }

    /// Frees every free buffer of the idle lanes' arenas ([`Lane::release_cached_memory`]); the lanes
    /// (their streams) stay idle in the pool.
    pub(crate) fn release_cached_memory(&self) -> Result<()> {
        let idle = self.idle.lock().unwrap_or_else(|p| p.into_inner()).clone();
        let mut first_error = Ok(());
        for lane in &idle {
            if let Err(e) = lane.release_cached_memory() {
                first_error = first_error.and(Err(e));
            }
        }
        first_error
    }

    /// The free bytes the idle lanes keep together (test hooks).
    #[cfg(feature = "internals")]
    pub(crate) fn idle_bytes(&self) -> usize {
        let idle = self.idle.lock().unwrap_or_else(|p| p.into_inner());
        idle.iter().map(|l| l.arena.lock().bytes()).sum()
    }

    /// Drops every idle lane and its buffers (test hooks: a cold start).
    #[cfg(feature = "internals")]
    pub(crate) fn clear(&self) {
        self.idle.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }
}

/// Frees the device memory (and pinned host memory) clatch keeps between calls on CUDA device `ordinal`
/// in the idle streams of the device's pool, which the blocking calls, batches and image streams of
/// [`crate::Extractor`] and [`crate::Matcher`] use. See [`crate::cuda::release_cached_memory`].
pub(crate) fn release_cached_memory(ordinal: usize) -> Result<()> {
    crate::cuda::device(ordinal)?.lanes.release_cached_memory()
}

/// A lane of the device's pool, given back when dropped (waited for first if the thread panics,
/// [`LanePool::give`]).
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

/// Test hooks of the arenas (the `internals` feature only): not part of the API.
#[cfg(feature = "internals")]
pub mod hooks {
    thread_local! {
        pub(super) static FREED: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
        pub(super) static GROWN_BYTES: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    }

    /// How many kept buffers (device and pinned) this thread's calls have freed so far: trimmed when
    /// a lane went back to the device's pool, or released on request.
    pub fn buffers_freed() -> usize {
        FREED.get()
    }

    /// How many bytes of device buffers this thread's calls have added to arenas so far (arena growth:
    /// what a steady state never adds; freed buffers are not subtracted).
    pub fn arena_bytes_grown() -> usize {
        GROWN_BYTES.get()
    }

    /// The most free bytes the idle lanes of one device keep together.
    pub const KEPT_DEVICE_BYTES: usize = super::KEPT_DEVICE_BYTES;

    /// Takes `lanes` lanes of device `ordinal`'s pool at once, grows each one's arena by a buffer of
    /// `bytes`, gives them back one after another, and returns the free bytes the device's idle lanes
    /// then keep together: at most [`KEPT_DEVICE_BYTES`].
    pub fn fill_idle_lanes(
        ordinal: usize,
        lanes: usize,
        bytes: usize,
    ) -> crate::error::Result<usize> {
        let dev = crate::cuda::device(ordinal)?;
        let taken = (0..lanes)
            .map(|_| super::Leased::take(&dev))
            .collect::<crate::error::Result<Vec<_>>>()?;
        for lane in &taken {
            drop(lane.scratch::<u8>(bytes, "filling an idle lane")?);
        }
        for lane in taken {
            drop(lane);
        }
        Ok(dev.lanes.idle_bytes())
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
    fn a_lane_keeps_its_smallest_buffers_up_to_the_bounds() {
        let mb = 1 << 20;
        // Everything fits: the largest size is kept.
        assert_eq!(
            kept_size(vec![8 * mb, 2 * mb, 2 * mb], 256 * mb, 512 * mb),
            8 * mb
        );
        // One buffer over the largest kept size goes, whatever the total.
        assert_eq!(
            kept_size(vec![4 * mb, 300 * mb, 2 * mb], 256 * mb, 512 * mb),
            4 * mb
        );
        // Over the total: the smallest sizes kept, a size whole or not at all.
        assert_eq!(
            kept_size(
                vec![250 * mb, 250 * mb, 100 * mb, 10 * mb],
                256 * mb,
                512 * mb
            ),
            100 * mb
        );
        assert_eq!(kept_size(vec![10, 20], 0, 0), 0);
        assert_eq!(kept_size(Vec::new(), 256 * mb, 512 * mb), 0);
        assert_eq!(kept_size(vec![1, 1, 1], 1, 2), 0);
    }

    #[test]
    fn best_fit_takes_the_smallest_that_holds() {
        let caps = [64usize, 16, 32, 8];
        assert_eq!(best_fit(caps.into_iter(), 20), Some(2));
        assert_eq!(best_fit(caps.into_iter(), 8), Some(3));
        assert_eq!(best_fit(caps.into_iter(), 65), None);
    }
}
