//! A folder run in this process: every photo extracted and written as it comes, then the pairs
//! matched and written a group at a time ([`FolderPlan::run`]).

use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use crate::collection::DescriptorCollection;
use crate::colmap::error::ColmapError;
use crate::colmap::folder::extract_each_photo;
use crate::colmap::folder_output::{FolderOutput, WrittenFolder};
#[cfg(doc)]
use crate::colmap::pairs::match_photo_pairs;
use crate::colmap::plan::FolderPlan;
use crate::colmap::report::{FolderProgress, FolderStage};
use crate::descriptor::DescriptorSet;
use crate::matcher::Matcher;
use crate::matching::Match;
use crate::prefetch::Prefetched;

/// Pairs matched in one call: about this many calls over the stage (its progress steps), each of
/// [`MIN_PAIRS_PER_CALL`] to [`MAX_PAIRS_PER_CALL`] pairs. Only the descriptors stay in memory
/// between calls, never every pair's matches; a pair's matches do not depend on the grouping.
const CALLS_PER_STAGE: usize = 64;
/// Fewest pairs per call (a GPU uploads the sets of each call's photos).
const MIN_PAIRS_PER_CALL: usize = 16;
/// Most pairs per call (their matches are held until written).
const MAX_PAIRS_PER_CALL: usize = 1024;

/// Pairs matched in one call when `total` are to be matched.
fn pairs_per_call(total: usize) -> usize {
    (total / CALLS_PER_STAGE).clamp(MIN_PAIRS_PER_CALL, MAX_PAIRS_PER_CALL)
}

/// The caller's progress callback, if any, as the run's stop signal.
struct Progress<'a>(Option<&'a mut dyn FnMut(FolderProgress) -> ControlFlow<()>>);

impl Progress<'_> {
    fn tell(&mut self, stage: FolderStage, done: usize, total: usize) -> Result<(), ColmapError> {
        let stop = match &mut self.0 {
            Some(progress) => progress(FolderProgress { stage, done, total }).is_break(),
            None => false,
        };
        if stop {
            return Err(ColmapError::Stopped { stage });
        }
        Ok(())
    }
}

impl FolderPlan {
    /// Runs the stages in this process: opens the output ([`FolderPlan::open_output`]), extracts
    /// every photo with its decoding on worker threads ahead of the extractor
    /// ([`super::extract_each_photo`]) and writes it as it comes, waits for the backend's set-up,
    /// matches the pairs a group at a time (as [`match_photo_pairs`] would) and writes each group's matches in
    /// the pairs' order, then finishes both files under their temporary names: the caller commits
    /// them ([`WrittenFolder::commit`]), after running a program on them if it likes. `progress`:
    /// as [`super::FolderJob::run`]. On any error nothing is left at the outputs.
    pub fn run(
        self,
        progress: Option<&mut dyn FnMut(FolderProgress) -> ControlFlow<()>>,
    ) -> Result<WrittenFolder, ColmapError> {
        let mut progress = Progress(progress);
        let mut output = self.open_output()?;
        let (descriptors, extraction, decoding) = self.extract(&mut output, &mut progress)?;
        let set_up = self.start.wait()?;
        let matcher = Matcher::new(self.job.backend, self.job.matching.clone())?;
        let matching = match_into(
            &matcher,
            &descriptors,
            &self.pairs,
            &mut output,
            &mut progress,
        )?;
        let mut written = output.finish()?;
        let times = written.times_mut();
        times.set_up = set_up;
        times.extraction = extraction;
        times.decoding = decoding;
        times.matching = matching;
        Ok(written)
    }

    /// Extracts every photo into `output`; returns their descriptors, the stage's time (writing
    /// excluded) and the decoders' timings.
    fn extract(
        &self,
        output: &mut FolderOutput,
        progress: &mut Progress<'_>,
    ) -> Result<(Vec<DescriptorSet>, Duration, Prefetched), ColmapError> {
        let total = self.folder.paths.len();
        progress.tell(FolderStage::Extraction, 0, total)?;
        let (began, wrote) = (Instant::now(), output.writing());
        let mut descriptors = Vec::with_capacity(total);
        let decoding = extract_each_photo(
            &self.extractor,
            (&self.folder.paths, &self.folder.names),
            &self.job.limits,
            self.job.refinement,
            |i, photo, set| {
                output.add_described_photo(&photo, &set)?;
                descriptors.push(set);
                progress.tell(FolderStage::Extraction, i + 1, total)
            },
        )?;
        let stage = began.elapsed().saturating_sub(output.writing() - wrote);
        Ok((descriptors, stage, decoding))
    }
}

/// Matches `pairs` a group at a time and writes each group's matches into `output`, in order;
/// returns the stage's time (writing excluded). The descriptors are held by one collection on the
/// matcher's backend for the whole stage (on a GPU: uploaded once, not once per group); a pair's
/// matches are those of [`match_photo_pairs`], which runs spread over workers use.
fn match_into(
    matcher: &Matcher,
    descriptors: &[DescriptorSet],
    pairs: &[(usize, usize)],
    output: &mut FolderOutput,
    progress: &mut Progress<'_>,
) -> Result<Duration, ColmapError> {
    let total = pairs.len();
    progress.tell(FolderStage::Matching, 0, total)?;
    let (began, wrote, verified) = (Instant::now(), output.writing(), output.verifying());
    let Some(width) = descriptors.first().map(DescriptorSet::width) else {
        return Ok(began.elapsed()); // no photos, so no pairs
    };
    let mut collection = DescriptorCollection::new(matcher, width)?;
    collection.add(&descriptors.iter().collect::<Vec<_>>())?;
    let mut done = 0;
    for group in pairs.chunks(pairs_per_call(total)) {
        let found = collection.match_pairs(group)?;
        let found: Vec<&[Match]> = found.iter().map(Vec::as_slice).collect();
        output.add_pairs(group, &found)?;
        done += group.len();
        progress.tell(FolderStage::Matching, done, total)?;
    }
    Ok(began
        .elapsed()
        .saturating_sub(output.writing() - wrote)
        .saturating_sub(output.verifying() - verified))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_are_matched_in_about_64_calls_of_16_to_1024() {
        assert_eq!(pairs_per_call(0), 16);
        assert_eq!(pairs_per_call(55), 16);
        assert_eq!(pairs_per_call(4950), 77);
        assert_eq!(pairs_per_call(10_000_000), 1024);
    }
}
