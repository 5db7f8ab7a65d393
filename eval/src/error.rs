//! The harness's error type: every failure says what went wrong and with which file.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// Everything that can stop an evaluation.
#[derive(Debug, Error)]
pub enum EvalError {
    /// A library error with no particular file attached (configuration, backend).
    #[error("{0}")]
    Clatch(#[from] clatch::Error),

    /// A library error about one input image.
    #[error("{path}: {source}", path = .path.display())]
    Image {
        path: PathBuf,
        source: clatch::Error,
    },

    /// An image file that was refused before or while decoding.
    #[error("{0}")]
    Decode(#[from] clatch::decode::DecodeError),

    /// The embedded photo could not be decoded (a broken build).
    #[error("cannot decode the embedded photo: {0}")]
    Embedded(image::ImageError),

    /// A file or folder could not be read, or a file created or written.
    #[error("cannot {access} {path}: {source}", path = .path.display())]
    File {
        access: Access,
        path: PathBuf,
        source: std::io::Error,
    },

    /// An image could not be encoded.
    #[error("cannot encode image {path}: {source}", path = .path.display())]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },

    /// A homography file that is not nine finite numbers forming an invertible matrix.
    #[error("bad homography file {path}: {reason}", path = .path.display())]
    Homography { path: PathBuf, reason: String },

    /// An input that is missing or incomplete (a sequence folder without its images, ...).
    #[error("evaluation input {path}: {reason}", path = .path.display())]
    Input { path: PathBuf, reason: String },

    /// A merged result that does not describe the pair it names (another image size).
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
        line: u64,
        reason: String,
    },

    /// The OpenCV script could not be found, could not run or failed.
    #[error("{command} failed: {reason}")]
    Script { command: String, reason: String },

    /// Options that cannot be given together.
    #[error("{options}: {reason}")]
    OptionConflict { options: String, reason: String },

    /// A chart could not be drawn.
    #[error("cannot draw chart {path}: {reason}", path = .path.display())]
    Chart { path: PathBuf, reason: String },
}

/// What was being done with a file when it failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    Read,
    Write,
}

impl std::fmt::Display for Access {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Access::Read => "read",
            Access::Write => "write",
        })
    }
}

/// Names the file an I/O failure concerns.
pub trait IoContext<T> {
    /// The error of reading `path`.
    fn reading(self, path: &Path) -> Result<T, EvalError>;
    /// The error of writing `path`.
    fn writing(self, path: &Path) -> Result<T, EvalError>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn reading(self, path: &Path) -> Result<T, EvalError> {
        self.map_err(|source| EvalError::File {
            access: Access::Read,
            path: path.to_path_buf(),
            source,
        })
    }

    fn writing(self, path: &Path) -> Result<T, EvalError> {
        self.map_err(|source| EvalError::File {
            access: Access::Write,
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Names the image a library failure concerns.
pub trait ImageContext<T> {
    /// The library's error about the image at `path`.
    fn in_image(self, path: &Path) -> Result<T, EvalError>;
}

impl<T> ImageContext<T> for clatch::Result<T> {
    fn in_image(self, path: &Path) -> Result<T, EvalError> {
        self.map_err(|source| EvalError::Image {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Writes `bytes` to `path`, replacing what was there.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), EvalError> {
    std::fs::write(path, bytes).writing(path)
}
