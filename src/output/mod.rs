//! Writing files without losing any: each file goes to a temporary file in its final folder and is
//! renamed into place only when every output of the run is complete ([`Staged`]); an output that
//! names an input, or another output, is refused before any work ([`check_distinct`]), and so is a
//! path that is not a regular file ([`check_writable`]).
//!
//! The COLMAP writer (`clatch::colmap`'s `FolderOutput`) and every file the command-line tool writes
//! go through this module.
//!
//! ```
//! use std::io::Write;
//! use clatch::output::Staged;
//!
//! let dir = std::env::temp_dir().join(format!("clatch-doc-output-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let notes = dir.join("notes.txt");
//! let mut staged = Staged::new();
//! staged.write(&notes, |w| w.write_all(b"complete"))?;
//! assert!(!notes.exists(), "nothing at the final path before the commit");
//! staged.commit()?;
//! assert_eq!(std::fs::read_to_string(&notes)?, "complete");
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod checks;
mod lock;
mod staged;

use std::path::PathBuf;

use thiserror::Error;

pub use checks::{
    check_distinct, check_writable, check_writable_in_new_folder, ends_with_separator, file_kind,
};
pub use lock::{OutputLock, lock_path};
pub use staged::{
    Staged, TempDir, Uninterrupted, remove_temporaries, sweep_stale_temporaries, temporary_pid,
    write_file,
};

/// Why an output was refused or could not be written. Every variant names the file.
// Field names are described by each variant's message.
#[allow(missing_docs)]
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum OutputError {
    /// A file or folder could not be created, written or renamed.
    #[error("cannot write {path}: {source}", path = .path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },

    /// An output path that cannot be written as a file (a folder, a device, ...).
    #[error("cannot write {path}: {reason}", path = .path.display())]
    OutputPath { path: PathBuf, reason: String },

    /// Another run (process `holder`, when known) is writing this output now.
    #[error(
        "{path} is being written by another clatch run{by}; wait for it to end or choose another path \
         (lock file {lock})",
        path = .path.display(), lock = .lock.display(),
        by = .holder.map(|p| format!(" (process {p})")).unwrap_or_default()
    )]
    Locked {
        path: PathBuf,
        holder: Option<u32>,
        lock: PathBuf,
    },

    /// An output path that names an input or another output.
    #[error(
        "the {role} {path} is the same file as the {other_role} {other}; choose another path",
        path = .path.display(), other = .other.display()
    )]
    OutputClash {
        role: &'static str,
        path: PathBuf,
        other_role: &'static str,
        other: PathBuf,
    },
}

impl OutputError {
    /// Wraps an I/O error on `path`.
    pub fn write(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
        move |source| OutputError::Write {
            path: path.to_path_buf(),
            source,
        }
    }
}
