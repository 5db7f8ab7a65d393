#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

pub mod angle;
pub mod backend;
#[cfg(feature = "colmap")]
pub mod colmap;
#[cfg(feature = "cuda")]
pub mod cuda;
pub mod describe;
pub mod descriptor;
pub mod detect;
pub mod error;
pub mod extractor;
pub mod image;
pub mod keypoint;
pub mod matcher;
pub mod matching;
pub mod pyramid;
pub mod synthetic;

pub use backend::Backend;
pub use describe::opencv::OpencvLatch;
pub use describe::{Described, DescriptorConfig, PatchWeights, SkipReason, Skipped};
pub use descriptor::{Descriptor, DescriptorSet, DescriptorWidth};
pub use detect::DetectorConfig;
pub use error::{Error, Result};
pub use extractor::{Extractor, ExtractorConfig, Features};
pub use image::GrayView;
pub use keypoint::KeyPoint;
pub use matcher::Matcher;
pub use matching::{KnnMatches, Match, MatchConfig};
pub use pyramid::Pyramid;
