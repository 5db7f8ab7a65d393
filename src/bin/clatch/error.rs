//! The command-line tool's error type: every failure says what went wrong and with which file.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// Everything that can stop a `clatch` command.
#[derive(Debug, Error)]
pub enum CliError {
    /// A library error with no particular file attached (configuration, backend).
    #[error("{0}")]
    Clatch(#[from] clatch::Error),

    /// A library error about one input image.
    #[error("{path}: {source}", path = .path.display())]
    ClatchImage {
        path: PathBuf,
        source: clatch::Error,
    },

    /// A file could not be opened or read.
    #[error("cannot read {path}: {source}", path = .path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },

    /// A file could not be created or written.
    #[error("cannot write {path}: {source}", path = .path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },

    /// An image file could not be decoded.
    #[error("cannot decode image {path}: {source}", path = .path.display())]
    Decode {
        path: PathBuf,
        source: image::ImageError,
    },

    /// An image could not be encoded or saved.
    #[error("cannot save image {path}: {source}", path = .path.display())]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },

    /// An output picture path whose extension names no format this build can write.
    #[error("cannot save a picture as {path}: {reason}", path = .path.display())]
    PictureFormat { path: PathBuf, reason: String },

    /// A homography file that is not nine finite numbers forming an invertible matrix.
    #[error("bad homography file {path}: {reason}", path = .path.display())]
    Homography { path: PathBuf, reason: String },

    /// An evaluation input that is missing or incomplete (a sequence folder without its images, ...).
    #[error("evaluation input {path}: {reason}", path = .path.display())]
    EvalInput { path: PathBuf, reason: String },

    /// Two things that must have the same size do not (a warp and its source, a merged result and
    /// the pair it claims to describe).
    #[error("size mismatch for {what}: expected {expected}, found {found}")]
    SizeMismatch {
        what: String,
        expected: String,
        found: String,
    },

    /// A results file (CSV) from another tool that cannot be read as evaluation results.
    #[error("bad results file {path}, line {line}: {reason}", path = .path.display())]
    ResultsFormat {
        path: PathBuf,
        line: usize,
        reason: String,
    },

    /// An external script (the OpenCV evaluation) could not run or failed.
    #[error("{command} failed: {reason}")]
    Script { command: String, reason: String },

    /// A chart could not be drawn.
    #[error("cannot draw chart {path}: {reason}", path = .path.display())]
    Chart { path: PathBuf, reason: String },
}

impl CliError {
    /// Attaches an image's path to a library error.
    pub fn in_image(path: &Path) -> impl FnOnce(clatch::Error) -> CliError + '_ {
        move |source| CliError::ClatchImage {
            path: path.to_path_buf(),
            source,
        }
    }

    /// Wraps a write error on `path`.
    pub fn write(path: &Path) -> impl FnOnce(std::io::Error) -> CliError + '_ {
        move |source| CliError::Write {
            path: path.to_path_buf(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_file() {
        let e = CliError::in_image(Path::new("tiny.png"))(clatch::Error::ImageTooSmall {
            width: 10,
            height: 10,
            min: 64,
        });
        let text = e.to_string();
        assert!(text.starts_with("tiny.png: "), "{text}");
        assert!(text.contains("64x64"), "{text}");
        let e = CliError::Read {
            path: "missing.png".into(),
            source: std::io::Error::from(std::io::ErrorKind::NotFound),
        };
        assert!(e.to_string().contains("missing.png"));
    }
}
