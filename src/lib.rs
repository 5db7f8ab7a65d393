#![doc = include_str!("../README.md")]
#![deny(missing_docs)]
#![cfg_attr(docsrs, feature(doc_cfg))]

/// Declares a module of the pipeline's internals: crate-private, or public but hidden from the docs
/// with the `internals` feature (the test suites' and benches' hooks; no semver promise).
macro_rules! internal_modules {
    ($($name:ident),* $(,)?) => {$(
        #[cfg(feature = "internals")]
        #[doc(hidden)]
        pub mod $name;
        #[cfg(not(feature = "internals"))]
        mod $name;
    )*};
}

#[macro_use]
mod builder;

internal_modules!(angle, describe, detect, gray_view, matching, pyramid);

mod backend;
mod collection;
mod descriptor;
mod error;
mod extract;
mod features;
mod in_flight;
mod keypoint;
mod matcher;
mod names;
mod parallel;
mod verifier;

#[cfg(feature = "colmap")]
#[cfg_attr(docsrs, doc(cfg(feature = "colmap")))]
pub mod colmap;
#[cfg(feature = "cuda")]
pub mod cuda;
#[cfg(not(feature = "cuda"))]
#[path = "cuda/unavailable.rs"]
pub mod cuda;
#[cfg(feature = "image")]
#[cfg_attr(docsrs, doc(cfg(feature = "image")))]
pub mod decode;
pub mod homography;
pub mod output;
pub mod prefetch;
pub mod synthetic;
pub mod verify;

/// The numeric contract: every rule whose arithmetic decides a keypoint, a bit or a match, exactly as
/// every backend computes it.
#[doc = include_str!("../docs/numerics.md")]
pub mod numerics {}

/// OpenCV compatibility: what [`OpencvLatch`] reproduces of OpenCV's LATCH, and where the default
/// CLATCH descriptor differs from it.
#[doc = include_str!("../docs/opencv_compat.md")]
pub mod opencv_compat {}

pub use backend::{Backend, BackendStart};
pub use collection::{DescriptorCollection, DevicePool};
pub use cuda::SetUpSteps;
pub use describe::opencv::OpencvLatch;
pub use describe::{DescriptorConfig, PatchWeights, SkipReason, Skipped, Smoothing, WINDOW};
pub use descriptor::{Descriptor, DescriptorSet, DescriptorWidth};
pub use detect::{DetectorConfig, LevelBudget, Ranking, Subpixel, fast_score};
pub use error::{Error, ErrorKind, Result};
pub use extract::{Extractor, ExtractorConfig};
pub use features::Features;
pub use gray_view::{AsGrayView, GrayView, MAX_IMAGE_SIDE};
pub use keypoint::KeyPoint;
pub use matcher::Matcher;
pub use matching::{KnnMatches, Match, MatchConfig};
pub use names::{NamedOption, ParseNameError};
pub use pyramid::Pyramid;
pub use verifier::Verifier;

#[cfg(feature = "cuda")]
#[cfg_attr(docsrs, doc(cfg(feature = "cuda")))]
pub use cudarc::driver::DriverError;
