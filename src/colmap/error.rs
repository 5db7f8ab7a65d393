//! What can go wrong while writing a COLMAP database or match list.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of [`crate::colmap`]. Each says which image, pair or SQL operation was involved.
// Field names are described by each variant's message.
#[allow(missing_docs)]
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ColmapError {
    /// An SQLite call failed.
    #[error("COLMAP database: {operation} failed: {source}")]
    Sqlite {
        operation: &'static str,
        source: rusqlite::Error,
    },

    /// The database file already exists (COLMAP would append to it and ids would no longer match).
    #[error("COLMAP database {path} already exists; remove it or choose another path")]
    DatabaseExists { path: String },

    /// [`crate::colmap::Database::open_existing`] of a path that is not a file.
    #[error("COLMAP database {path} does not exist")]
    DatabaseMissing { path: String },

    /// A two-view geometry that cannot be stored (a matrix not finite, a singular homography to turn
    /// round, a quaternion not of unit length).
    #[error("two-view geometry of pair ({image_id1}, {image_id2}): {reason}")]
    InvalidGeometry {
        image_id1: u32,
        image_id2: u32,
        reason: &'static str,
    },

    /// A camera whose size or intrinsics make no sense.
    #[error("invalid camera: {reason}")]
    InvalidCamera { reason: String },

    /// An image id that the database does not hold (ids come from [`crate::colmap::Database::add_image`]).
    #[error("image id {image_id} is not in the database")]
    UnknownImage { image_id: u32 },

    /// An image name that is empty, absolute or already used.
    #[error("invalid image name {name:?}: {reason}")]
    InvalidImageName { name: String, reason: &'static str },

    /// Matches between an image and itself.
    #[error("matches of image {image_id} with itself: a pair needs two different images")]
    SamePair { image_id: u32 },

    /// A match refers to a keypoint the image does not have.
    #[error(
        "match {index} of pair ({image_id1}, {image_id2}) refers to keypoint {keypoint} of image {image_id}, which has {keypoints}"
    )]
    MatchOutOfRange {
        index: usize,
        image_id1: u32,
        image_id2: u32,
        image_id: u32,
        keypoint: u32,
        keypoints: usize,
    },

    /// Keypoints of an image were written twice, or matches of a pair.
    #[error("{what} written twice")]
    Duplicate { what: String },

    /// Writing the match list failed.
    #[error("writing the COLMAP match list: {0}")]
    MatchListIo(std::io::Error),

    /// The image folder could not be listed.
    #[error("cannot list the image folder {path}: {source}", path = .path.display())]
    ImageDir {
        path: PathBuf,
        source: std::io::Error,
    },

    /// The image folder holds no image file.
    #[error("no image in {path} (looked for the extensions {extensions})", path = .path.display())]
    NoImages { path: PathBuf, extensions: String },

    /// A file name COLMAP cannot take (not UTF-8, or with whitespace, which its match list cannot hold).
    #[error("{path}: {reason}; rename the file", path = .path.display())]
    ImageName { path: PathBuf, reason: &'static str },

    /// An image too small for the detector to score a single pixel.
    #[error(
        "{path} is {width}x{height}: keypoints are detected at least {margin} pixels from every border, \
         so an image needs at least {min}x{min} pixels",
        path = .path.display()
    )]
    ImageTooSmall {
        path: PathBuf,
        width: u32,
        height: u32,
        margin: usize,
        min: usize,
    },

    /// Images of different sizes with one given camera matrix.
    #[error(
        "{path} is {got_w}x{got_h} but the first image is {want_w}x{want_h}: one camera matrix needs one image size",
        path = .path.display()
    )]
    ImageSizeMismatch {
        path: PathBuf,
        got_w: u32,
        got_h: u32,
        want_w: u32,
        want_h: u32,
    },

    /// An image file that could not be read or decoded.
    #[error("{0}")]
    Decode(#[from] crate::decode::DecodeError),

    /// A library error about one image (its size, its extraction).
    #[error("{path}: {source}", path = .path.display())]
    Image { path: PathBuf, source: crate::Error },

    /// A library error with no image attached (a batch extraction, the backend).
    #[error("{0}")]
    Clatch(#[from] crate::Error),

    /// Matches of a pair whose image index is not one of the photos written.
    #[error("pair ({i}, {j}) of {photos} photos: {reason}")]
    BadPair {
        i: usize,
        j: usize,
        photos: usize,
        reason: &'static str,
    },

    /// More rows than a COLMAP blob (or its `rows` column) can describe.
    #[error("{what}: {count} rows is more than COLMAP can store")]
    TooMany { what: &'static str, count: usize },

    /// An output of the run refused (a folder, an input's path) or not written.
    #[error("{0}")]
    Output(#[from] crate::output::OutputError),

    /// A given pair names a photo index the folder does not have.
    #[error("pair {position}: index {index} is not one of the {photos} photos")]
    PairOutOfRange {
        position: usize,
        index: usize,
        photos: usize,
    },

    /// A given pair names a photo by a name the folder does not have.
    #[error("pair {position}: {name:?} is not an image of the folder")]
    PairNameUnknown { position: usize, name: String },

    /// A given pair of a photo with itself.
    #[error("pair {position}: {name} with itself; a pair needs two different photos")]
    PairOfOnePhoto { position: usize, name: String },

    /// A given pair listed again (in either order).
    #[error("pair {position}: {first} and {second} are pair {earlier} again; list each pair once")]
    DuplicatePair {
        position: usize,
        earlier: usize,
        first: String,
        second: String,
    },

    /// A pair to match whose photo's descriptors were not given.
    #[error("pair {position}: no descriptors of photo {image} were given")]
    MissingDescriptors { position: usize, image: usize },

    /// The progress callback asked the run to stop; nothing was written.
    #[error("stopped by the progress callback while {stage}")]
    Stopped { stage: crate::colmap::FolderStage },
}

impl ColmapError {
    /// Wraps an SQLite error with the operation that failed.
    pub(crate) fn sql(operation: &'static str) -> impl FnOnce(rusqlite::Error) -> ColmapError {
        move |source| ColmapError::Sqlite { operation, source }
    }
}
