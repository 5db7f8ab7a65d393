//! A folder run checked before any work: [`FolderPlan`].

use std::path::Path;

use crate::backend::{Backend, BackendStart};
use crate::colmap::camera::PinholeCamera;
use crate::colmap::error::ColmapError;
use crate::colmap::folder::ImageFolder;
use crate::colmap::folder_output::FolderOutput;
use crate::colmap::job::{FolderCamera, FolderJob, Overwrite};
use crate::colmap::pairs::resolve_pairs;
use crate::extract::Extractor;
use crate::matcher::Matcher;
use crate::output::{OutputLock, check_distinct, check_writable, check_writable_in_new_folder};

/// A [`FolderJob`] with everything checked before any work: the extractor and matching settings, the
/// backend (its set-up started), every photo's name and header ([`ImageFolder`]), the camera against
/// the photos' sizes, the pairs, and the outputs (files clatch may replace, none of them an input, no
/// existing database unless [`Overwrite::Replace`]). Nothing is written until
/// [`FolderPlan::run`] or [`FolderPlan::open_output`].
#[derive(Debug)]
pub struct FolderPlan {
    pub(crate) job: FolderJob,
    pub(crate) folder: ImageFolder,
    pub(crate) camera: Option<PinholeCamera>,
    pub(crate) pairs: Vec<(usize, usize)>,
    pub(crate) extractor: Extractor,
    /// The backend's set-up, running beside the checks and the first photos' decoding.
    pub(crate) start: BackendStart,
    /// The database's lock, held from the checks until the run ends (with its last clone).
    pub(crate) lock: OutputLock,
}

impl FolderPlan {
    /// [`FolderJob::plan`].
    pub(crate) fn new(job: &FolderJob) -> Result<Self, ColmapError> {
        let start = job.backend.start()?;
        let extractor = Extractor::starting(&start, job.extractor_config())?;
        // The matching rules checked now; the run's matcher is made on the backend once it is set
        // up (the CPU needs no set-up).
        Matcher::new(Backend::Cpu, job.matching.clone())?;
        let folder = ImageFolder::open(&job.images, &job.limits)?;
        let camera = match &job.camera {
            FolderCamera::PerPhoto => None,
            FolderCamera::KText { text, .. } => Some(folder.shared_camera(text)?),
            FolderCamera::Shared(camera) => {
                folder.check_one_size((camera.width, camera.height))?;
                Some(camera.validated()?)
            }
        };
        let pairs = resolve_pairs(job.pairs.as_deref(), &folder.names)?;
        check_outputs(job, &folder)?;
        let lock = OutputLock::acquire(&job.database)?;
        // Checked again under the lock: a run that ended meanwhile may have written it.
        check_outputs(job, &folder)?;
        Ok(Self {
            job: job.clone(),
            folder,
            camera,
            pairs,
            extractor,
            start,
            lock,
        })
    }

    /// The job.
    pub fn job(&self) -> &FolderJob {
        &self.job
    }

    /// The photos, their names and sizes.
    pub fn folder(&self) -> &ImageFolder {
        &self.folder
    }

    /// The camera every photo shares, if the job gives one.
    pub fn camera(&self) -> Option<&PinholeCamera> {
        self.camera.as_ref()
    }

    /// The pairs to match, as photo indices, in the order they are written.
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// The lock on the database, held until this plan, its output and every clone of the lock are
    /// dropped: a caller that works on the files after the run (runs COLMAP on them) keeps a clone.
    pub fn lock(&self) -> OutputLock {
        self.lock.clone()
    }

    /// The writer of this run's database and match list, under temporary names beside them
    /// ([`FolderOutput::create`]): the last stage, for a run whose photos and matches come from
    /// elsewhere (workers of a cluster) in the folder's order.
    pub fn open_output(&self) -> Result<FolderOutput, ColmapError> {
        FolderOutput::create(
            &self.job.database,
            &self.job.match_list,
            self.job.writes_match_list(),
            self.camera.as_ref(),
        )
        .map(|output| {
            output
                .holding(self.lock.clone())
                .with_verification(self.job.verification.clone(), self.job.backend)
                .with_guided_matching(self.job.guided_config())
        })
    }
}

/// The outputs: files clatch may replace (not folders, devices), none of them a photo or the camera
/// matrix file, and no existing database unless the job may replace it.
fn check_outputs(job: &FolderJob, folder: &ImageFolder) -> Result<(), ColmapError> {
    check_writable(&job.database)?;
    check_writable_in_new_folder(&job.match_list)?;
    let mut inputs: Vec<(&'static str, &Path)> = folder
        .paths
        .iter()
        .map(|p| ("image", p.as_path()))
        .collect();
    if let FolderCamera::KText {
        file: Some(file), ..
    } = &job.camera
    {
        inputs.push(("camera matrix", file));
    }
    check_distinct(
        &inputs,
        &[("database", &job.database), ("match list", &job.match_list)],
    )?;
    if let Some(other) = super::folder_output::workspace_owner(&job.match_list)
        && Some(other.as_str()) != job.database.file_name().and_then(|n| n.to_str())
    {
        return Err(ColmapError::WorkspaceOfAnother {
            workspace: job
                .match_list
                .parent()
                .unwrap_or(Path::new("."))
                .to_path_buf(),
            other,
        });
    }
    if job.overwrite == Overwrite::Refuse && job.database.exists() {
        return Err(ColmapError::DatabaseExists {
            path: job.database.display().to_string(),
        });
    }
    Ok(())
}
