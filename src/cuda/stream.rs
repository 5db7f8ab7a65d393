//! Work queued on streams the caller holds: several images in flight at once.
//!
//! A [`GpuStream`] is a CUDA stream clatch creates and owns (never the default stream). Work queued on
//! one stream runs in order; work on different streams may overlap on the device. The `*_async` calls
//! of [`crate::Extractor`] and [`crate::Matcher`] queue everything and return a pending result at once;
//! its `wait` blocks until the stream has reached it and copies the result back. So a caller can queue
//! the extraction of image `i + 1` on one stream, then match image `i` on another, and the device works
//! on both. The blocking calls are these, waited for at once.

use std::sync::Arc;

use cudarc::driver::{CudaEvent, CudaSlice, CudaStream};

use super::describe::{launch_describe, upload_weights};
use super::detect::{DeviceKeypoints, detect_on_device};
use super::device::{GpuDevice, driver_error};
use super::matching::{MatchJob, check_rows};
use super::memory::alloc_zeros;
use super::pyramid::QueuedPyramid;
use super::texture::DeviceImage;
use crate::describe::DescriptorConfig;
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::detect::DetectorConfig;
use crate::error::{Error, Result};
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::matching::{Match, MatchConfig};
use crate::pyramid::Pyramid;

/// A CUDA stream owned by clatch, on one device. `Send` and `Sync`: streams can be handed to worker
/// threads; clones share the stream.
#[derive(Debug, Clone)]
pub struct GpuStream {
    dev: Arc<GpuDevice>,
    stream: Arc<CudaStream>,
    ordinal: usize,
}

impl GpuStream {
    /// A new stream on CUDA device `ordinal`.
    pub fn new(ordinal: usize) -> Result<Self> {
        let dev = super::device(ordinal)?;
        let stream = dev.new_stream()?;
        Ok(Self {
            dev,
            stream,
            ordinal,
        })
    }

    /// The device ordinal.
    pub fn ordinal(&self) -> usize {
        self.ordinal
    }

    /// The device.
    pub fn device(&self) -> &GpuDevice {
        &self.dev
    }

    /// Blocks until everything queued so far has run.
    pub fn synchronize(&self) -> Result<()> {
        self.stream
            .synchronize()
            .map_err(driver_error("stream synchronisation"))
    }

    /// An event recorded now: complete once everything queued so far has run.
    fn mark(&self) -> Result<CudaEvent> {
        self.stream
            .record_event(None)
            .map_err(driver_error("event record"))
    }

    /// Checks that this stream belongs to the backend's device.
    pub(crate) fn check_device(&self, device: usize) -> Result<()> {
        if device != self.ordinal {
            return Err(Error::InvalidConfig {
                field: "stream",
                value: format!("cuda:{}", self.ordinal),
                reason: "the stream belongs to another device than the backend",
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
        // Kept alive until the kernels that read it have run (wait synchronises first).
        _image: DeviceImage,
        keypoints: DeviceKeypoints,
        descriptors: CudaSlice<u64>,
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

    /// Waits for the device and copies the features back.
    pub fn wait(self) -> Result<Features> {
        let stream = &self.stream.stream;
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
        let keypoints = keypoints.download(stream)?;
        let words = if keypoints.is_empty() {
            Vec::new()
        } else {
            stream
                .clone_dtoh(&descriptors.slice(..keypoints.len() * width.words()))
                .map_err(driver_error("copying descriptors back"))?
        };
        Ok(Features::all(
            keypoints,
            DescriptorSet::from_words(width, words)?,
        ))
    }
}

/// Queues detection and description of `image` (validated) on `stream`.
pub(crate) fn detect_and_describe_async(
    stream: &GpuStream,
    image: &GrayView,
    detector: &DetectorConfig,
    descriptor: &DescriptorConfig,
    pyramid: Option<&Pyramid>,
) -> Result<PendingFeatures> {
    let (dev, s) = (&*stream.dev, &stream.stream);
    if let Some(p) = pyramid {
        let queued = super::pyramid::queue(dev, s, image, detector, p)?;
        return Ok(PendingFeatures {
            done: stream.mark()?,
            stream: stream.clone(),
            work: Work::Pyramid {
                queued,
                descriptor: descriptor.clone(),
            },
        });
    }
    let mut device_image = DeviceImage::upload(dev, s, image)?;
    let keypoints = detect_on_device(dev, s, &device_image, detector)?;
    device_image.build_quads(dev, s, descriptor.smoothing)?;
    let width = descriptor.width;
    let weights = upload_weights(s, descriptor)?;
    let mut descriptors = alloc_zeros(
        s,
        keypoints.capacity * width.words(),
        "descriptor allocation",
    )?;
    // Detection keeps a margin for the window, so every detected keypoint fits: no host check needed.
    launch_describe(
        dev,
        s,
        &device_image,
        (&keypoints.keypoints, &keypoints.total),
        &weights,
        width.bits() as i32,
        &mut descriptors,
    )?;
    Ok(PendingFeatures {
        done: stream.mark()?,
        stream: stream.clone(),
        work: Work::Single {
            _image: device_image,
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
        stream.stream.clone(),
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
