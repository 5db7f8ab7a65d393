//! A folder's database and match list (when one is written) under temporary names beside their final
//! paths, and renamed into place only once both are complete: a failed run leaves nothing at the
//! outputs, and an earlier database is replaced only by a complete one.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::backend::Backend;
use crate::colmap::camera::PinholeCamera;
use crate::colmap::error::ColmapError;
use crate::colmap::folder::Photo;
use crate::colmap::pair_id;
use crate::colmap::report::{FolderReport, FolderTimes};
use crate::colmap::writer::{FolderCounts, FolderWriter};
use crate::descriptor::DescriptorSet;
use crate::keypoint::KeyPoint;
use crate::matching::Match;
use crate::output::{OutputError, OutputLock, Staged};
use crate::parallel::*;
use crate::verifier::Verifier;
use crate::verify::{self, GuidedMatches, GuidedMatching, VerifyConfig, ViewPair};

/// The file in a match list's folder naming the database the list belongs to.
pub const OWNER_NAME: &str = ".clatch-database";

fn owner_path(match_list: &Path) -> PathBuf {
    match match_list.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.join(OWNER_NAME),
        _ => PathBuf::from(OWNER_NAME),
    }
}

/// The database file name the match list's folder belongs to, if an earlier run wrote one there.
pub(crate) fn workspace_owner(match_list: &Path) -> Option<String> {
    let text = std::fs::read_to_string(owner_path(match_list)).ok()?;
    Some(text.trim_end_matches('\n').to_owned()).filter(|s| !s.is_empty())
}

/// A write failure of the database or the match list as an error naming the file (its final path:
/// the temporary one beside it is removed).
fn naming_the_file(
    e: ColmapError,
    (database, match_list): &(PathBuf, Option<PathBuf>),
) -> ColmapError {
    match e {
        ColmapError::Sqlite { .. } => ColmapError::Writing {
            path: database.clone(),
            source: Box::new(e),
        },
        ColmapError::MatchListIo(_) => ColmapError::Writing {
            path: match_list.clone().unwrap_or_else(|| database.clone()),
            source: Box::new(e),
        },
        other => other,
    }
}

/// The one writer of a folder run ([`FolderWriter`]) over temporary files: the stage every run ends
/// in, whether it extracted and matched in this process ([`super::FolderPlan::run`]) or gathered the
/// photos and matches from workers. [`FolderOutput::finish`] completes both files, which
/// [`WrittenFolder::commit`] then renames into place; dropped before, they are removed.
pub struct FolderOutput {
    // Declared before `staged`: the database is closed before its temporary file is removed.
    writer: FolderWriter<BufWriter<File>>,
    staged: Staged,
    /// The locks on the database and on the match list (its file beside it, removed before `made`).
    locks: Vec<OutputLock>,
    /// The temporary database and match list (if written), then their final paths.
    temp: (PathBuf, Option<PathBuf>),
    outputs: (PathBuf, Option<PathBuf>),
    writing: Duration,
    /// The pairs' verification, when the job asks for it.
    verification: Option<Verification>,
    /// The verified pairs' guided matching, when the job asks for it.
    guided: Option<Guided>,
    /// Declared last: removed (if still empty) after the temporary files.
    made: MadeFolders,
}

/// What verifying the pairs as they are written needs: the settings, every photo's keypoints, and
/// the time spent.
#[derive(Debug)]
struct Verification {
    config: VerifyConfig,
    /// The run's backend: verification waits for its set-up only when the first pairs come.
    backend: Backend,
    keypoints: Vec<Vec<KeyPoint>>,
    time: Duration,
}

/// What matching the verified pairs again under their geometry needs: the settings and every
/// photo's descriptors (`None` for a photo added without them).
#[derive(Debug)]
struct Guided {
    config: GuidedMatching,
    descriptors: Vec<Option<DescriptorSet>>,
}

/// The folders a run created for its outputs, innermost first: removed again, each only while empty,
/// when the run ends without putting its files in place (so a failed run leaves no empty workspace
/// behind, and never removes a file).
#[derive(Debug, Default)]
struct MadeFolders(Vec<PathBuf>);

impl MadeFolders {
    /// Creates `folder` and whatever of its ancestors is missing, remembering which.
    fn create(folder: &Path) -> Result<Self, ColmapError> {
        let missing: Vec<PathBuf> = folder
            .ancestors()
            .take_while(|p| !p.as_os_str().is_empty() && std::fs::symlink_metadata(p).is_err())
            .map(Path::to_path_buf)
            .collect();
        std::fs::create_dir_all(folder).map_err(OutputError::write(folder))?;
        Ok(Self(missing))
    }

    /// The run put its files in place: the folders stay.
    fn keep(mut self) {
        self.0.clear();
    }
}

impl Drop for MadeFolders {
    fn drop(&mut self) {
        for folder in &self.0 {
            // Fails, leaving the folder, when anything is in it.
            if std::fs::remove_dir(folder).is_err() {
                break;
            }
        }
    }
}

impl FolderOutput {
    /// Creates the match list's folder, the workspace, if it is missing (removed again, if still
    /// empty, when the run fails), then a new database and (with `write_match_list`) match list under
    /// temporary names beside `database` and `match_list`; the match list's path is locked either
    /// way. `camera`: one camera for every photo, or `None` for one per size and focal
    /// ([`FolderWriter::create`]).
    pub fn create(
        database: &Path,
        match_list: &Path,
        write_match_list: bool,
        camera: Option<&PinholeCamera>,
    ) -> Result<Self, ColmapError> {
        let began = Instant::now();
        let made = match match_list.parent().filter(|p| !p.as_os_str().is_empty()) {
            Some(folder) => MadeFolders::create(folder)?,
            None => MadeFolders::default(),
        };
        let locks = vec![OutputLock::acquire(match_list)?];
        let mut staged = Staged::new();
        let temp_database = staged.reserve(database)?;
        // `Database::create` makes the file itself (and never opens an existing one).
        std::fs::remove_file(&temp_database).map_err(OutputError::write(&temp_database))?;
        let (temp_list, list) = match write_match_list {
            true => {
                let (path, file) = staged.open(match_list)?;
                (Some(path), Some(BufWriter::new(file)))
            }
            false => (None, None),
        };
        let owner = database.file_name().unwrap_or_default().to_string_lossy();
        staged.write(&owner_path(match_list), |w| writeln!(w, "{owner}"))?;
        let writer = FolderWriter::create(&temp_database, list, camera)?;
        let final_list = write_match_list.then(|| match_list.to_path_buf());
        Ok(Self {
            writer,
            staged,
            locks,
            temp: (temp_database, temp_list),
            outputs: (database.to_path_buf(), final_list),
            writing: began.elapsed(),
            verification: None,
            guided: None,
            made,
        })
    }

    /// The same output verifying every pair it is given with `config` ([`crate::verify`]) on
    /// `backend` and writing its matches and two-view geometry into the database
    /// ([`FolderWriter::add_geometry`]); `None`: the match list alone.
    pub(crate) fn with_verification(
        mut self,
        config: Option<VerifyConfig>,
        backend: Backend,
    ) -> Self {
        self.verification = config.map(|config| Verification {
            config,
            backend,
            keypoints: Vec::new(),
            time: Duration::ZERO,
        });
        self
    }

    /// The same output matching every verified pair again under its geometry with `config`
    /// ([`crate::verify::guided_matches`]) and writing the guided matches as its inliers; `None`:
    /// the verified inliers. Needs verification and every photo added with its descriptors
    /// ([`FolderOutput::add_described_photo`]).
    pub(crate) fn with_guided_matching(mut self, config: Option<GuidedMatching>) -> Self {
        self.guided = config.map(|config| Guided {
            config,
            descriptors: Vec::new(),
        });
        self
    }

    /// The same output holding `lock` too (the plan's lock on the database) until it is committed.
    pub(crate) fn holding(mut self, lock: OutputLock) -> Self {
        self.locks.push(lock);
        self
    }

    /// Adds the next photo: [`FolderWriter::add_photo`] (and keeps its keypoints when the pairs are
    /// verified).
    pub fn add_photo(&mut self, photo: &Photo) -> Result<usize, ColmapError> {
        self.add_photo_and(photo, None)
    }

    /// [`FolderOutput::add_photo`] with the photo's descriptors (row `i` describes keypoint `i`),
    /// which a job with guided matching ([`super::FolderJob::guided_matching`]) needs for every
    /// photo of a pair; kept only then.
    pub fn add_described_photo(
        &mut self,
        photo: &Photo,
        descriptors: &DescriptorSet,
    ) -> Result<usize, ColmapError> {
        self.add_photo_and(photo, Some(descriptors))
    }

    fn add_photo_and(
        &mut self,
        photo: &Photo,
        descriptors: Option<&DescriptorSet>,
    ) -> Result<usize, ColmapError> {
        let index = self.timed(|w| w.add_photo(photo))?;
        if let Some(verification) = &mut self.verification {
            verification.keypoints.push(photo.keypoints.clone());
        }
        if let Some(guided) = &mut self.guided {
            guided.descriptors.push(descriptors.cloned());
        }
        Ok(index)
    }

    /// Adds the matches of a pair ([`FolderWriter::add_matches`]) and, when the job verifies, its
    /// two-view geometry.
    pub fn add_matches(
        &mut self,
        i: usize,
        j: usize,
        matches: &[Match],
    ) -> Result<(), ColmapError> {
        self.add_pairs(&[(i, j)], &[matches])
    }

    /// Adds the matches of several pairs, in order, and, when the job verifies, their two-view
    /// geometries, the pairs verified side by side (rayon); the bytes are those of adding each pair
    /// in turn.
    pub fn add_pairs(
        &mut self,
        pairs: &[(usize, usize)],
        matches: &[&[Match]],
    ) -> Result<(), ColmapError> {
        for (&(i, j), found) in pairs.iter().zip(matches) {
            self.timed(|w| w.add_matches(i, j, found))?;
        }
        let Some(verification) = &self.verification else {
            return Ok(());
        };
        let began = Instant::now();
        let geometries = self.geometries(verification, pairs, matches)?;
        let guided = match &self.guided {
            Some(guided) => self.guided(verification, guided, pairs, &geometries)?,
            None => vec![None; pairs.len()],
        };
        if let Some(verification) = &mut self.verification {
            verification.time += began.elapsed();
        }
        for (((&(i, j), found), geometry), guided) in
            pairs.iter().zip(matches).zip(&geometries).zip(&guided)
        {
            match guided {
                Some(g) => self.timed(|w| w.add_guided_geometry(i, j, found, g))?,
                None => self.timed(|w| w.add_geometry(i, j, found, geometry))?,
            }
        }
        Ok(())
    }

    /// The guided matches of `pairs` under their verified `geometries` (`None` for a pair whose
    /// geometry has no constraint), the pairs side by side (rayon).
    fn guided(
        &self,
        verification: &Verification,
        guided: &Guided,
        pairs: &[(usize, usize)],
        geometries: &[verify::TwoViewGeometry],
    ) -> Result<Vec<Option<GuidedMatches>>, ColmapError> {
        let described = |position: usize, image: usize| {
            guided
                .descriptors
                .get(image)
                .and_then(Option::as_ref)
                .ok_or(ColmapError::MissingDescriptors { position, image })
        };
        let inputs = pairs
            .iter()
            .enumerate()
            .map(|(position, &(i, j))| Ok((described(position, i)?, described(position, j)?)))
            .collect::<Result<Vec<_>, ColmapError>>()?;
        let found: Vec<crate::Result<Option<GuidedMatches>>> = pairs
            .par_iter()
            .enumerate()
            .map(|(position, &(i, j))| {
                // Indices checked by `geometries` (which found a photo's keypoints for each).
                let (a, b) = (&verification.keypoints[i], &verification.keypoints[j]);
                let (da, db) = inputs[position];
                verify::guided_matches(a, b, da, db, &geometries[position], &guided.config)
            })
            .collect();
        Ok(found.into_iter().collect::<crate::Result<Vec<_>>>()?)
    }

    /// The verified geometries of `pairs` (photo indices, matches already written), each pair's
    /// sampler keyed by COLMAP's pair id.
    fn geometries(
        &self,
        verification: &Verification,
        pairs: &[(usize, usize)],
        matches: &[&[Match]],
    ) -> Result<Vec<verify::TwoViewGeometry>, ColmapError> {
        let photos = verification.keypoints.len();
        let views = pairs
            .iter()
            .zip(matches)
            .map(|(&(i, j), found)| {
                let (Some(a), Some(b), Some(ca), Some(cb)) = (
                    verification.keypoints.get(i),
                    verification.keypoints.get(j),
                    self.writer.verify_camera(i),
                    self.writer.verify_camera(j),
                ) else {
                    return Err(ColmapError::BadPair {
                        i,
                        j,
                        photos,
                        reason: "an index is not one of the photos written",
                    });
                };
                Ok(ViewPair::new(a, b, found)
                    .with_cameras(ca, cb)
                    .with_key(pair_id(i as u32 + 1, j as u32 + 1)))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let verifier = Verifier::new(verification.backend, verification.config.clone())?;
        Ok(verifier.verify_pairs(&views)?)
    }

    /// Time spent verifying so far (zero without verification).
    pub(crate) fn verifying(&self) -> Duration {
        self.verification
            .as_ref()
            .map_or(Duration::ZERO, |v| v.time)
    }

    /// `write` on the writer, its time added to the writing time; a failure to write (a full disk)
    /// names the file.
    fn timed<T>(
        &mut self,
        write: impl FnOnce(&mut FolderWriter<BufWriter<File>>) -> Result<T, ColmapError>,
    ) -> Result<T, ColmapError> {
        let began = Instant::now();
        let result = write(&mut self.writer);
        self.writing += began.elapsed();
        result.map_err(|e| naming_the_file(e, &self.outputs))
    }

    /// Photos, keypoints, pairs and matches written so far.
    pub fn counts(&self) -> FolderCounts {
        self.writer.counts()
    }

    /// Time spent writing so far.
    pub fn writing(&self) -> Duration {
        self.writing
    }

    /// Commits the database and writes the match list to disk, both still under their temporary
    /// names.
    pub fn finish(self) -> Result<WrittenFolder, ColmapError> {
        let began = Instant::now();
        let counts = self.writer.counts();
        let outputs = &self.outputs;
        let name = |e| naming_the_file(e, outputs);
        if let Some(list) = self.writer.finish().map_err(name)? {
            let file = list
                .into_inner()
                .map_err(|e| name(ColmapError::MatchListIo(e.into_error())))?;
            file.sync_all()
                .map_err(|e| name(ColmapError::MatchListIo(e)))?;
        }
        Ok(WrittenFolder {
            staged: self.staged,
            locks: self.locks,
            report: FolderReport {
                database: self.temp.0,
                match_list: self.temp.1,
                counts,
                times: FolderTimes {
                    writing: self.writing + began.elapsed(),
                    verification: self.verification.map_or(Duration::ZERO, |v| v.time),
                    ..FolderTimes::default()
                },
            },
            outputs: self.outputs,
            made: self.made,
        })
    }
}

/// A folder's database and match list, complete under temporary names beside their final paths (for
/// a program that reads them first: `colmap matches_importer` verifies the matches into the
/// database): [`WrittenFolder::commit`] renames them into place; dropped uncommitted, they are
/// removed.
#[derive(Debug)]
pub struct WrittenFolder {
    staged: Staged,
    /// Released once the files are in place (or removed).
    locks: Vec<OutputLock>,
    /// The report, its paths the temporary files'.
    report: FolderReport,
    /// The final database and match list (if written).
    outputs: (PathBuf, Option<PathBuf>),
    /// Declared last: removed (if still empty) after the temporary files.
    made: MadeFolders,
}

impl WrittenFolder {
    /// The locks on the database and the match list, held until this value and every clone are
    /// dropped (a caller that runs a program on the files keeps them past [`WrittenFolder::commit`]).
    pub fn locks(&self) -> Vec<OutputLock> {
        self.locks.clone()
    }

    /// The complete database, under its temporary name.
    pub fn database(&self) -> &Path {
        &self.report.database
    }

    /// The complete match list, under its temporary name (`None`: the run writes none,
    /// [`super::FolderJob::writes_match_list`]).
    pub fn match_list(&self) -> Option<&Path> {
        self.report.match_list.as_deref()
    }

    /// Photos, keypoints, pairs and matches written.
    pub fn counts(&self) -> FolderCounts {
        self.report.counts
    }

    /// The stages' times, known to this process (a run that extracted and matched here fills them in).
    pub(crate) fn times_mut(&mut self) -> &mut FolderTimes {
        &mut self.report.times
    }

    /// Renames the database and the match list into place (replacing older files there) and returns
    /// the run's report with their final paths.
    pub fn commit(self) -> Result<FolderReport, ColmapError> {
        let began = Instant::now();
        self.staged.commit()?;
        drop(self.locks);
        self.made.keep();
        let mut report = self.report;
        (report.database, report.match_list) = self.outputs;
        report.times.writing += began.elapsed();
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_names_the_file() {
        let outputs = (
            PathBuf::from("runs/out.db"),
            Some(PathBuf::from("runs/ws/matches.txt")),
        );
        let full = || std::io::Error::other("No space left on device");
        let e = naming_the_file(
            ColmapError::Sqlite {
                operation: "inserting keypoints",
                source: rusqlite::Error::InvalidQuery,
            },
            &outputs,
        );
        assert!(
            e.to_string().starts_with("cannot write runs/out.db: "),
            "{e}"
        );
        let e = naming_the_file(ColmapError::MatchListIo(full()), &outputs);
        assert!(e.to_string().contains("runs/ws/matches.txt"), "{e}");
        assert!(e.to_string().contains("No space left"), "{e}");
    }
}
