//! The public entry points, and the one place where a [`crate::Backend`] is matched on.
//!
//! Each algorithm has a CPU reference (`detect::cpu`, `describe::cpu`, `describe::opencv::cpu`,
//! `pyramid::cpu`, `matching::cpu`) and a CUDA twin in `cuda`; the [`Extractor`] and [`Matcher`] here
//! validate their inputs once, then hand them to the backend chosen at construction; a
//! [`DevicePool`] spreads a collection over several backends. No algorithm
//! module chooses a backend. Without the `cuda` feature `crate::cuda` is a stand-in whose device type
//! has no values, so a `Backend::Cuda` arm there can never be reached (construction already refused
//! it) and this file needs no `cfg`.

mod batch;
mod collection;
mod extractor;
mod in_flight;
mod matcher;
mod pairs;
mod pool;

pub use collection::DescriptorCollection;
pub use extractor::{Extractor, ExtractorConfig};
pub use matcher::Matcher;
pub use pool::DevicePool;
