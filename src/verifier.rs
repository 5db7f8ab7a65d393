//! Geometric verification behind one backend-independent interface: the [`Verifier`] checks its
//! inputs once (the same checks and errors on every backend), then runs the CPU reference
//! (`verify::verify_pairs`) or its CUDA twin (`cuda::verify`), which returns the same geometries bit
//! for bit.

use crate::backend::Backend;
use crate::cuda;
use crate::error::Result;
use crate::verify::{self, TwoViewGeometry, VerifyConfig, ViewPair};

/// Verifies pairs of images (COLMAP 3.8's two-view geometry, [`crate::verify`]) on a chosen backend.
///
/// A `Verifier` is cheap to clone, `Send` and `Sync`. Every backend returns the same
/// [`TwoViewGeometry`] for a pair, matrices and inlier indices bit for bit ([`crate::numerics`],
/// section "Verification"); the CUDA backend verifies a whole batch of pairs per launch.
///
/// ```
/// use clatch::verify::{GeometryConfig, VerifyConfig, ViewPair};
/// use clatch::{Backend, KeyPoint, Match, Verifier};
///
/// // A plane seen twice, shifted sideways by 20 pixels: every match is an inlier of H.
/// let a: Vec<KeyPoint> = (0..30).map(|i| KeyPoint::new(100.0 + 37.0 * (i % 6) as f32, 80.0 + 41.0 * (i / 6) as f32)).collect();
/// let b: Vec<KeyPoint> = a.iter().map(|k| KeyPoint::new(k.x - 20.0, k.y)).collect();
/// let matches: Vec<Match> = (0..30).map(|i| Match { query: i, train: i, distance: 0 }).collect();
///
/// let verifier = Verifier::new(Backend::auto(), VerifyConfig::default())?;
/// let geometries = verifier.verify_pairs(&[ViewPair::new(&a, &b, &matches).with_key(7)])?;
/// assert_eq!(geometries[0].config, GeometryConfig::PlanarOrPanoramic);
/// assert_eq!(geometries[0].inliers.len(), 30);
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Verifier {
    backend: Backend,
    config: VerifyConfig,
}

impl Verifier {
    /// Checks the configuration (`Error::InvalidConfig`) and the backend
    /// (`Error::BackendUnavailable`).
    pub fn new(backend: Backend, config: VerifyConfig) -> Result<Self> {
        config.check()?;
        backend.ensure_available()?;
        Ok(Self { backend, config })
    }

    /// The backend this verifier runs on.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The configuration it verifies with.
    pub fn config(&self) -> &VerifyConfig {
        &self.config
    }

    /// The geometry of every pair, in input order: exactly [`verify::verify_pairs`]'s result. Every
    /// pair is checked before any work, with the same errors on every backend
    /// (`Error::InvalidInput` naming the first bad pair: a match naming a keypoint that is not
    /// there, a matched keypoint at a non-finite position, an unusable camera).
    ///
    /// ```
    /// use clatch::verify::{VerifyConfig, ViewPair};
    /// use clatch::{Backend, ErrorKind, KeyPoint, Match, Verifier};
    ///
    /// let a = [KeyPoint::new(1.0, 2.0)];
    /// let bad = [Match { query: 0, train: 5, distance: 0 }];
    /// let verifier = Verifier::new(Backend::Cpu, VerifyConfig::default())?;
    /// let error = verifier.verify_pairs(&[ViewPair::new(&a, &a, &bad)]).unwrap_err();
    /// assert_eq!(error.kind(), ErrorKind::InvalidInput);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn verify_pairs(&self, pairs: &[ViewPair<'_>]) -> Result<Vec<TwoViewGeometry>> {
        match self.backend {
            Backend::Cpu => verify::verify_pairs(pairs, &self.config),
            Backend::Cuda { device } => {
                verify::check_pairs(pairs, &self.config)?;
                cuda::verify_pairs(&*cuda::device(device)?, pairs, &self.config)
            }
        }
    }
}
