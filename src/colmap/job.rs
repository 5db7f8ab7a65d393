//! What a folder run is asked to do: [`FolderJob`], the one description of the COLMAP folder pipeline
//! that the command-line tool, the Python package and its Ray driver all build.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use crate::backend::Backend;
use crate::colmap::camera::PinholeCamera;
use crate::colmap::corner::Refinement;
use crate::colmap::error::ColmapError;
use crate::colmap::folder::{DEFAULT_GRID, DEFAULT_MAX_KEYPOINTS};
use crate::colmap::pairs::PhotoRef;
use crate::colmap::plan::FolderPlan;
use crate::colmap::report::{FolderProgress, FolderReport};
use crate::decode::DecodeLimits;
use crate::extract::ExtractorConfig;
use crate::matching::MatchConfig;
use crate::verify::VerifyConfig;

/// The match list's file name in a workspace folder.
pub const MATCH_LIST_NAME: &str = "matches.txt";

/// The workspace of a database when none is given: `out.db` → `out-colmap/` beside it; any other
/// name keeps its extension, `out.sqlite` → `out.sqlite-colmap/`, so that `out.db` and
/// `out.sqlite` never share a workspace. (A database named `out` would share `out.db`'s: the
/// workspace records its database, and a run of the other is refused,
/// [`ColmapError::WorkspaceOfAnother`].)
///
/// ```
/// use std::path::Path;
/// let workspace = clatch::colmap::default_workspace(Path::new("runs/out.db"));
/// assert_eq!(workspace, Path::new("runs/out-colmap"));
/// let workspace = clatch::colmap::default_workspace(Path::new("runs/out.sqlite"));
/// assert_eq!(workspace, Path::new("runs/out.sqlite-colmap"));
/// ```
pub fn default_workspace(database: &Path) -> PathBuf {
    let is_db = database
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("db"));
    let name = if is_db {
        database.file_stem()
    } else {
        database.file_name()
    };
    let name = name.unwrap_or_default().to_string_lossy();
    database.with_file_name(format!("{name}-colmap"))
}

/// The cameras a folder run writes.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub enum FolderCamera {
    /// One camera per image size and EXIF focal length: the focal length from EXIF's 35 mm
    /// equivalent where a photo has one, else COLMAP's guess ([`super::photo_camera`]).
    #[default]
    PerPhoto,
    /// The intrinsic matrix K as text (nine numbers, row-major: [`PinholeCamera::from_k_text`]),
    /// shared by every photo, which all need the first one's size. `file`: the file it was read from,
    /// an input no output may name.
    KText {
        /// The text of K.
        text: String,
        /// The file the text was read from, if any.
        file: Option<PathBuf>,
    },
    /// This camera, shared by every photo, which all need its size.
    Shared(PinholeCamera),
}

/// What a run may do to an existing database.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum Overwrite {
    /// An existing database is an error, before any work.
    #[default]
    Refuse,
    /// An existing database (and match list) is replaced, once the new one is complete.
    Replace,
}

/// A folder of photos into a new COLMAP 3.8 database (and, without verification, a match list): which photos, which settings,
/// which outputs. [`FolderJob::run`] does the whole run in this process; its stages are
/// [`FolderJob::plan`] (every check, before any work), then [`super::FolderPlan::run`] (extract every
/// photo, match every pair, write both files under temporary names) and
/// [`super::WrittenFolder::commit`] (rename them into place). A run spread over other processes uses
/// the same stages' parts: [`super::extract_photos`] and [`super::match_photo_pairs`] wherever the
/// work runs, [`super::FolderPlan::open_output`] where the files are written; the same job writes the
/// same bytes either way.
///
/// ```no_run
/// use clatch::Backend;
/// use clatch::colmap::{FolderJob, Overwrite};
///
/// let job = FolderJob::new("photos/", "out.db")
///     .with_backend(Backend::auto())
///     .with_overwrite(Overwrite::Replace);
/// let report = job.run(Some(&mut |p| {
///     eprintln!("{}: {} of {}", p.stage, p.done, p.total);
///     std::ops::ControlFlow::Continue(())
/// }))?;
/// println!(
///     "{} photos, {} matches over {} pairs, {} verified, in {}",
///     report.counts.photos,
///     report.counts.matches,
///     report.counts.pairs,
///     report.counts.pairs_with_inliers,
///     report.database.display()
/// );
/// # Ok::<(), clatch::colmap::ColmapError>(())
/// ```
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct FolderJob {
    /// The folder of photos (its image files, not its subfolders: [`super::ImageFolder`]).
    pub images: PathBuf,
    /// The database to create.
    pub database: PathBuf,
    /// The match list (default: [`MATCH_LIST_NAME`] in [`default_workspace`]); its folder, the
    /// workspace, is created if missing. Written without verification (for COLMAP's
    /// `matches_importer`), and with verification only when [`FolderJob::write_match_list`] says so.
    pub match_list: PathBuf,
    /// Whether a run with verification writes the match list too (default `false`: the database
    /// holds the matches and their geometries, as after COLMAP's own matcher). A run without
    /// verification always writes it.
    pub write_match_list: bool,
    /// The cameras.
    pub camera: FolderCamera,
    /// The pairs to match, in the order they are written; `None`: every pair `(i, j)`, `i < j`
    /// ([`super::resolve_pairs`]).
    pub pairs: Option<Vec<(PhotoRef, PhotoRef)>>,
    /// Where extraction and matching run.
    pub backend: Backend,
    /// Detector and descriptor settings (default: [`FolderJob::default_extractor`]); the detector's
    /// sub-pixel method is always the refinement's ([`FolderJob::extractor_config`]).
    pub extractor: ExtractorConfig,
    /// Which matches are kept.
    pub matching: MatchConfig,
    /// How the keypoint positions written to COLMAP are refined below a pixel (default
    /// [`Refinement::Score`]).
    pub refinement: Refinement,
    /// Limits on the photos' sizes.
    pub limits: DecodeLimits,
    /// What may happen to an existing database.
    pub overwrite: Overwrite,
    /// Whether and how every pair's matches are verified ([`crate::verify`]) and written into the
    /// database's `matches` and `two_view_geometries`, as COLMAP's own matcher would, so that
    /// COLMAP's mapper runs straight on it (default [`FolderJob::default_verification`]; `None`:
    /// the match list alone, for COLMAP's `matches_importer` to verify). Verification runs on the
    /// job's backend ([`crate::Verifier`]): the same geometries, bit for bit, on every backend.
    pub verification: Option<VerifyConfig>,
    /// With [`FolderJob::verification`]: whether each verified pair's descriptors are matched again
    /// under its geometry ([`crate::verify::guided_matches`], with [`FolderJob::matching`]'s rules
    /// and the verification's threshold), the guided matches written as the pair's inliers (the
    /// putative matches stay the match list's), the guided matches passing the verification's
    /// neighbour rule too. Default `true`: on the generated facades it multiplied the correct
    /// inliers by 3.8 to 6.7 at 95.7 to 98.9 % within 4 px of the truth, and raised them by 23 % on
    /// Herz-Jesu at 97.2 % within 4 px of the true epipolar lines (cameras there slightly further
    /// off), for 1.6 to 2.6 times the run's CPU time (EVALUATION.md, "guided matching").
    pub guided_matching: bool,
}

impl FolderJob {
    /// The photos of `images` into the new database `database` (its workspace
    /// `<database>-colmap/` beside it), on the CPU, with the settings for structure from motion:
    /// [`FolderJob::default_extractor`], the default [`MatchConfig`] (ratio 0.8, cross-check),
    /// [`Refinement::Score`], one camera per image size and focal, every pair, every pair verified
    /// ([`FolderJob::default_verification`]) and no match list.
    pub fn new(images: impl Into<PathBuf>, database: impl Into<PathBuf>) -> Self {
        let database = database.into();
        Self {
            images: images.into(),
            match_list: default_workspace(&database).join(MATCH_LIST_NAME),
            database,
            camera: FolderCamera::default(),
            pairs: None,
            backend: Backend::Cpu,
            extractor: Self::default_extractor(),
            matching: MatchConfig::default(),
            refinement: Refinement::Score,
            limits: DecodeLimits::default(),
            overwrite: Overwrite::default(),
            verification: Some(Self::default_verification()),
            write_match_list: false,
            guided_matching: true,
        }
    }

    /// The verification settings of the folder run (`clatch colmap`, the Python `match_folder`):
    /// COLMAP 3.8's ([`VerifyConfig::default`]) with the neighbour rule
    /// on ([`crate::verify::NeighbourConsistency::default`]), which drops matches one period off on
    /// repeated structure (EVALUATION.md, "repeated structure: neighbour consistency").
    pub fn default_verification() -> VerifyConfig {
        VerifyConfig::default()
            .with_neighbour_consistency(Some(crate::verify::NeighbourConsistency::default()))
    }

    /// The extractor settings for structure from motion: the library's defaults with keypoints spread
    /// over a [`DEFAULT_GRID`] grid and a budget of [`DEFAULT_MAX_KEYPOINTS`] whatever the photo's
    /// size (COLMAP's own per-image budget; the structure-from-motion figures were measured so).
    pub fn default_extractor() -> ExtractorConfig {
        let mut config = ExtractorConfig::default();
        config.detector.grid = DEFAULT_GRID;
        config.detector.max_keypoints = DEFAULT_MAX_KEYPOINTS;
        config.detector.budget_pixels = None;
        config
    }

    /// The match list in `workspace`: [`MATCH_LIST_NAME`] there.
    pub fn with_workspace(mut self, workspace: impl AsRef<Path>) -> Self {
        self.match_list = workspace.as_ref().join(MATCH_LIST_NAME);
        self
    }

    /// The match list at `match_list`.
    pub fn with_match_list(mut self, match_list: impl Into<PathBuf>) -> Self {
        self.match_list = match_list.into();
        self
    }

    /// The cameras.
    pub fn with_camera(mut self, camera: FolderCamera) -> Self {
        self.camera = camera;
        self
    }

    /// These pairs, by photo index or name, in this order (instead of every pair).
    pub fn with_pairs<A: Into<PhotoRef>, B: Into<PhotoRef>>(
        mut self,
        pairs: impl IntoIterator<Item = (A, B)>,
    ) -> Self {
        self.pairs = Some(
            pairs
                .into_iter()
                .map(|(a, b)| (a.into(), b.into()))
                .collect(),
        );
        self
    }

    /// The backend.
    pub fn with_backend(mut self, backend: Backend) -> Self {
        self.backend = backend;
        self
    }

    /// The detector and descriptor settings.
    pub fn with_extractor(mut self, extractor: ExtractorConfig) -> Self {
        self.extractor = extractor;
        self
    }

    /// The matching rules.
    pub fn with_matching(mut self, matching: MatchConfig) -> Self {
        self.matching = matching;
        self
    }

    /// The sub-pixel refinement of the keypoints written.
    pub fn with_refinement(mut self, refinement: Refinement) -> Self {
        self.refinement = refinement;
        self
    }

    /// The limits on the photos' sizes.
    pub fn with_limits(mut self, limits: DecodeLimits) -> Self {
        self.limits = limits;
        self
    }

    /// What may happen to an existing database.
    pub fn with_overwrite(mut self, overwrite: Overwrite) -> Self {
        self.overwrite = overwrite;
        self
    }

    /// Verifies every pair with `config` and writes the matches and geometries into the database
    /// ([`FolderJob::verification`]).
    pub fn with_verification(mut self, config: VerifyConfig) -> Self {
        self.verification = Some(config);
        self
    }

    /// Verifies nothing: writes the match list for COLMAP's `matches_importer` to verify
    /// ([`FolderJob::verification`] `None`).
    pub fn without_verification(mut self) -> Self {
        self.verification = None;
        self
    }

    /// Whether a run with verification writes the match list too ([`FolderJob::write_match_list`]).
    pub fn with_match_list_written(mut self, write: bool) -> Self {
        self.write_match_list = write;
        self
    }

    /// Whether the run writes the match list: always without verification, on request with it.
    pub fn writes_match_list(&self) -> bool {
        self.verification.is_none() || self.write_match_list
    }

    /// Whether each verified pair is matched again under its geometry
    /// ([`FolderJob::guided_matching`]; on by default).
    pub fn with_guided_matching(mut self, guided: bool) -> Self {
        self.guided_matching = guided;
        self
    }

    /// The guided matching the run does: with verification and [`FolderJob::guided_matching`],
    /// [`FolderJob::matching`]'s rules under the verification's threshold and with its neighbour
    /// rule; else `None`.
    pub fn guided_config(&self) -> Option<crate::verify::GuidedMatching> {
        let verification = self
            .verification
            .as_ref()
            .filter(|_| self.guided_matching)?;
        Some(
            crate::verify::GuidedMatching::default()
                .with_rules(self.matching.clone())
                .with_max_error(verification.max_error)
                .with_neighbour_consistency(verification.neighbour_consistency),
        )
    }

    /// The extractor settings the run uses: [`FolderJob::extractor`] with the detector's sub-pixel
    /// method the refinement's ([`Refinement::detector_subpixel`]).
    pub fn extractor_config(&self) -> ExtractorConfig {
        let mut config = self.extractor.clone();
        config.detector.subpixel = self.refinement.detector_subpixel();
        config
    }

    /// Checks everything before any work ([`FolderPlan`]): the settings, every photo's name and
    /// header, the camera, the pairs and the outputs; starts the backend's set-up on a thread of its
    /// own. Writes nothing.
    pub fn plan(&self) -> Result<FolderPlan, ColmapError> {
        FolderPlan::new(self)
    }

    /// The whole run in this process: [`FolderJob::plan`], [`FolderPlan::run`], then
    /// [`super::WrittenFolder::commit`]. `progress` hears of every photo and group of pairs, and
    /// stops the run by returning [`ControlFlow::Break`] ([`ColmapError::Stopped`]). On any error
    /// nothing is left at the outputs (a match list folder the run created stays, empty) and an
    /// existing database is untouched.
    pub fn run(
        &self,
        progress: Option<&mut dyn FnMut(FolderProgress) -> ControlFlow<()>>,
    ) -> Result<FolderReport, ColmapError> {
        self.plan()?.run(progress)?.commit()
    }
}
