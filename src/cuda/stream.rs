//! Work queued on streams the caller holds: several images in flight at once.
//!
//! A [`GpuStream`] is a CUDA stream clatch creates and owns (never the default stream). Work queued on
//! one stream runs in order; work on different streams may overlap on the device. The `*_async` calls
//! of [`crate::Extractor`] and [`crate::Matcher`] queue everything and return a pending result at once;
//! its `wait` blocks until the stream has reached it and copies the result back. So a caller can queue
//! the extraction of image `i + 1` on one stream, then match image `i` on another, and the device works
//! on both. The blocking calls are these, waited for at once.

use std::sync::Arc;

use cudarc::driver::CudaEvent;

use super::collection::DeviceCollection;
use super::describe::{launch_describe, weights};
use super::detect::{DeviceKeypoints, detect_on_device, download_counts};
use super::device::GpuDevice;
use super::error::driver_error;
use super::image::{DeviceImage, ImageLife};
use super::matching::{MatchJob, check_rows};
use super::memory::arena::{Lane, Scratch};
use super::pyramid::QueuedPyramid;
use super::spans::Span;
use crate::describe::DescriptorConfig;
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::detect::DetectorConfig;
use crate::error::{Error, Result};
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;
use crate::matching::{Match, MatchConfig};
use crate::pyramid::Pyramid;

/// A CUDA stream owned by clatch, on one device. `Send` and `Sync`: streams can be handed to worker
/// threads; clones share the stream.
///
/// A stream keeps the device buffers (and pinned host buffers) of the calls queued on it after they
/// finish, and hands them to the next calls, growing them when a call needs more: a steady state of
/// images of similar size allocates nothing. They are freed with the stream (its last clone), or on
/// request ([`GpuStream::release_cached_memory`]).
#[derive(Debug, Clone)]
pub struct GpuStream {
    dev: Arc<GpuDevice>,
    hold: Arc<Hold>,
    ordinal: usize,
}

/// A stream's lane, given back to the device's pool when the last clone drops if it came from there.
#[derive(Debug)]
struct Hold {
    lane: Lane,
    /// The device whose pool the lane goes back to, if any.
    pool: Option<Arc<GpuDevice>>,
}

impl Drop for Hold {
    fn drop(&mut self) {
        if let Some(dev) = &self.pool {
            // Work still queued on it is fine: the next user queues after it.
            dev.lanes.give(self.lane.clone());
        }
    }
}

impl GpuStream {
    /// A new stream on CUDA device `ordinal`.
    pub fn new(ordinal: usize) -> Result<Self> {
        let dev = super::device(ordinal)?;
        let lane = Lane::new(&dev)?;
        Ok(Self {
            dev,
            hold: Arc::new(Hold { lane, pool: None }),
            ordinal,
        })
    }

    /// An idle stream of the device's pool (its buffers warm from earlier calls), back in the pool
    /// when the last clone drops: for the library's own blocking calls and batches.
    pub(crate) fn pooled(ordinal: usize) -> Result<Self> {
        let dev = super::device(ordinal)?;
        let lane = dev.lanes.take(&dev)?;
        Ok(Self {
            hold: Arc::new(Hold {
                lane,
                pool: Some(dev.clone()),
            }),
            dev,
            ordinal,
        })
    }

    fn lane(&self) -> &Lane {
        &self.hold.lane
    }

    /// `result`, after waiting for the stream when it is an error (see [`ImageLife::Work`]).
    pub(crate) fn settle<T>(&self, result: Result<T>) -> Result<T> {
        super::memory::arena::settled(self.lane(), result)
    }

    /// The ordinal of the device the stream is on (the `device` of its [`crate::Backend::Cuda`]).
    pub fn ordinal(&self) -> usize {
        self.ordinal
    }

    /// Blocks until everything queued so far has run.
    pub fn synchronize(&self) -> Result<()> {
        self.lane().synchronize_all()
    }

    /// Frees the buffers this stream keeps between calls (device memory and page-locked host
    /// memory); the next call on it allocates what it needs again. Buffers of results still pending
    /// stay theirs (they come back to the stream when the results are read or dropped). Waits for
    /// the stream. Safe at any time, from any thread; see also [`super::release_cached_memory`] for
    /// the streams of the library's own calls.
    pub fn release_cached_memory(&self) -> Result<()> {
        self.lane().release_cached_memory()
    }

    /// An event recorded now: complete once everything queued so far has run.
    fn mark(&self) -> Result<CudaEvent> {
        self.lane()
            .record_event(None)
            .map_err(driver_error("event record"))
    }

    /// Checks that this stream belongs to the backend's device.
    pub(crate) fn check_device(&self, device: usize) -> Result<()> {
        if device != self.ordinal {
            return Err(Error::InvalidInput {
                what: "stream",
                reason: format!(
                    "it belongs to cuda:{}, another device than the backend's (cuda:{device})",
                    self.ordinal
                ),
            });
        }
        Ok(())
    }
}

/// Features being computed on a stream: detection and description of one image, queued with no host
/// round trip between them (the image is uploaded once). With a pyramid, the levels and their detection
/// are queued; the top-N over the levels and the description on each level happen in `wait`.
#[derive(Debug)]
pub struct PendingFeatures {
    stream: GpuStream,
    work: Work,
    done: CudaEvent,
}

/// What a [`PendingFeatures`] holds on the device.
#[derive(Debug)]
enum Work {
    Single {
        // Its buffers go back to the stream's arena when the result is read or dropped; the next user
        // queues on the same stream, after the kernels that read them.
        _image: Box<DeviceImage>,
        keypoints: DeviceKeypoints,
        descriptors: Scratch<u64>,
        width: DescriptorWidth,
    },
    Pyramid {
        queued: QueuedPyramid,
        descriptor: DescriptorConfig,
    },
}

impl PendingFeatures {
    /// True once the device has finished what was queued (with a pyramid: the levels' detection).
    pub fn is_ready(&self) -> bool {
        self.done.is_complete()
    }

    /// Waits for the device and copies the features back (through the stream's pinned buffers).
    pub fn wait(self) -> Result<Features> {
        let lane = self.stream.lane();
        let (keypoints, descriptors, width) = match self.work {
            Work::Pyramid { queued, descriptor } => {
                return queued.features(&self.stream.dev, &descriptor);
            }
            Work::Single {
                keypoints,
                descriptors,
                width,
                ..
            } => (keypoints, descriptors, width),
        };
        let count = download_counts(lane, &[&keypoints])?[0];
        let words = count * width.words();
        // Sized by the capacity, not the count: images of one size reuse them whatever they show.
        let capacity = keypoints.capacity;
        let mut host_keypoints = lane.pinned::<KeyPoint>(capacity, "keypoint read-back buffer")?;
        host_keypoints.queue_download(0, &keypoints.records().slice(..count))?;
        let mut host_words =
            lane.pinned::<u64>(capacity * width.words(), "descriptor read-back buffer")?;
        host_words.queue_download(0, &descriptors.whole().slice(..words))?;
        // The descriptors were queued last: waiting for them waits for both.
        let words = host_words.wait(words)?.to_vec();
        Ok(Features::all(
            host_keypoints.wait(count)?.to_vec(),
            DescriptorSet::from_words(width, words)?,
        ))
    }
}

impl PendingFeatures {
    /// The width of the descriptors being computed.
    pub(crate) fn width(&self) -> DescriptorWidth {
        match &self.work {
            Work::Single { width, .. } => *width,
            Work::Pyramid { descriptor, .. } => descriptor.width,
        }
    }

    /// The stream the features are computed on.
    pub(crate) fn stream(&self) -> &GpuStream {
        &self.stream
    }

    /// Finishes the features on the device and puts the descriptors into `collection` as its next set
    /// (same device and width, checked by the caller) without a host copy; returns the keypoints, which
    /// are read back. See [`DeviceCollection::append_rows`] for how the two streams are ordered.
    pub(crate) fn into_collection(
        self,
        collection: &mut DeviceCollection,
    ) -> Result<Vec<KeyPoint>> {
        let lane = self.stream.lane();
        let (keypoints, descriptors, width) = match self.work {
            Work::Pyramid { queued, descriptor } => {
                return queued.features_into(&self.stream.dev, &descriptor, collection);
            }
            Work::Single {
                keypoints,
                descriptors,
                width,
                ..
            } => (keypoints, descriptors, width),
        };
        let count = download_counts(lane, &[&keypoints])?[0];
        let words = count * width.words();
        let mut host_keypoints =
            lane.pinned::<KeyPoint>(keypoints.capacity, "keypoint read-back buffer")?;
        host_keypoints.queue_download(0, &keypoints.records().slice(..count))?;
        collection.append_rows(lane, count, |target| {
            lane.memcpy_dtod(&descriptors.whole().slice(..words), target)
                .map_err(driver_error("descriptors into a collection"))
        })?;
        Ok(host_keypoints.wait(count)?.to_vec())
    }
}

/// Queues detection and description of `image` (validated) on `stream`; `life` says how long `image`
/// stays valid. With [`ImageLife::Work`] the caller waits for the stream (or the result) before the
/// image is released, errors included ([`GpuStream::settle`]).
pub(crate) fn detect_and_describe_async(
    stream: &GpuStream,
    image: &GrayView,
    detector: &DetectorConfig,
    descriptor: &DescriptorConfig,
    pyramid: Option<&Pyramid>,
    life: ImageLife,
) -> Result<PendingFeatures> {
    let (dev, s) = (&*stream.dev, stream.lane());
    if let Some(p) = pyramid {
        let queued = super::pyramid::queue(dev, s, image, detector, p, life)?;
        return Ok(PendingFeatures {
            done: stream.mark()?,
            stream: stream.clone(),
            work: Work::Pyramid {
                queued,
                descriptor: descriptor.clone(),
            },
        });
    }
    let _span = Span::open(s);
    let mut device_image = DeviceImage::upload(dev, s, image, life)?;
    let keypoints = detect_on_device(dev, s, &device_image, detector)?;
    device_image.build_quads(dev, s, descriptor.smoothing)?;
    let width = descriptor.width;
    let weights = weights(dev, descriptor)?;
    let mut descriptors = s.scratch::<u64>(
        keypoints.capacity.max(1) * width.words(),
        "descriptor allocation",
    )?;
    // Detection keeps a margin for the window, so every detected keypoint fits: no host check needed.
    launch_describe(
        dev,
        s,
        &device_image,
        (&keypoints.records(), &keypoints.total.view()),
        &weights,
        width.bits() as i32,
        &mut descriptors.view_mut(),
    )?;
    Ok(PendingFeatures {
        done: stream.mark()?,
        stream: stream.clone(),
        work: Work::Single {
            _image: Box::new(device_image),
            keypoints,
            descriptors,
            width,
        },
    })
}

/// Matches being computed on a stream.
pub struct PendingMatches {
    job: Option<MatchJob>,
    done: Option<CudaEvent>,
}

impl std::fmt::Debug for PendingMatches {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PendingMatches")
            .field("ready", &self.is_ready())
            .finish()
    }
}

impl PendingMatches {
    /// True once the device has finished matching.
    pub fn is_ready(&self) -> bool {
        self.done.as_ref().is_none_or(CudaEvent::is_complete)
    }

    /// Waits for the device and copies the kept matches back (in query order).
    pub fn wait(self) -> Result<Vec<Match>> {
        self.job.map_or(Ok(Vec::new()), |job| job.fetch())
    }
}

/// Queues `match_descriptors` of validated sets on `stream`.
pub(crate) fn match_async(
    stream: &GpuStream,
    query: &DescriptorSet,
    train: &DescriptorSet,
    config: &MatchConfig,
) -> Result<PendingMatches> {
    check_rows(query, "query descriptors")?;
    check_rows(train, "gallery descriptors")?;
    if query.is_empty() {
        return Ok(PendingMatches {
            job: None,
            done: None,
        });
    }
    let mut job = MatchJob::prepare(
        &stream.dev,
        (**stream.lane()).clone(),
        query,
        train,
        config,
        None,
    )?;
    job.launch(&stream.dev)?;
    Ok(PendingMatches {
        job: Some(job),
        done: Some(stream.mark()?),
    })
}
