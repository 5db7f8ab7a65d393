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

    /// An image file that was refused before or while decoding (size from its header, not a regular
    /// file, truncated, corrupt).
    #[error("{0}")]
    Decode(#[from] clatch::decode::DecodeError),

    /// The embedded photo could not be decoded (a broken build).
    #[error("cannot decode the embedded image {name}: {source}")]
    Embedded {
        name: &'static str,
        source: image::ImageError,
    },

    /// An input that is a folder, FIFO, device or socket: reading it could block or never end.
    #[error("{path}: not a regular file ({kind})", path = .path.display())]
    NotAFile { path: PathBuf, kind: &'static str },

    /// A text input (homography, camera matrix) larger than any such file can be.
    #[error("{path}: more than {max} bytes; not a {what} file", path = .path.display())]
    TextTooLarge {
        path: PathBuf,
        max: u64,
        what: &'static str,
    },

    /// An output refused before any work (a folder, an input's path) or not written: the library's
    /// rules for every file the tool writes ([`clatch::output`]).
    #[error("{0}")]
    Output(#[from] clatch::output::OutputError),

    /// An output path that cannot be written as a file (a folder, a device, ...).
    #[error("cannot write {path}: {reason}", path = .path.display())]
    OutputPath { path: PathBuf, reason: String },

    /// An output picture path whose extension names no format this build can write.
    #[error("cannot save a picture as {path}: {reason}", path = .path.display())]
    PictureFormat { path: PathBuf, reason: String },

    /// A camera matrix file that is not a pinhole K.
    #[error("bad camera matrix file {path}: {source}", path = .path.display())]
    CameraK {
        path: PathBuf,
        source: clatch::colmap::ColmapError,
    },

    /// Writing the COLMAP database or match list failed.
    #[error("{0}")]
    Colmap(#[from] clatch::colmap::ColmapError),

    /// The workspace already holds COLMAP models from an earlier run.
    #[error("{path} already holds COLMAP models; use --force to replace them or choose another --workspace", path = .path.display())]
    ModelsExist { path: PathBuf },

    /// The workspace's model folder holds something clatch did not put there; clatch never replaces it.
    #[error(
        "{folder} holds {entry}, which clatch did not write: clatch replaces only the COLMAP models it \
         installed there itself; move it or choose another --workspace",
        folder = .folder.display()
    )]
    ForeignInWorkspace { folder: PathBuf, entry: String },

    /// The images folder is where clatch writes its outputs.
    #[error(
        "the images folder {images} is {what}, where clatch writes; move the photos or choose another --workspace",
        images = .images.display()
    )]
    ImagesInWorkspace { images: PathBuf, what: &'static str },

    /// The `colmap` program could not be started.
    #[error("cannot run {program} ({step}): {source}", program = .program.display())]
    ColmapStart {
        program: PathBuf,
        step: &'static str,
        source: std::io::Error,
    },

    /// A `colmap` step failed; the tail of its output says why.
    #[error("colmap {step} failed ({status}); full log {log}; last lines:\n{tail}", log = .log.display())]
    ColmapFailed {
        step: &'static str,
        status: String,
        log: PathBuf,
        tail: String,
    },

    /// A COLMAP step failed after the database (and match list) were complete: both were kept.
    #[error(
        "{error}\n{kept} (every photo's features and the matches); COLMAP can run on them again \
         without extracting:\n{commands}",
        kept = kept_files(database, match_list.as_deref())
    )]
    ColmapFailedKept {
        error: Box<CliError>,
        database: PathBuf,
        match_list: Option<PathBuf>,
        commands: String,
    },

    /// A --mapper-option refused before any work.
    #[error("--mapper-option {option}: {reason}")]
    MapperOption { option: String, reason: String },

    /// Fewer photos than COLMAP's mapper can build a model from.
    #[error(
        "{images} holds {photos} photo(s): COLMAP's mapper needs at least 2; use --no-colmap to write \
         only the database",
        images = .images.display()
    )]
    TooFewPhotos { images: PathBuf, photos: usize },

    /// A `colmap` step ran past --colmap-timeout and was killed.
    #[error(
        "colmap {step} still ran after {seconds} s (--colmap-timeout) and was stopped; its output so far: {log}",
        log = .log.display()
    )]
    ColmapTimeout {
        step: &'static str,
        seconds: u64,
        log: PathBuf,
    },

    /// `colmap model_analyzer` printed no figure where one was expected.
    #[error("cannot read `{field}` from colmap model_analyzer's output for {model}; it printed:\n{output}", model = .model.display())]
    ModelAnalyzer {
        field: &'static str,
        model: PathBuf,
        output: String,
    },

    /// A homography file that is not nine finite numbers forming an invertible matrix.
    #[error("bad homography file {path}: {reason}", path = .path.display())]
    Homography { path: PathBuf, reason: String },

    /// Some images of a batch failed (each listed on stderr); the others' files were written.
    #[error(
        "{failed} of {total} images failed (listed above, the first {first}); the others' files were \
         written; --fail-fast stops at the first and writes none",
        first = .first.display()
    )]
    ImagesFailed {
        failed: usize,
        total: usize,
        first: PathBuf,
    },

    /// Options that cannot be given together.
    #[error("{options}: {reason}")]
    OptionConflict { options: String, reason: String },
}

impl CliError {
    /// Attaches an image's path to a library error.
    pub fn in_image(path: &Path) -> impl FnOnce(clatch::Error) -> CliError + '_ {
        move |source| CliError::ClatchImage {
            path: path.to_path_buf(),
            source,
        }
    }

    /// Wraps a read error on `path`.
    pub fn read(path: &Path) -> impl FnOnce(std::io::Error) -> CliError + '_ {
        move |source| CliError::Read {
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

/// "the database X (and the match list Y) are kept".
fn kept_files(database: &std::path::Path, match_list: Option<&std::path::Path>) -> String {
    match match_list {
        Some(list) => format!(
            "the database {} and the match list {} are kept",
            database.display(),
            list.display()
        ),
        None => format!("the database {} is kept", database.display()),
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
