//! LO-RANSAC as COLMAP 3.8 runs it (`optim/loransac.h`, `ransac.h`, `support_measurement.h`), with
//! three changes that make every decision exact and reproducible on any backend:
//!
//! - **samples** are counter-based ([`Sampler`]): trial `t` draws a pure function of
//!   `(seed, pair, stream, t)`;
//! - **support** is `(inliers, score)` with the score an integer, `Σ floor(r / r_max · 2^32)` over
//!   the inliers (COLMAP sums the `f64` residuals, an order-dependent sum); more inliers win, then
//!   the lower score, then the earlier model (a later one must be strictly better);
//! - **the dynamic trial bound** `ceil(k · log(1 − c) / log(1 − w^m))` is decided without a
//!   logarithm: trial `t` (counted from 0) ends the search when `t ≥ min_trials` and
//!   `(1 − w^m)^t ≤ (1 − c)^k`, with `w = inliers / n`, `w^m` and the power by fixed products
//!   (square and multiply over the bits of `t`) and `(1 − c)^k` computed once on the host.
//!
//! Otherwise as COLMAP: a residual `r ≤ r_max` (squared error against squared threshold) is an
//! inlier; a sample model better than the best so far is locally optimised (the non-minimal solver
//! on its inliers, repeated at most ten times while the inlier count grows); the trial bound is
//! re-derived whenever the best model changes and checked after every model; the result is the best
//! model, successful when it has at least `SAMPLE_SIZE` inliers, with its inlier mask.

use super::sampler::{Sampler, Stream};

/// A model estimator: a minimal solver for the samples, a non-minimal one for local optimisation,
/// and a residual (a squared error, compared with the squared threshold).
pub(crate) trait Estimator {
    /// What is estimated.
    type Model: Copy;
    /// Correspondences of a minimal sample.
    const SAMPLE_SIZE: usize;
    /// Fewest inliers the non-minimal solver takes.
    const LOCAL_MIN_POINTS: usize;
    /// The models through a minimal sample, appended to `models`.
    fn minimal(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Self::Model>);
    /// The models fitted to many correspondences, appended to `models`.
    fn local(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Self::Model>);
    /// The squared error of one correspondence; NaN or infinity never counts as an inlier.
    fn residual(model: &Self::Model, a: [f64; 2], b: [f64; 2]) -> f64;
}

/// Local optimisation rounds per improvement (COLMAP's `kMaxNumLocalTrials`).
const MAX_LOCAL_ROUNDS: usize = 10;

/// The settings of one estimation, as resolved on the host.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RansacSettings {
    /// Squared error threshold: `r ≤ max_residual` is an inlier.
    pub max_residual: f64,
    /// Trials always run (unless `max_trials` is smaller).
    pub min_trials: u32,
    /// Trials at most: the configured maximum, lowered by COLMAP's a-priori bound from the minimum
    /// inlier ratio ([`prior_max_trials`]).
    pub max_trials: u32,
    /// `(1 − confidence)^multiplier`, the stopping threshold of the dynamic bound.
    pub stop_threshold: f64,
    /// Whose samples: `(seed, pair key)`.
    pub seed: u64,
    pub pair: u64,
}

/// COLMAP's `ComputeNumTrials(ratio · 10^5, 10^5)` for a sample of `sample_size`, the a-priori
/// ceiling of the trial count, computed on the host with the pure-Rust `libm` (the same value on
/// every platform; a backend receives the integer).
pub(crate) fn prior_max_trials(
    min_inlier_ratio: f64,
    confidence: f64,
    multiplier: f64,
    sample_size: usize,
) -> u64 {
    const SAMPLES: f64 = 100_000.0;
    let inliers = libm::floor(min_inlier_ratio * SAMPLES);
    let ratio = inliers / SAMPLES;
    let nominator = 1.0 - confidence;
    if nominator <= 0.0 {
        return u64::MAX;
    }
    let denominator = 1.0 - libm::pow(ratio, sample_size as f64);
    if denominator <= 0.0 {
        return 1;
    }
    if denominator == 1.0 {
        return u64::MAX;
    }
    let trials = libm::ceil(libm::log(nominator) / libm::log(denominator) * multiplier);
    if trials >= u64::MAX as f64 {
        u64::MAX
    } else {
        trials as u64
    }
}

/// A model's support: inliers, and the integer score of their residuals (lower is better).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Support {
    pub inliers: usize,
    pub score: u64,
}

impl Support {
    /// Worse than any model (so the first model evaluated becomes the best).
    const NONE: Support = Support {
        inliers: 0,
        score: u64::MAX,
    };

    /// Strictly better: more inliers, or as many with a lower score.
    fn beats(&self, other: &Support) -> bool {
        self.inliers > other.inliers || (self.inliers == other.inliers && self.score < other.score)
    }
}

/// What an estimation found.
#[derive(Clone, Debug)]
pub(crate) struct RansacReport<M> {
    /// The best model (`None` when no sample gave one).
    pub model: Option<M>,
    /// Its support.
    pub support: Support,
    /// Whether it has at least `SAMPLE_SIZE` inliers (COLMAP's `success`).
    pub success: bool,
    /// Which correspondences are its inliers (empty without a model).
    pub inlier_mask: Vec<bool>,
    /// Trials run.
    pub trials: u32,
}

/// Correspondences per block of a support count: after each block the count stops when the model
/// can no longer reach the best model's inliers.
const BLOCK: usize = 64;

/// The correspondences as a structure of arrays, for residual loops the compiler vectorises.
struct Columns {
    xa: Vec<f64>,
    ya: Vec<f64>,
    xb: Vec<f64>,
    yb: Vec<f64>,
}

impl Columns {
    fn new(a: &[[f64; 2]], b: &[[f64; 2]]) -> Self {
        Self {
            xa: a.iter().map(|p| p[0]).collect(),
            ya: a.iter().map(|p| p[1]).collect(),
            xb: b.iter().map(|p| p[0]).collect(),
            yb: b.iter().map(|p| p[1]).collect(),
        }
    }
}

/// Which instructions the residual loops may use, detected once per estimation. The arithmetic is
/// the same either way (separate IEEE operations, never contracted into an FMA): only the vector
/// width changes, and each correspondence's residual is computed on its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Isa {
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            return Isa::Avx2;
        }
        Isa::Portable
    }
}

/// The residuals of the correspondences `start..end` into `residuals[start..end]`; how many of them
/// are inliers.
#[inline(always)]
fn count_block<E: Estimator>(
    model: &E::Model,
    columns: &Columns,
    start: usize,
    end: usize,
    max_residual: f64,
    residuals: &mut [f64],
) -> usize {
    let out = &mut residuals[start..end];
    let (xa, ya) = (&columns.xa[start..end], &columns.ya[start..end]);
    let (xb, yb) = (&columns.xb[start..end], &columns.yb[start..end]);
    let mut count = 0;
    for i in 0..out.len() {
        let r = E::residual(model, [xa[i], ya[i]], [xb[i], yb[i]]);
        out[i] = r;
        count += usize::from(r <= max_residual);
    }
    count
}

/// The inliers of `model`, its residuals into `residuals`; `None` as soon as fewer than `at_least`
/// are possible (the residuals are then partly written).
#[inline(always)]
fn count_inliers<E: Estimator>(
    model: &E::Model,
    columns: &Columns,
    max_residual: f64,
    at_least: usize,
    residuals: &mut [f64],
) -> Option<usize> {
    let n = residuals.len();
    let mut inliers = 0;
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        inliers += count_block::<E>(model, columns, start, end, max_residual, residuals);
        if inliers + (n - end) < at_least {
            return None;
        }
        start = end;
    }
    Some(inliers)
}

/// [`count_inliers`] compiled for AVX2 (without FMA).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn count_inliers_avx2<E: Estimator>(
    model: &E::Model,
    columns: &Columns,
    max_residual: f64,
    at_least: usize,
    residuals: &mut [f64],
) -> Option<usize> {
    count_inliers::<E>(model, columns, max_residual, at_least, residuals)
}

/// The support of `model` when it beats `best`, with its residuals in `residuals`; `None` when it
/// does not. A model that cannot reach `best`'s inlier count is dropped before all its residuals
/// are computed: the result is the same as counting them all, since only a better model changes
/// the search (the best model, its residuals, the trial bound and local optimisation).
fn better_support<E: Estimator>(
    isa: Isa,
    model: &E::Model,
    columns: &Columns,
    max_residual: f64,
    best: &Support,
    residuals: &mut [f64],
) -> Option<Support> {
    let inliers = match isa {
        Isa::Portable => count_inliers::<E>(model, columns, max_residual, best.inliers, residuals),
        // SAFETY: `Isa::Avx2` is only detected where the CPU has AVX2.
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => unsafe {
            count_inliers_avx2::<E>(model, columns, max_residual, best.inliers, residuals)
        },
    }?;
    let mut score = 0;
    for r in residuals.iter() {
        if *r <= max_residual {
            // In [0, 2^32]: r / max ≤ 1 is one correctly rounded division, the product exact.
            score += ((*r / max_residual) * 4_294_967_296.0) as u64;
        }
    }
    let support = Support { inliers, score };
    support.beats(best).then_some(support)
}

/// `x^t` by square and multiply over the bits of `t`, lowest first: the same products everywhere.
fn power(x: f64, mut t: u32) -> f64 {
    let (mut result, mut base) = (1.0, x);
    while t > 0 {
        if t & 1 == 1 {
            result *= base;
        }
        base *= base;
        t >>= 1;
    }
    result
}

/// Whether the dynamic bound is reached after trial `trial` with the best support `inliers` of `n`:
/// `(1 − (inliers/n)^m)^trial ≤ stop_threshold`.
fn dynamic_bound_reached(
    trial: u32,
    inliers: usize,
    n: usize,
    sample_size: usize,
    stop_threshold: f64,
) -> bool {
    let ratio = inliers as f64 / n as f64;
    let mut ratio_power = 1.0;
    for _ in 0..sample_size {
        ratio_power *= ratio;
    }
    power(1.0 - ratio_power, trial) <= stop_threshold
}

/// LO-RANSAC over the correspondences `a[i] ↔ b[i]`.
pub(crate) fn lo_ransac<E: Estimator>(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    settings: &RansacSettings,
    stream: Stream,
) -> RansacReport<E::Model> {
    let n = a.len();
    let mut report = RansacReport {
        model: None,
        support: Support::NONE,
        success: false,
        inlier_mask: Vec::new(),
        trials: 0,
    };
    if n < E::SAMPLE_SIZE || n > u32::MAX as usize {
        report.support = Support {
            inliers: 0,
            score: 0,
        };
        return report;
    }
    let isa = Isa::detect();
    let columns = Columns::new(a, b);
    let sampler = Sampler::new(settings.seed, settings.pair, stream);
    let max_residual = settings.max_residual;
    let mut residuals = vec![0.0; n];
    let mut best_residuals = vec![0.0; n];
    let mut best: Option<E::Model> = None;
    let mut best_support = Support::NONE;
    let mut indices = vec![0u32; E::SAMPLE_SIZE];
    let (mut sample_a, mut sample_b) = (
        vec![[0.0; 2]; E::SAMPLE_SIZE],
        vec![[0.0; 2]; E::SAMPLE_SIZE],
    );
    let (mut inliers_a, mut inliers_b) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut models, mut local_models) = (Vec::new(), Vec::new());
    let mut trials = 0;

    'trials: while trials < settings.max_trials {
        let trial = trials;
        trials += 1;
        sampler.sample(u64::from(trial), n as u32, &mut indices);
        for (k, &i) in indices.iter().enumerate() {
            sample_a[k] = a[i as usize];
            sample_b[k] = b[i as usize];
        }
        models.clear();
        E::minimal(&sample_a, &sample_b, &mut models);
        for model in &models {
            if let Some(support) = better_support::<E>(
                isa,
                model,
                &columns,
                max_residual,
                &best_support,
                &mut residuals,
            ) {
                best_support = support;
                best = Some(*model);
                std::mem::swap(&mut residuals, &mut best_residuals);
                if support.inliers > E::SAMPLE_SIZE && support.inliers >= E::LOCAL_MIN_POINTS {
                    for _ in 0..MAX_LOCAL_ROUNDS {
                        inliers_a.clear();
                        inliers_b.clear();
                        for ((pa, pb), r) in a.iter().zip(b).zip(&best_residuals) {
                            if *r <= max_residual {
                                inliers_a.push(*pa);
                                inliers_b.push(*pb);
                            }
                        }
                        let before = best_support.inliers;
                        local_models.clear();
                        E::local(&inliers_a, &inliers_b, &mut local_models);
                        for local in &local_models {
                            if let Some(local_support) = better_support::<E>(
                                isa,
                                local,
                                &columns,
                                max_residual,
                                &best_support,
                                &mut residuals,
                            ) {
                                best_support = local_support;
                                best = Some(*local);
                                std::mem::swap(&mut residuals, &mut best_residuals);
                            }
                        }
                        if best_support.inliers <= before {
                            break;
                        }
                    }
                }
            }
            if trial >= settings.min_trials
                && dynamic_bound_reached(
                    trial,
                    best_support.inliers,
                    n,
                    E::SAMPLE_SIZE,
                    settings.stop_threshold,
                )
            {
                break 'trials;
            }
        }
    }

    report.trials = trials;
    report.model = best;
    report.support = if best.is_some() {
        best_support
    } else {
        Support {
            inliers: 0,
            score: 0,
        }
    };
    if best.is_some() {
        report.inlier_mask = best_residuals.iter().map(|r| *r <= max_residual).collect();
    }
    report.success = best.is_some() && best_support.inliers >= E::SAMPLE_SIZE;
    report
}

/// The support of `model` over all correspondences, and its residuals into `residuals`.
#[cfg(test)]
fn evaluate<E: Estimator>(
    model: &E::Model,
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    max_residual: f64,
    residuals: &mut [f64],
) -> Support {
    let mut support = Support {
        inliers: 0,
        score: 0,
    };
    for ((pa, pb), r) in a.iter().zip(b).zip(residuals.iter_mut()) {
        *r = E::residual(model, *pa, *pb);
        if *r <= max_residual {
            support.inliers += 1;
            // In [0, 2^32]: r / max ≤ 1 is one correctly rounded division, the product exact.
            support.score += ((*r / max_residual) * 4_294_967_296.0) as u64;
        }
    }
    support
}

/// The straightforward LO-RANSAC, as first written: every model's support over every
/// correspondence. Kept for the tests: [`lo_ransac`] must give the same report, bit for bit.
#[cfg(test)]
pub(crate) fn lo_ransac_reference<E: Estimator>(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    settings: &RansacSettings,
    stream: Stream,
) -> RansacReport<E::Model> {
    let n = a.len();
    let mut report = RansacReport {
        model: None,
        support: Support::NONE,
        success: false,
        inlier_mask: Vec::new(),
        trials: 0,
    };
    if n < E::SAMPLE_SIZE || n > u32::MAX as usize {
        report.support = Support {
            inliers: 0,
            score: 0,
        };
        return report;
    }
    let sampler = Sampler::new(settings.seed, settings.pair, stream);
    let max_residual = settings.max_residual;
    let mut residuals = vec![0.0; n];
    let mut best_residuals = vec![0.0; n];
    let mut best: Option<E::Model> = None;
    let mut best_support = Support::NONE;
    let mut indices = vec![0u32; E::SAMPLE_SIZE];
    let (mut sample_a, mut sample_b) = (
        vec![[0.0; 2]; E::SAMPLE_SIZE],
        vec![[0.0; 2]; E::SAMPLE_SIZE],
    );
    let (mut inliers_a, mut inliers_b) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut models, mut local_models) = (Vec::new(), Vec::new());
    let mut trials = 0;

    'trials: while trials < settings.max_trials {
        let trial = trials;
        trials += 1;
        sampler.sample(u64::from(trial), n as u32, &mut indices);
        for (k, &i) in indices.iter().enumerate() {
            sample_a[k] = a[i as usize];
            sample_b[k] = b[i as usize];
        }
        models.clear();
        E::minimal(&sample_a, &sample_b, &mut models);
        for model in &models {
            let support = evaluate::<E>(model, a, b, max_residual, &mut residuals);
            if support.beats(&best_support) {
                best_support = support;
                best = Some(*model);
                best_residuals.copy_from_slice(&residuals);
                if support.inliers > E::SAMPLE_SIZE && support.inliers >= E::LOCAL_MIN_POINTS {
                    for _ in 0..MAX_LOCAL_ROUNDS {
                        inliers_a.clear();
                        inliers_b.clear();
                        for ((pa, pb), r) in a.iter().zip(b).zip(&best_residuals) {
                            if *r <= max_residual {
                                inliers_a.push(*pa);
                                inliers_b.push(*pb);
                            }
                        }
                        let before = best_support.inliers;
                        local_models.clear();
                        E::local(&inliers_a, &inliers_b, &mut local_models);
                        for local in &local_models {
                            let local_support =
                                evaluate::<E>(local, a, b, max_residual, &mut residuals);
                            if local_support.beats(&best_support) {
                                best_support = local_support;
                                best = Some(*local);
                                best_residuals.copy_from_slice(&residuals);
                            }
                        }
                        if best_support.inliers <= before {
                            break;
                        }
                    }
                }
            }
            if trial >= settings.min_trials
                && dynamic_bound_reached(
                    trial,
                    best_support.inliers,
                    n,
                    E::SAMPLE_SIZE,
                    settings.stop_threshold,
                )
            {
                break 'trials;
            }
        }
    }

    report.trials = trials;
    report.model = best;
    report.support = if best.is_some() {
        best_support
    } else {
        Support {
            inliers: 0,
            score: 0,
        }
    };
    if best.is_some() {
        report.inlier_mask = best_residuals.iter().map(|r| *r <= max_residual).collect();
    }
    report.success = best.is_some() && best_support.inliers >= E::SAMPLE_SIZE;
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_bound_is_colmaps() {
        // ceil(3 log(0.001) / log(1 − 0.25^m)): 5295 for m = 4, 339 520 for m = 7.
        assert_eq!(prior_max_trials(0.25, 0.999, 3.0, 4), 5295);
        assert_eq!(prior_max_trials(0.25, 0.999, 3.0, 7), 339_520);
        assert_eq!(prior_max_trials(1.0, 0.999, 3.0, 4), 1);
        assert_eq!(prior_max_trials(0.0, 0.999, 3.0, 4), u64::MAX);
    }

    #[test]
    fn dynamic_bound_agrees_with_the_logarithm_away_from_the_edge() {
        // 50 % inliers, 7 points, confidence 0.999, multiplier 3: 2646 trials.
        let threshold = libm::pow(0.001, 3.0);
        let bound =
            libm::ceil(3.0 * libm::log(0.001) / libm::log(1.0 - libm::pow(0.5, 7.0))) as u32;
        assert!(!dynamic_bound_reached(bound - 2, 500, 1000, 7, threshold));
        assert!(dynamic_bound_reached(bound + 1, 500, 1000, 7, threshold));
        // All inliers: COLMAP's bound is 1 trial, so trial index 1 stops, index 0 does not.
        assert!(!dynamic_bound_reached(0, 1000, 1000, 7, threshold));
        assert!(dynamic_bound_reached(1, 1000, 1000, 7, threshold));
        assert!(
            !dynamic_bound_reached(100_000, 0, 1000, 7, threshold),
            "no inliers: never"
        );
    }

    #[test]
    fn support_order_is_inliers_then_score_then_first() {
        let a = Support {
            inliers: 10,
            score: 50,
        };
        assert!(
            Support {
                inliers: 11,
                score: 99
            }
            .beats(&a)
        );
        assert!(
            Support {
                inliers: 10,
                score: 49
            }
            .beats(&a)
        );
        assert!(!a.beats(&a));
        assert!(
            Support {
                inliers: 0,
                score: 0
            }
            .beats(&Support::NONE)
        );
    }
}
