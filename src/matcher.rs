//! Hamming matching behind one backend-independent interface: the [`Matcher`] checks its inputs once,
//! then runs the CPU reference (`matching::cpu`) or its CUDA twin. Many pairs in one call live with the
//! collections (`crate::collection`), which this module does not import.

use crate::backend::Backend;
use crate::cuda::{self, GpuStream, PendingMatches};
use crate::descriptor::DescriptorSet;
use crate::error::{Error, Result};
use crate::matching::{self, KnnMatches, Match, MatchConfig};

/// Brute-force Hamming matcher (the exact rules, ties included: [`MatchConfig`] and
/// [`crate::numerics`], section 5).
///
/// A `Matcher` is cheap to clone, `Send` and `Sync`: share one across threads.
///
/// ```
/// use clatch::{Backend, DescriptorSet, DescriptorWidth, MatchConfig, Matcher};
///
/// let width = DescriptorWidth::from_bits(64)?;
/// let gallery = DescriptorSet::from_words(width, vec![0b1011, 0xFFFF, 0])?;
/// let queries = DescriptorSet::from_words(width, vec![0b0011])?;
/// let matcher = Matcher::new(Backend::Cpu, MatchConfig::default())?;
/// let knn = matcher.knn(&queries, &gallery, 2)?;
/// let nearest = knn.neighbours(0).expect("one query");
/// assert_eq!(nearest[0].train, 0); // 1 bit away
/// assert_eq!(nearest[1].train, 2); // 2 bits away
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Matcher {
    backend: Backend,
    config: MatchConfig,
}

impl Matcher {
    /// Validates the configuration and the backend.
    pub fn new(backend: Backend, config: MatchConfig) -> Result<Self> {
        config.check()?;
        backend.ensure_available()?;
        Ok(Self { backend, config })
    }

    /// The same configuration on `backend`, whose availability the caller has checked (a
    /// [`crate::DevicePool`]'s workers).
    pub(super) fn on(&self, backend: Backend) -> Self {
        Self {
            backend,
            config: self.config.clone(),
        }
    }

    /// The backend this matcher runs on.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The configuration used by [`Matcher::match_descriptors`].
    pub fn config(&self) -> &MatchConfig {
        &self.config
    }

    /// The `k` nearest gallery descriptors of every query, nearest first, ties to the lowest index.
    /// An empty query set gives an empty result. The CUDA backend returns at most 8 neighbours per
    /// query ([`crate::cuda::MAX_K`]); a larger `k` is [`Error::KTooLargeForBackend`].
    pub fn knn(
        &self,
        query: &DescriptorSet,
        train: &DescriptorSet,
        k: usize,
    ) -> Result<KnnMatches> {
        matching::check_sets(query, train, k)?;
        match self.backend {
            Backend::Cpu => Ok(matching::cpu::knn(query, train, k)),
            Backend::Cuda { device } => cuda::knn(&*cuda::device(device)?, query, train, k),
        }
    }

    /// The best match of every query that passes the configured ratio test, cross-check and distance
    /// limit, in query order. The ratio test needs at least two gallery descriptors.
    pub fn match_descriptors(
        &self,
        query: &DescriptorSet,
        train: &DescriptorSet,
    ) -> Result<Vec<Match>> {
        matching::check_sets(query, train, self.config.neighbours_needed())?;
        match self.backend {
            Backend::Cpu => Ok(matching::cpu::match_descriptors(query, train, &self.config)),
            Backend::Cuda { device } => {
                cuda::match_descriptors(&*cuda::device(device)?, query, train, &self.config)
            }
        }
    }

    /// Queues [`Matcher::match_descriptors`] on `stream` and returns at once; the result's `wait`
    /// gives exactly what the blocking call gives. The backend must be `Backend::Cuda` on the
    /// stream's device ([`Error::InvalidInput`] otherwise).
    pub fn match_descriptors_async(
        &self,
        stream: &GpuStream,
        query: &DescriptorSet,
        train: &DescriptorSet,
    ) -> Result<PendingMatches> {
        matching::check_sets(query, train, self.config.neighbours_needed())?;
        match self.backend {
            Backend::Cuda { device } => {
                stream.check_device(device)?;
                cuda::match_async(stream, query, train, &self.config)
            }
            Backend::Cpu => Err(Error::InvalidInput {
                what: "stream",
                reason: "asynchronous matching runs on a CUDA backend; this matcher's is cpu"
                    .into(),
            }),
        }
    }
}
