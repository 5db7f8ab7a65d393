//! What can go wrong while writing a COLMAP database or match list.

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

    /// More rows than a COLMAP blob (or its `rows` column) can describe.
    #[error("{what}: {count} rows is more than COLMAP can store")]
    TooMany { what: &'static str, count: usize },
}

impl ColmapError {
    /// Wraps an SQLite error with the operation that failed.
    pub(crate) fn sql(operation: &'static str) -> impl FnOnce(rusqlite::Error) -> ColmapError {
        move |source| ColmapError::Sqlite { operation, source }
    }
}
