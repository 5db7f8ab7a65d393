//! The options `clatch` and its evaluation harness (`clatch-eval`) share: the backend, the detector
//! and descriptor, the sub-pixel positions, the matcher and the ground-truth check, each with its
//! mapping onto the library's configuration, so the names and defaults are written once.

use clap::Args;
use clatch::{Backend, DescriptorWidth, ExtractorConfig};
use clatch::{LevelBudget, MatchConfig, Pyramid, Ranking, Smoothing, Subpixel};

use crate::names::{self, BackendFlag};

/// Backend selection.
#[derive(Debug, Args)]
pub struct BackendArgs {
    /// Compute backend.
    #[arg(long, default_value = "auto", value_parser = names::backend())]
    pub backend: BackendFlag,
    /// CUDA device ordinal (with --backend cuda).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub device: usize,
}

/// Detector and descriptor settings.
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// FAST threshold (1..=254): nine contiguous circle pixels must differ from the centre by more.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u8).range(1..=254))]
    pub threshold: u8,
    /// Keep at most this many keypoints per image, strongest first (default 5000, the library's, and
    /// 8192 for `colmap`, COLMAP's own budget of SIFT features per image).
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    pub max_keypoints: Option<usize>,
    /// Budgets that follow the image: --max-keypoints is the budget of an image of up to PIXELS
    /// pixels, a larger one keeps proportionally more (`off`: --max-keypoints for every size).
    /// Default: the library's.
    #[arg(long, value_name = "PIXELS|off", value_parser = parse_budget_pixels)]
    pub budget_pixels: Option<BudgetPixels>,
    /// Side in pixels of the window each detected keypoint is described over (the 64x64 samples are
    /// spread over it): 1 to 1024. Default 40, and 64 with --single-scale.
    #[arg(long, value_name = "PIXELS", value_parser = parse_keypoint_size)]
    pub keypoint_size: Option<f32>,
    /// Descriptor width in bits: a multiple of 8 from 8 to 512.
    #[arg(long, default_value_t = 512, value_parser = parse_bits)]
    pub bits: usize,
    /// Detect on a scale pyramid of LEVELS levels (full resolution included), each FACTOR (in
    /// [1.05, 2], default 2) smaller than the one before; each keypoint is described on its own level.
    /// Default 8:1.2 (the library's default); see --single-scale.
    #[arg(long, value_name = "LEVELS[:FACTOR]", value_parser = parse_pyramid)]
    pub pyramid: Option<Pyramid>,
    /// The single-scale speed preset: full resolution only, 64-pixel windows, the strongest keypoints
    /// anywhere (the defaults of clatch before 0.2). Fewer correct matches under scale and viewpoint
    /// change.
    #[arg(long, conflicts_with_all = ["pyramid", "level_budget"])]
    pub single_scale: bool,
    /// Spread keypoints over a GRID x GRID division of each image (1: the strongest anywhere; default
    /// 1, and 8 for `colmap`, so that textured corners of a photo cannot take every keypoint).
    #[arg(long, value_name = "GRID", value_parser = clap::value_parser!(u32).range(1..=64))]
    pub grid: Option<u32>,
    /// How --max-keypoints is shared among pyramid levels: `global` (the strongest of all levels),
    /// `geometric` (ORB's shares, each level's in proportion to its scale; the default) or `area`
    /// (each level's in proportion to its pixels).
    #[arg(long, value_parser = names::named::<LevelBudget>())]
    pub level_budget: Option<LevelBudget>,
    /// What orders corners when the strongest are kept: `fast` (the FAST score) or `harris` (ORB's
    /// Harris response over the strongest 2 x --max-keypoints).
    #[arg(long, value_parser = names::named::<Ranking>(), default_value_t = Ranking::Fast)]
    pub ranking: Ranking,
    /// Smooth the image the descriptor samples (each pyramid level's, before its keypoints are
    /// described; detection still sees the unsmoothed image) with an integer binomial kernel.
    /// Default: the library's (`none`).
    #[arg(long, value_parser = names::named::<Smoothing>())]
    pub smoothing: Option<Smoothing>,
}

/// `--subpixel` (every command but `colmap`, which adds its `corner` method).
#[derive(Debug, Args)]
pub struct SubpixelArgs {
    /// Sub-pixel keypoint positions: `none` (whole pixels of each keypoint's pyramid level) or `score`
    /// (per axis, the peak of the parabola through the FAST scores of the keypoint and its 4
    /// neighbours, on every level; descriptors do not change). Default `score`, and `none` with
    /// --single-scale.
    #[arg(long, value_parser = names::named::<Subpixel>())]
    pub subpixel: Option<Subpixel>,
}

impl SubpixelArgs {
    /// The library's setting, when given.
    pub fn library(&self) -> Option<Subpixel> {
        self.subpixel
    }
}

/// Which matches are kept.
#[derive(Debug, Args)]
pub struct MatchingArgs {
    /// Lowe's ratio test: keep a match only if best < RATIO x second best (0 < RATIO <= 1).
    #[arg(long, default_value_t = 0.8, value_parser = parse_ratio)]
    pub ratio: f32,
    /// Turn the ratio test off.
    #[arg(long, conflicts_with = "ratio")]
    pub no_ratio: bool,
    /// Keep matches that are not mutual nearest neighbours.
    #[arg(long)]
    pub no_cross_check: bool,
    /// Drop matches farther than this many bits.
    #[arg(long, value_name = "BITS")]
    pub max_distance: Option<u32>,
}

/// How matches are checked against a ground-truth homography.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// A match is an inlier if its reprojection error is at most this many pixels.
    #[arg(long, default_value_t = 3.0, value_name = "PIXELS", value_parser = parse_tolerance)]
    pub inlier_px: f64,
}

/// `--budget-pixels`: a pixel count, or `off` (`None`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BudgetPixels(pub Option<usize>);

fn parse_budget_pixels(s: &str) -> Result<BudgetPixels, String> {
    if s == "off" {
        return Ok(BudgetPixels(None));
    }
    parse_positive(s).map(|p| BudgetPixels(Some(p)))
}

fn parse_positive(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
    }
}

fn parse_bits(s: &str) -> Result<usize, String> {
    let bits = s.parse::<usize>().map_err(|e| e.to_string())?;
    DescriptorWidth::from_bits(bits)
        .map(DescriptorWidth::bits)
        .map_err(|_| "must be a multiple of 8 between 8 and 512".into())
}

/// Smallest pyramid factor: closer levels are near-identical copies whose corners duplicate each other's
/// (at 1.05 every level of an image the detector accepts is at least 4 pixels smaller than the last).
pub const MIN_PYRAMID_FACTOR: f32 = 1.05;

/// `LEVELS` or `LEVELS:FACTOR`; the ranges are checked with the keypoint size by the library, and the
/// factor against [`MIN_PYRAMID_FACTOR`].
fn parse_pyramid(s: &str) -> Result<Pyramid, String> {
    let (levels, factor) = s.split_once(':').unwrap_or((s, "2"));
    let levels = levels
        .parse::<usize>()
        .map_err(|e| format!("LEVELS: {e}"))?;
    let scale_factor = factor.parse::<f32>().map_err(|e| format!("FACTOR: {e}"))?;
    if levels > 1 && scale_factor.is_finite() && scale_factor < MIN_PYRAMID_FACTOR {
        return Err(format!(
            "FACTOR {scale_factor} is below {MIN_PYRAMID_FACTOR}: levels that close are near-identical \
             copies of each other"
        ));
    }
    let pyramid = Pyramid::new(levels, scale_factor);
    // The ranges only: whether the top level's keypoints fit depends on --keypoint-size too
    // ([`DetectArgs::check_sizes`]).
    pyramid.validate(1.0).map_err(|e| match e {
        clatch::Error::InvalidConfig {
            field: "pyramid.levels",
            reason,
            ..
        } => format!("LEVELS {levels} {reason}"),
        clatch::Error::InvalidConfig { reason, .. } => format!("FACTOR {scale_factor} {reason}"),
        other => other.to_string(),
    })?;
    Ok(pyramid)
}

fn parse_keypoint_size(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && (1.0..=1024.0).contains(&v) {
        Ok(v)
    } else {
        Err("must be a number of pixels from 1 to 1024".into())
    }
}

fn parse_ratio(s: &str) -> Result<f32, String> {
    let ratio = s.parse::<f32>().map_err(|e| e.to_string())?;
    if ratio.is_finite() && ratio > 0.0 && ratio <= 1.0 {
        Ok(ratio)
    } else {
        Err("must be a number in (0, 1]".into())
    }
}

fn parse_tolerance(s: &str) -> Result<f64, String> {
    let px = s.parse::<f64>().map_err(|e| e.to_string())?;
    if px.is_finite() && px >= 0.0 {
        Ok(px)
    } else {
        Err("must be a finite number of pixels, at least 0".into())
    }
}

impl BackendArgs {
    /// The backend asked for (`auto`: CUDA device 0 when usable, else the CPU), not yet checked.
    pub fn chosen(&self) -> Backend {
        self.backend.backend(self.device)
    }

    /// The backend asked for; `cuda` gives the library's typed error when it cannot exist here.
    pub fn resolve(&self) -> clatch::Result<Backend> {
        let backend = self.chosen();
        backend.ensure_available()?;
        Ok(backend)
    }

    /// The backend asked for, its set-up started on a thread of its own ([`Backend::start`]) so that
    /// it overlaps checking and decoding the images; what is known at once (a build without CUDA, no
    /// driver) is an error here.
    pub fn start(&self) -> clatch::Result<clatch::BackendStart> {
        self.chosen().start()
    }
}

impl DetectArgs {
    /// Detector and descriptor configuration: the library's default (or the single-scale preset)
    /// with the flags given on top.
    pub fn config(&self) -> clatch::Result<ExtractorConfig> {
        self.config_from(if self.single_scale {
            ExtractorConfig::single_scale()
        } else {
            ExtractorConfig::default()
        })
    }

    /// [`DetectArgs::config`] for OpenCV-compatible LATCH, which describes full-resolution keypoints
    /// only: the single-scale preset unless --pyramid is given (which the caller then refuses).
    pub fn config_full_resolution(&self) -> clatch::Result<ExtractorConfig> {
        if self.pyramid.is_some() {
            return self.config();
        }
        self.config_from(ExtractorConfig::single_scale())
    }

    /// Whether the keypoints of every pyramid level fit the descriptor (at most 1024 pixels: the
    /// top level's are --keypoint-size x FACTOR^(LEVELS - 1) of the full image's); otherwise a
    /// message naming the options as given and what would fit.
    pub fn check_sizes(&self) -> Result<(), String> {
        let Ok(config) = self.config_unchecked() else {
            return Ok(()); // the library's own error follows
        };
        let Some(pyramid) = config.pyramid else {
            return Ok(());
        };
        let size = config.detector.keypoint_size;
        if pyramid.validate(size).is_ok() {
            return Ok(());
        }
        let factor = pyramid.scale_factor;
        let top = f64::from(size) * f64::from(factor).powi(pyramid.levels as i32 - 1);
        let levels_fit = (1..pyramid.levels)
            .rev()
            .find(|&l| Pyramid::new(l, factor).validate(size).is_ok());
        let size_fits = (1..=1024u32)
            .rev()
            .find(|&k| pyramid.validate(k as f32).is_ok());
        let pyramid_given = match self.pyramid {
            Some(_) => format!("--pyramid {}:{factor}", pyramid.levels),
            None => format!("the default pyramid {}:{factor}", pyramid.levels),
        };
        let size_given = match self.keypoint_size {
            Some(k) => format!("--keypoint-size {k}"),
            None => format!("the default keypoint size {size}"),
        };
        let mut fixes = Vec::new();
        if let Some(l) = levels_fit {
            fixes.push(format!("at most {l} levels with FACTOR {factor}"));
        }
        if let Some(k) = size_fits {
            fixes.push(format!("--keypoint-size at most {k} with these levels"));
        }
        Err(format!(
            "{pyramid_given} with {size_given}: keypoints on the top level would be {top:.0} \
             pixels wide, more than the 1024 a descriptor window may span; use {}",
            if fixes.is_empty() {
                "a smaller --keypoint-size".to_owned()
            } else {
                fixes.join(", or ")
            }
        ))
    }

    /// [`DetectArgs::config`] without [`DetectArgs::check_sizes`]'s message.
    fn config_unchecked(&self) -> clatch::Result<ExtractorConfig> {
        self.config_from(if self.single_scale {
            ExtractorConfig::single_scale()
        } else {
            ExtractorConfig::default()
        })
    }

    fn config_from(&self, base: ExtractorConfig) -> clatch::Result<ExtractorConfig> {
        let detector = &base.detector;
        let detector = detector
            .clone()
            .with_threshold(self.threshold)
            .with_max_keypoints(self.max_keypoints.unwrap_or(detector.max_keypoints))
            .with_budget_pixels(self.budget_pixels.map_or(detector.budget_pixels, |b| b.0))
            .with_keypoint_size(self.keypoint_size.unwrap_or(detector.keypoint_size))
            .with_grid(self.grid.unwrap_or(1) as usize)
            .with_level_budget(self.level_budget.unwrap_or(detector.level_budget))
            .with_ranking(self.ranking);
        let descriptor = &base.descriptor;
        let descriptor = descriptor
            .clone()
            .with_width(DescriptorWidth::from_bits(self.bits)?)
            .with_smoothing(self.smoothing.unwrap_or(descriptor.smoothing));
        let pyramid = self.pyramid.or(base.pyramid);
        Ok(base
            .with_detector(detector)
            .with_descriptor(descriptor)
            .with_pyramid(pyramid))
    }
}

impl MatchingArgs {
    /// Matcher configuration.
    pub fn config(&self) -> MatchConfig {
        MatchConfig::default()
            .with_ratio((!self.no_ratio).then_some(self.ratio))
            .with_cross_check(!self.no_cross_check)
            .with_max_distance(self.max_distance)
    }
}

/// The matcher settings in words, e.g. `ratio 0.8, cross-check`.
pub fn describe_matching(config: &MatchConfig) -> String {
    let mut parts = Vec::new();
    match config.ratio {
        Some(r) => parts.push(format!("ratio {r}")),
        None => parts.push("no ratio test".into()),
    }
    parts.push(if config.cross_check {
        "cross-check".into()
    } else {
        "no cross-check".into()
    });
    if let Some(d) = config.max_distance {
        parts.push(format!("max distance {d}"));
    }
    parts.join(", ")
}

// Its one test needs a build without CUDA.
#[cfg(all(test, not(feature = "cuda")))]
mod tests {
    use super::*;

    #[test]
    fn cuda_without_the_feature_is_a_typed_error() {
        let args = BackendArgs {
            backend: BackendFlag::named(Backend::Cuda { device: 0 }),
            device: 0,
        };
        assert!(matches!(
            args.resolve(),
            Err(clatch::Error::BackendUnavailable { .. })
        ));
    }
}
