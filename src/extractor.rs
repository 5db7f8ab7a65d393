//! Detection and description behind one backend-independent interface.

use crate::backend::Backend;
use crate::describe::{self, Described, DescriptorConfig, WINDOW};
use crate::descriptor::DescriptorSet;
use crate::detect::{self, DetectorConfig};
use crate::error::{Error, Result};
use crate::image::GrayView;
use crate::keypoint::KeyPoint;
use crate::pyramid::{self, Pyramid};

/// Settings of an [`Extractor`].
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ExtractorConfig {
    /// FAST detector settings.
    pub detector: DetectorConfig,
    /// CLATCH descriptor settings.
    pub descriptor: DescriptorConfig,
    /// Multi-scale detection over an image pyramid ([`crate::pyramid`]); `None` (the default) detects
    /// on the full-resolution image only.
    pub pyramid: Option<Pyramid>,
}

/// Keypoints and their descriptors: row `i` of `descriptors` describes `keypoints[i]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Features {
    /// Detected keypoints, strongest first.
    pub keypoints: Vec<KeyPoint>,
    /// One descriptor per keypoint.
    pub descriptors: DescriptorSet,
}

impl Features {
    /// Pairs `keypoints` with their description, keeping only the keypoints that got a descriptor
    /// (for detected keypoints that is all of them: detection keeps a margin for the window).
    pub fn from_described(keypoints: Vec<KeyPoint>, described: Described) -> Self {
        let keypoints = if described.skipped.is_empty() {
            keypoints
        } else {
            described
                .keypoint_index
                .iter()
                .map(|&i| keypoints[i])
                .collect()
        };
        Self {
            keypoints,
            descriptors: described.descriptors,
        }
    }
}

/// Finds keypoints and computes their CLATCH descriptors.
///
/// ```
/// use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
///
/// let pixels = clatch::synthetic::rectangles(320, 240, 1);
/// let image = GrayView::new(&pixels, 320, 240, 320)?;
/// let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
/// let features = extractor.detect_and_describe(&image)?;
/// assert_eq!(features.keypoints.len(), features.descriptors.len());
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Extractor {
    backend: Backend,
    config: ExtractorConfig,
}

impl Extractor {
    /// Validates the configuration and the backend.
    pub fn new(backend: Backend, config: ExtractorConfig) -> Result<Self> {
        config.detector.validate()?;
        if let Some(p) = &config.pyramid {
            p.validate(config.detector.keypoint_size)?;
        }
        backend.ensure_available()?;
        Ok(Self { backend, config })
    }

    /// The backend this extractor runs on.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The configuration.
    pub fn config(&self) -> &ExtractorConfig {
        &self.config
    }

    fn check_image(image: &GrayView) -> Result<()> {
        if image.width() < WINDOW || image.height() < WINDOW {
            return Err(Error::ImageTooSmall {
                width: image.width(),
                height: image.height(),
                min: WINDOW,
            });
        }
        Ok(())
    }

    /// FAST keypoints with orientation, strongest first (see [`crate::detect`] for the exact rules).
    /// Every keypoint returned has a window that fits, so [`Extractor::describe`] skips none of them.
    ///
    /// With a [`Pyramid`], keypoints of every level in level-0 coordinates (see [`crate::pyramid`]).
    pub fn detect(&self, image: &GrayView) -> Result<Vec<KeyPoint>> {
        Self::check_image(image)?;
        if let Some(p) = &self.config.pyramid {
            return self.detect_pyramid(image, p);
        }
        match self.backend {
            Backend::Cpu => Ok(detect::cpu::detect(image, &self.config.detector)),
            #[cfg(feature = "cuda")]
            Backend::Cuda { device } => {
                crate::cuda::detect(&*crate::cuda::device(device)?, image, &self.config.detector)
            }
        }
    }

    /// Descriptors of caller-supplied keypoints. Keypoints whose window leaves the image are not
    /// described and are listed in [`Described::skipped`]; [`Described::keypoint_index`] maps each
    /// descriptor row to its input keypoint. An empty keypoint list gives an empty result.
    pub fn describe(&self, image: &GrayView, keypoints: &[KeyPoint]) -> Result<Described> {
        Self::check_image(image)?;
        describe::validate_keypoints(keypoints, image.width(), image.height())?;
        match self.backend {
            Backend::Cpu => Ok(describe::cpu::describe(
                image,
                keypoints,
                &self.config.descriptor,
            )),
            #[cfg(feature = "cuda")]
            Backend::Cuda { device } => crate::cuda::describe(
                &*crate::cuda::device(device)?,
                image,
                keypoints,
                &self.config.descriptor,
            ),
        }
    }

    fn detect_pyramid(&self, image: &GrayView, p: &Pyramid) -> Result<Vec<KeyPoint>> {
        match self.backend {
            Backend::Cpu => Ok(pyramid::cpu::detect(image, &self.config.detector, p)),
            #[cfg(feature = "cuda")]
            Backend::Cuda { device } => crate::cuda::pyramid_detect(
                &*crate::cuda::device(device)?,
                image,
                &self.config.detector,
                p,
            ),
        }
    }

    /// Detects keypoints and describes them. On the GPU the image is uploaded once and description
    /// follows detection on the device with no host round trip.
    ///
    /// With a [`Pyramid`], each keypoint is described on its own level (its window `size` pixels of
    /// level 0, sampled from the downscaled level), so [`Extractor::describe`] of the returned
    /// keypoints, which samples level 0, gives the same descriptors only for level-0 keypoints.
    pub fn detect_and_describe(&self, image: &GrayView) -> Result<Features> {
        if let Some(p) = &self.config.pyramid {
            Self::check_image(image)?;
            return match self.backend {
                Backend::Cpu => pyramid::cpu::detect_and_describe(
                    image,
                    &self.config.detector,
                    &self.config.descriptor,
                    p,
                ),
                #[cfg(feature = "cuda")]
                Backend::Cuda { device } => crate::cuda::pyramid_detect_and_describe(
                    &*crate::cuda::device(device)?,
                    image,
                    &self.config.detector,
                    &self.config.descriptor,
                    p,
                ),
            };
        }
        match self.backend {
            Backend::Cpu => {
                let keypoints = self.detect(image)?;
                let described = self.describe(image, &keypoints)?;
                Ok(Features::from_described(keypoints, described))
            }
            #[cfg(feature = "cuda")]
            Backend::Cuda { device } => self
                .detect_and_describe_async(&crate::cuda::GpuStream::new(device)?, image)?
                .wait(),
        }
    }

    /// Queues detection and description of `image` on `stream` and returns at once; the result's
    /// `wait` gives exactly what [`Extractor::detect_and_describe`] gives. With one stream per image,
    /// several images are in flight at once (see [`crate::cuda::GpuStream`]). The backend must be
    /// `Backend::Cuda` on the stream's device. With a [`Pyramid`], the levels and their detection are
    /// queued; the top-N over the levels and the description on each level run in `wait`.
    ///
    /// ```no_run
    /// # fn main() -> clatch::Result<()> {
    /// use clatch::{Backend, Extractor, ExtractorConfig, GrayView, cuda::GpuStream};
    /// let frames: Vec<Vec<u8>> = vec![vec![0; 640 * 480]; 8];
    /// let extractor = Extractor::new(Backend::Cuda { device: 0 }, ExtractorConfig::default())?;
    /// let streams: Vec<GpuStream> = (0..4).map(|_| GpuStream::new(0)).collect::<Result<_, _>>()?;
    /// let pending: Vec<_> = frames
    ///     .iter()
    ///     .zip(streams.iter().cycle())
    ///     .map(|(f, s)| extractor.detect_and_describe_async(s, &GrayView::new(f, 640, 480, 640)?))
    ///     .collect::<Result<_, _>>()?;
    /// for p in pending {
    ///     let features = p.wait()?;
    /// }
    /// # Ok(()) }
    /// ```
    #[cfg(feature = "cuda")]
    pub fn detect_and_describe_async(
        &self,
        stream: &crate::cuda::GpuStream,
        image: &GrayView,
    ) -> Result<crate::cuda::PendingFeatures> {
        Self::check_image(image)?;
        match self.backend {
            Backend::Cuda { device } => {
                stream.check_device(device)?;
                crate::cuda::detect_and_describe_async(
                    stream,
                    image,
                    &self.config.detector,
                    &self.config.descriptor,
                    self.config.pyramid.as_ref(),
                )
            }
            Backend::Cpu => Err(Error::InvalidConfig {
                field: "backend",
                value: "cpu".into(),
                reason: "asynchronous extraction runs on a CUDA backend",
            }),
        }
    }
}
