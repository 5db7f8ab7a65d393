//! Detection and description behind one backend-independent interface: the [`Extractor`] validates its
//! inputs once, then hands them to the backend chosen at construction, the one place (with the
//! [`crate::Matcher`]) where a [`crate::Backend`] is matched on. Each stage has a CPU reference
//! (`detect::cpu`, `describe::cpu`, `describe::opencv::cpu`, `pyramid::cpu`) and a CUDA twin in `cuda`;
//! no algorithm module chooses a backend. Without the `cuda` feature `crate::cuda` is a stand-in whose
//! device type has no values, so a `Backend::Cuda` arm can never be reached (construction already
//! refused it) and this file needs no `cfg`.

mod batch;

use crate::backend::Backend;
use crate::cuda::{self, GpuStream, ImageLife, PendingFeatures};
use crate::describe::opencv::{self, OpencvLatch};
use crate::describe::{self, DescriptorConfig, WINDOW};
use crate::detect::{self, DetectorConfig};
use crate::error::{Error, Result};
use crate::features::Features;
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;
use crate::pyramid::{self, Pyramid};

/// Settings of an [`Extractor`].
///
/// The default is the accurate configuration, chosen by measurement (EVALUATION.md): FAST at
/// threshold 20 on an 8-level pyramid of factor 1.2, the 5000 keypoints (more on an image above one
/// megapixel: [`DetectorConfig::budget`]) shared among the levels as ORB shares them, each described
/// over a 40-pixel window on its own level. For today's
/// full-resolution-only speed path, see [`ExtractorConfig::single_scale`].
///
/// ```
/// use clatch::{ExtractorConfig, LevelBudget, Pyramid};
///
/// let accurate = ExtractorConfig::default();
/// assert_eq!(accurate.pyramid, Some(Pyramid::new(8, 1.2)));
/// assert_eq!(accurate.detector.level_budget, LevelBudget::Geometric);
/// let fast = ExtractorConfig::single_scale();
/// assert_eq!(fast.pyramid, None);
/// assert_eq!(fast.detector.keypoint_size, 64.0);
/// ```
///
/// The struct is `#[non_exhaustive]`, so that settings can be added without breaking callers: build
/// it from [`ExtractorConfig::default`] (or [`ExtractorConfig::single_scale`]) with the `with_*`
/// methods, or change the public fields of one you hold.
///
/// ```
/// use clatch::{DetectorConfig, ExtractorConfig, Pyramid, Smoothing};
///
/// let config = ExtractorConfig::default()
///     .with_detector(DetectorConfig::default().with_max_keypoints(2000).with_grid(4))
///     .with_pyramid(Some(Pyramid::new(4, 1.5)));
/// assert_eq!(config.detector.max_keypoints, 2000);
///
/// let mut smoothed = ExtractorConfig::single_scale();
/// smoothed.descriptor.smoothing = Smoothing::Binomial3;
/// ```
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct ExtractorConfig {
    /// FAST detector settings.
    pub detector: DetectorConfig,
    /// CLATCH descriptor settings.
    pub descriptor: DescriptorConfig,
    /// Multi-scale detection over an image pyramid (see [`Pyramid`]), by default
    /// [`Pyramid::DEFAULT`] (8 levels of factor 1.2); `None` detects on the full-resolution image
    /// only.
    pub pyramid: Option<Pyramid>,
}

impl Default for ExtractorConfig {
    fn default() -> Self {
        Self {
            detector: DetectorConfig::default(),
            descriptor: DescriptorConfig::default(),
            pyramid: Some(Pyramid::DEFAULT),
        }
    }
}

impl ExtractorConfig {
    /// The single-scale speed preset: full resolution only, 64-pixel windows, the strongest
    /// keypoints anywhere, 5000 whatever the image's size (the defaults before the pyramid became
    /// the default). About 2.5x less
    /// work per image on the CPU, and far fewer correct matches under scale and viewpoint change.
    pub fn single_scale() -> Self {
        Self {
            detector: DetectorConfig {
                keypoint_size: crate::KeyPoint::DEFAULT_SIZE,
                level_budget: crate::LevelBudget::Global,
                subpixel: crate::Subpixel::None,
                budget_pixels: None,
                ..DetectorConfig::default()
            },
            descriptor: DescriptorConfig::default(),
            pyramid: None,
        }
    }

    with_methods! {
        /// The same settings with these detector settings ([`ExtractorConfig::detector`]).
        with_detector => detector: DetectorConfig;
        /// The same settings with these descriptor settings ([`ExtractorConfig::descriptor`]).
        with_descriptor => descriptor: DescriptorConfig;
        /// The same settings with this pyramid ([`ExtractorConfig::pyramid`]; `None`: the
        /// full-resolution image only).
        with_pyramid => pyramid: Option<Pyramid>;
    }
}

/// Finds keypoints and computes their CLATCH descriptors.
///
/// An `Extractor` is cheap to clone, `Send` and `Sync`: share one across threads.
///
/// ```
/// use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
///
/// let pixels = clatch::synthetic::rectangles(320, 240, 1)?;
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
        Self::validate(&config)?;
        backend.ensure_available()?;
        Ok(Self { backend, config })
    }

    fn validate(config: &ExtractorConfig) -> Result<()> {
        config.detector.validate()?;
        match &config.pyramid {
            Some(p) => p.validate(config.detector.keypoint_size),
            None => Ok(()),
        }
    }

    /// [`Extractor::new`] on a backend still being set up ([`Backend::start`]): checks the
    /// configuration now and returns at once. The first call on the GPU waits for the set-up, and
    /// returns its error if it failed (where `new` would have); the handle's
    /// [`BackendStart::wait`](crate::BackendStart::wait) gives the same error and the set-up's time.
    pub fn starting(start: &crate::BackendStart, config: ExtractorConfig) -> Result<Self> {
        Self::validate(&config)?;
        Ok(Self {
            backend: start.backend(),
            config,
        })
    }

    /// The same configuration on `backend`, whose availability the caller has checked (a
    /// [`crate::DevicePool`]'s workers).
    pub(super) fn on(&self, backend: Backend) -> Self {
        Self {
            backend,
            config: self.config.clone(),
        }
    }

    /// The backend this extractor runs on.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The configuration.
    pub fn config(&self) -> &ExtractorConfig {
        &self.config
    }

    /// The pyramid detection goes through: the configured one, or a single level when the detector
    /// spreads keypoints or shares them out (that selection lives in the pyramid path, on the host, for
    /// every backend).
    fn levels(&self) -> Option<Pyramid> {
        self.config.pyramid.or_else(|| {
            self.config.detector.selects().then_some(Pyramid {
                levels: 1,
                scale_factor: 2.0,
            })
        })
    }

    /// The detector settings for `image`: the budget resolved for its size
    /// ([`DetectorConfig::budget`]) here, on the host, before any backend runs.
    fn detector_for(&self, image: &GrayView) -> DetectorConfig {
        self.config
            .detector
            .for_image(image.width(), image.height())
    }

    pub(super) fn check_image(image: &GrayView) -> Result<()> {
        if image.width() < WINDOW || image.height() < WINDOW {
            return Err(Error::ImageTooSmall {
                width: image.width(),
                height: image.height(),
                min: WINDOW,
            });
        }
        Ok(())
    }

    /// FAST keypoints with orientation, strongest first (the exact rules: [`crate::numerics`],
    /// section 3). Every keypoint returned has a window that fits, so [`Extractor::describe`] skips
    /// none of them.
    ///
    /// With a [`Pyramid`], keypoints of every level in level-0 coordinates.
    pub fn detect(&self, image: &GrayView) -> Result<Vec<KeyPoint>> {
        Self::check_image(image)?;
        if let Some(p) = &self.levels() {
            return self.detect_pyramid(image, p);
        }
        let detector = self.detector_for(image);
        match self.backend {
            Backend::Cpu => Ok(detect::cpu::detect(image, &detector)),
            Backend::Cuda { device } => cuda::detect(&*cuda::device(device)?, image, &detector),
        }
    }

    /// Descriptors of caller-supplied keypoints. Keypoints whose window leaves the image are not
    /// described and are listed in [`Features::skipped`]; [`Features::keypoint_index`] maps each
    /// descriptor row to its input keypoint. An empty keypoint list gives an empty result.
    pub fn describe(&self, image: &GrayView, keypoints: &[KeyPoint]) -> Result<Features> {
        Self::check_image(image)?;
        describe::validate_keypoints(keypoints, image.width(), image.height())?;
        let described = match self.backend {
            Backend::Cpu => describe::cpu::describe(image, keypoints, &self.config.descriptor),
            Backend::Cuda { device } => cuda::describe(
                &*cuda::device(device)?,
                image,
                keypoints,
                &self.config.descriptor,
            )?,
        };
        Ok(Features::of_input(keypoints, described))
    }

    /// Describes `keypoints` as OpenCV's LATCH does (`cv2.xfeatures2d.LATCH_create(...).compute`,
    /// settings in `latch`; this extractor's descriptor settings are not used). The keypoint `size`,
    /// `response` and `octave` are ignored (as by OpenCV). Keypoints OpenCV drops at the border, and
    /// those it would read outside the image for, are listed in [`Features::skipped`].
    /// [`crate::DescriptorSet::to_opencv_bytes`] of the result equals cv2's descriptor rows.
    ///
    /// ```
    /// use clatch::{Backend, Extractor, ExtractorConfig, GrayView, KeyPoint, OpencvLatch};
    ///
    /// let pixels = clatch::synthetic::noise(120, 100, 1)?;
    /// let image = GrayView::new(&pixels, 120, 100, 120)?;
    /// let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::default())?;
    /// // OpenCV's defaults: 32 bytes, rotation invariance, 7x7 patches, sigma 2.
    /// let latch = OpencvLatch::new(32, true, 3, 2.0)?;
    /// let keypoints = [KeyPoint::new(60.0, 50.0).with_angle(30.0), KeyPoint::new(5.0, 5.0)];
    /// let described = extractor.describe_opencv(&latch, &image, &keypoints)?;
    /// assert_eq!(described.keypoint_index, [0]); // the second is too close to the border
    /// let rows: Vec<u8> = described.descriptors.to_opencv_bytes(); // what cv2's compute returns
    /// assert_eq!(rows.len(), 32);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn describe_opencv(
        &self,
        latch: &OpencvLatch,
        image: &GrayView,
        keypoints: &[KeyPoint],
    ) -> Result<Features> {
        let placed = latch.place(image, keypoints)?;
        let described = match self.backend {
            Backend::Cpu => opencv::cpu::describe(image, keypoints, latch, placed),
            Backend::Cuda { device } => {
                cuda::describe_opencv(&*cuda::device(device)?, image, latch, placed)?
            }
        };
        Ok(Features::of_input(keypoints, described))
    }

    fn detect_pyramid(&self, image: &GrayView, p: &Pyramid) -> Result<Vec<KeyPoint>> {
        let detector = self.detector_for(image);
        match self.backend {
            Backend::Cpu => Ok(pyramid::cpu::detect(image, &detector, p)),
            Backend::Cuda { device } => {
                cuda::pyramid_detect(&*cuda::device(device)?, image, &detector, p)
            }
        }
    }

    /// Detects keypoints and describes them. On the GPU the image is uploaded once and description
    /// follows detection on the device with no host round trip.
    ///
    /// With a [`Pyramid`], each keypoint is described on its own level (its window `size` pixels of
    /// level 0, sampled from the downscaled level), so [`Extractor::describe`] of the returned
    /// keypoints, which samples level 0, gives the same descriptors only for level-0 keypoints.
    pub fn detect_and_describe(&self, image: &GrayView) -> Result<Features> {
        if let Some(p) = &self.levels() {
            Self::check_image(image)?;
            let detector = self.detector_for(image);
            return match self.backend {
                Backend::Cpu => {
                    pyramid::cpu::detect_and_describe(image, &detector, &self.config.descriptor, p)
                }
                Backend::Cuda { device } => cuda::pyramid_detect_and_describe(
                    &*cuda::device(device)?,
                    image,
                    &detector,
                    &self.config.descriptor,
                    p,
                ),
            };
        }
        match self.backend {
            Backend::Cpu => {
                let keypoints = self.detect(image)?;
                self.describe(image, &keypoints)
            }
            Backend::Cuda { device } => {
                // The image outlives this call, which waits for the stream on every path.
                let stream = GpuStream::pooled(device)?;
                let result = self
                    .queue_features(&stream, image, ImageLife::Work)
                    .and_then(PendingFeatures::wait);
                stream.settle(result)
            }
        }
    }

    /// Queues detection and description of `image` on `stream` and returns at once; the result's
    /// `wait` gives exactly what [`Extractor::detect_and_describe`] gives. With one stream per image,
    /// several images are in flight at once (see [`GpuStream`]). The backend must be
    /// `Backend::Cuda` on the stream's device ([`Error::InvalidInput`] otherwise). With a [`Pyramid`], the levels and their detection are
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
    pub fn detect_and_describe_async(
        &self,
        stream: &GpuStream,
        image: &GrayView,
    ) -> Result<PendingFeatures> {
        self.queue_features(stream, image, ImageLife::Call)
    }

    /// [`Extractor::detect_and_describe_async`] of an image valid for as long as `life` says.
    pub(super) fn queue_features(
        &self,
        stream: &GpuStream,
        image: &GrayView,
        life: ImageLife,
    ) -> Result<PendingFeatures> {
        Self::check_image(image)?;
        match self.backend {
            Backend::Cuda { device } => {
                stream.check_device(device)?;
                cuda::detect_and_describe_async(
                    stream,
                    image,
                    &self.detector_for(image),
                    &self.config.descriptor,
                    self.levels().as_ref(),
                    life,
                )
            }
            Backend::Cpu => Err(Error::InvalidInput {
                what: "stream",
                reason: "asynchronous extraction runs on a CUDA backend; this extractor's is cpu"
                    .into(),
            }),
        }
    }
}
