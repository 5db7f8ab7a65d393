//! What a folder run tells as it goes ([`FolderProgress`]) and at its end ([`FolderReport`]).

use std::path::PathBuf;
use std::time::Duration;

use crate::colmap::writer::FolderCounts;
use crate::prefetch::Prefetched;

/// A stage of a folder run that reports its progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FolderStage {
    /// Photos decoded, detected, described, refined and written to the database.
    Extraction,
    /// Pairs matched, verified ([`super::FolderJob::verification`]) and written.
    Matching,
}

impl std::fmt::Display for FolderStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FolderStage::Extraction => "extracting features",
            FolderStage::Matching => "matching pairs",
        })
    }
}

/// How far a stage is: `done` of its `total` photos or pairs. Each stage reports `done = 0` as it
/// starts, then more in increasing order (every photo; every group of pairs matched together), on the
/// thread that runs the job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct FolderProgress {
    /// The stage.
    pub stage: FolderStage,
    /// Photos or pairs done.
    pub done: usize,
    /// Photos or pairs of the stage.
    pub total: usize,
}

/// Wall time of each stage of a folder run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct FolderTimes {
    /// The backend's set-up (on the GPU its context and kernels), on a thread of its own beside the
    /// checks and the first photos' decoding; extraction includes any wait for it.
    pub set_up: Duration,
    /// Extracting every photo: decoding, detecting, describing, refining (writing them excluded).
    pub extraction: Duration,
    /// The decoders' side of extraction: their summed time and how long extraction waited for them.
    pub decoding: Prefetched,
    /// Matching every pair (writing the matches excluded).
    pub matching: Duration,
    /// Verifying every pair's matches ([`super::FolderJob::verification`]; zero without it).
    pub verification: Duration,
    /// Writing the database and the match list, and putting them in place.
    pub writing: Duration,
}

/// What a folder run wrote, and how long each stage took.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct FolderReport {
    /// The database (once committed; before, the run's temporary file beside it).
    pub database: PathBuf,
    /// The match list (likewise; `None`: the run wrote none, [`super::FolderJob::writes_match_list`]).
    pub match_list: Option<PathBuf>,
    /// Photos, keypoints, pairs and matches written.
    pub counts: FolderCounts,
    /// Wall time of each stage (those a run spread over other processes did not time are zero).
    pub times: FolderTimes,
}
