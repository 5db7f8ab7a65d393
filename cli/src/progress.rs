//! A progress bar over a command's stages, drawn to stderr (indicatif hides it when stderr is not a
//! terminal, so piped output stays clean).

use std::borrow::Cow;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// Progress over a fixed number of stages.
pub struct Progress(ProgressBar);

impl Progress {
    /// A bar of `stages` steps on stderr.
    pub fn new(stages: u64) -> Self {
        let bar = ProgressBar::new(stages);
        if let Ok(style) =
            ProgressStyle::with_template("{spinner:.cyan} [{bar:24.cyan/blue}] {pos}/{len} {msg}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.enable_steady_tick(Duration::from_millis(100));
        Self(bar)
    }

    /// A bar counting `len` items of one stage (images, pairs) under `message`, with their rate.
    pub fn counter(len: u64, message: impl Into<Cow<'static, str>>) -> Self {
        let progress = Self::new(len);
        if let Ok(style) = ProgressStyle::with_template(
            "{spinner:.cyan} [{bar:24.cyan/blue}] {pos}/{len} {msg} ({per_sec}, {eta} left)",
        ) {
            progress.0.set_style(style.progress_chars("=> "));
        }
        progress.stage(message);
        progress
    }

    /// A bar that never draws, for tests.
    #[cfg(test)]
    pub fn hidden() -> Self {
        Self(ProgressBar::hidden())
    }

    /// Announces the stage about to run.
    pub fn stage(&self, message: impl Into<Cow<'static, str>>) {
        self.0.set_message(message);
    }

    /// Marks the current stage done.
    pub fn done(&self) {
        self.0.inc(1);
    }

    /// Moves a counter to `done` items.
    pub fn done_so_far(&self, done: u64) {
        self.0.set_position(done);
    }

    /// Removes the bar so that the report prints on a clean terminal.
    pub fn finish(&self) {
        self.0.finish_and_clear();
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        // On an early return (an error) the bar must not linger above the error message.
        if !self.0.is_finished() {
            self.0.finish_and_clear();
        }
    }
}
