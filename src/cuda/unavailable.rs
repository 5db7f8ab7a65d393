//! The CUDA backend's stand-in when clatch is built without its `cuda` feature.
//!
//! It has the same public types as the real `cuda` module, so code that uses streams compiles in every
//! build; [`GpuStream::new`] (like `Backend::Cuda` itself) then fails with
//! [`crate::Error::BackendUnavailable`]. None of these types has a value, so none of their methods can
//! run, and the crate-internal entry points below take a device that cannot exist.

use std::convert::Infallible;
use std::sync::Arc;

use crate::describe::opencv::{OpencvLatch, Placed};
use crate::describe::{Described, DescriptorConfig};
use crate::descriptor::{DescriptorSet, DescriptorWidth};
use crate::detect::DetectorConfig;
use crate::error::Result;
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;
use crate::matching::{KnnMatches, Match, MatchConfig};
use crate::pyramid::Pyramid;

mod set_up;

pub use crate::matching::GPU_MAX_K as MAX_K;
pub use set_up::SetUpSteps;
pub(crate) use set_up::{NOT_BUILT, unavailable};

/// Frees the memory clatch keeps between calls on CUDA device `ordinal`: always
/// [`crate::Error::BackendUnavailable`] in this build.
pub fn release_cached_memory(ordinal: usize) -> Result<()> {
    Err(unavailable(ordinal, NOT_BUILT))
}

/// A CUDA stream owned by clatch, on one device. Without the `cuda` feature none can be created.
#[derive(Debug, Clone)]
pub struct GpuStream {
    never: Infallible,
}

impl GpuStream {
    /// A new stream on CUDA device `ordinal`: always [`crate::Error::BackendUnavailable`] in this
    /// build.
    pub fn new(ordinal: usize) -> Result<Self> {
        Err(unavailable(ordinal, NOT_BUILT))
    }

    /// A stream of the device's pool: always [`crate::Error::BackendUnavailable`] in this build.
    pub(crate) fn pooled(ordinal: usize) -> Result<Self> {
        Self::new(ordinal)
    }

    /// The ordinal of the device the stream is on (the `device` of its [`crate::Backend::Cuda`]).
    pub fn ordinal(&self) -> usize {
        match self.never {}
    }

    /// Blocks until everything queued so far has run.
    pub fn synchronize(&self) -> Result<()> {
        match self.never {}
    }

    /// Frees the buffers this stream keeps between calls.
    pub fn release_cached_memory(&self) -> Result<()> {
        match self.never {}
    }

    pub(crate) fn settle<T>(&self, _: Result<T>) -> Result<T> {
        match self.never {}
    }

    pub(crate) fn check_device(&self, _device: usize) -> Result<()> {
        match self.never {}
    }
}

/// Features being computed on a stream (none in this build).
#[derive(Debug)]
pub struct PendingFeatures {
    never: Infallible,
}

impl PendingFeatures {
    /// True once the device has finished what was queued.
    pub fn is_ready(&self) -> bool {
        match self.never {}
    }

    /// Waits for the device and copies the features back.
    pub fn wait(self) -> Result<Features> {
        match self.never {}
    }

    pub(crate) fn width(&self) -> DescriptorWidth {
        match self.never {}
    }

    pub(crate) fn stream(&self) -> &GpuStream {
        match self.never {}
    }

    pub(crate) fn into_collection(self, _: &mut DeviceCollection) -> Result<Vec<KeyPoint>> {
        match self.never {}
    }
}

/// Matches being computed on a stream (none in this build).
#[derive(Debug)]
pub struct PendingMatches {
    never: Infallible,
}

impl PendingMatches {
    /// True once the device has finished matching.
    pub fn is_ready(&self) -> bool {
        match self.never {}
    }

    /// Waits for the device and copies the kept matches back (in query order).
    pub fn wait(self) -> Result<Vec<Match>> {
        match self.never {}
    }
}

/// A loaded device: none exists in this build.
#[derive(Debug)]
pub(crate) enum GpuDevice {}

pub(crate) fn device(ordinal: usize) -> Result<Arc<GpuDevice>> {
    Err(unavailable(ordinal, NOT_BUILT))
}

pub(crate) fn verify_pairs(
    dev: &GpuDevice,
    _: &[crate::verify::ViewPair<'_>],
    _: &crate::verify::VerifyConfig,
) -> Result<Vec<crate::verify::TwoViewGeometry>> {
    match *dev {}
}

pub(crate) fn detect(dev: &GpuDevice, _: &GrayView, _: &DetectorConfig) -> Result<Vec<KeyPoint>> {
    match *dev {}
}

pub(crate) fn describe(
    dev: &GpuDevice,
    _: &GrayView,
    _: &[KeyPoint],
    _: &DescriptorConfig,
) -> Result<Described> {
    match *dev {}
}

pub(crate) fn describe_opencv(
    dev: &GpuDevice,
    _: &GrayView,
    _: &OpencvLatch,
    _: Placed,
) -> Result<Described> {
    match *dev {}
}

pub(crate) fn pyramid_detect(
    dev: &GpuDevice,
    _: &GrayView,
    _: &DetectorConfig,
    _: &Pyramid,
) -> Result<Vec<KeyPoint>> {
    match *dev {}
}

pub(crate) fn pyramid_detect_and_describe(
    dev: &GpuDevice,
    _: &GrayView,
    _: &DetectorConfig,
    _: &DescriptorConfig,
    _: &Pyramid,
) -> Result<Features> {
    match *dev {}
}

pub(crate) fn knn(
    dev: &GpuDevice,
    _: &DescriptorSet,
    _: &DescriptorSet,
    _: usize,
) -> Result<KnnMatches> {
    match *dev {}
}

pub(crate) fn match_descriptors(
    dev: &GpuDevice,
    _: &DescriptorSet,
    _: &DescriptorSet,
    _: &MatchConfig,
) -> Result<Vec<Match>> {
    match *dev {}
}

pub(crate) fn detect_and_describe_async(
    stream: &GpuStream,
    _: &GrayView,
    _: &DetectorConfig,
    _: &DescriptorConfig,
    _: Option<&Pyramid>,
    _: ImageLife,
) -> Result<PendingFeatures> {
    match stream.never {}
}

/// How long the caller's image stays valid (see the real module's `ImageLife`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ImageLife {
    Call,
    Work,
}

pub(crate) fn match_async(
    stream: &GpuStream,
    _: &DescriptorSet,
    _: &DescriptorSet,
    _: &MatchConfig,
) -> Result<PendingMatches> {
    match stream.never {}
}

/// Descriptor sets held on a device (none in this build).
#[derive(Debug)]
pub(crate) struct DeviceCollection {
    never: Infallible,
}

impl DeviceCollection {
    pub(crate) fn new(dev: Arc<GpuDevice>, _: DescriptorWidth) -> Result<Self> {
        match *dev {}
    }

    pub(crate) fn add(&mut self, _: &[&DescriptorSet]) -> Result<()> {
        match self.never {}
    }

    pub(crate) fn match_pairs(
        &self,
        _: &[(usize, usize)],
        _: &MatchConfig,
        _: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        match self.never {}
    }

    pub(crate) fn search(
        &self,
        _: &DescriptorSet,
        _: &[usize],
        _: &MatchConfig,
        _: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        match self.never {}
    }
}
