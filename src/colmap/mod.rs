//! Handing keypoints and matches to [COLMAP](https://colmap.github.io) 3.8 for structure from motion
//! (feature `colmap`, which turns on `image`).
//!
//! A folder of photos goes through [`ImageFolder`] (which files, their names and sizes, checked before
//! any work), [`extract_photos`] (features with the positions refined by a [`Refinement`]),
//! [`crate::Matcher::match_pairs`] and [`FolderWriter`] (the database and the match list, in one
//! order): the command-line tool's `clatch colmap` and the Python package's `clatch.colmap` and
//! `clatch.ray` all take this path, so they write the same bytes.
//!
//! COLMAP cannot match binary descriptors and needs none: it gets keypoints in its SQLite database
//! ([`Database`]) and putative matches as a text file ([`MatchList`]) that
//! `colmap matches_importer --match_type raw` reads, verifies geometrically and stores in
//! `two_view_geometries`, the only match table its `mapper` reads.
//!
//! **Target: COLMAP 3.8** (Debian 12's), whose schema is [`schema::SCHEMA_3_8`]. Conventions, from
//! COLMAP 3.8's source and checked by running it:
//! - keypoint coordinates put the centre of the first pixel at (0.5, 0.5), so 0.5 is added to clatch's
//!   (whose pixel centres are integers);
//! - orientations are in radians (clatch's [`KeyPoint::angle`] is in degrees);
//! - the pair `(a, b)` has id `2147483647 · min(a, b) + max(a, b)` ([`pair_id`]), and its matches blob
//!   lists `(index in min image, index in max image)`;
//! - blobs are raw little-endian arrays, with their `rows` and `cols` in the row.
//!
//! ```
//! use clatch::colmap::{pair_id, image_ids_of_pair};
//! assert_eq!(pair_id(3, 1), 2147483647 + 3);
//! assert_eq!(image_ids_of_pair(pair_id(7, 2)), (2, 7));
//! ```

mod camera;
mod corner;
mod database;
mod error;
pub mod exif;
mod folder;
mod match_list;
pub mod schema;
mod writer;

pub use camera::{DEFAULT_FOCAL_FACTOR, PINHOLE_MODEL_ID, PinholeCamera};
pub use corner::{Refinement, refine_corners};
pub use database::{Database, check_match_indices};
pub use error::ColmapError;
pub use folder::{
    DEFAULT_GRID, DEFAULT_MAX_KEYPOINTS, IMAGE_EXTENSIONS, ImageFolder, Photo, check_detectable,
    extract_photo, extract_photos, image_name, list_images, photo_camera,
};
pub use match_list::MatchList;
pub use writer::FolderWriter;

use crate::keypoint::KeyPoint;
use crate::matching::Match;
use schema::MAX_IMAGE_ID;

/// COLMAP's id of the unordered pair of two images.
pub fn pair_id(image_id1: u32, image_id2: u32) -> u64 {
    let (lo, hi) = (image_id1.min(image_id2), image_id1.max(image_id2));
    u64::from(MAX_IMAGE_ID) * u64::from(lo) + u64::from(hi)
}

/// The two image ids of a [`pair_id`], smaller first.
pub fn image_ids_of_pair(pair_id: u64) -> (u32, u32) {
    let hi = pair_id % u64::from(MAX_IMAGE_ID);
    let lo = (pair_id - hi) / u64::from(MAX_IMAGE_ID);
    (lo as u32, hi as u32)
}

/// COLMAP's 4-column keypoint blob: float32 `x + 0.5, y + 0.5, scale, orientation` per keypoint, with
/// `scale` half the keypoint's window side (the radius of the described patch) and `orientation`
/// [`KeyPoint::angle`] in radians (both measured from +x towards +y, the image's down direction).
pub fn keypoints_blob(keypoints: &[KeyPoint]) -> Vec<u8> {
    keypoints
        .iter()
        .flat_map(|k| [k.x + 0.5, k.y + 0.5, k.size / 2.0, k.angle.to_radians()])
        .flat_map(f32::to_le_bytes)
        .collect()
}

/// COLMAP's 2-column matches blob of the pair `(image_id1, image_id2)`: uint32 pairs
/// `(index in the smaller id's image, index in the larger id's image)`, where `query` indexes
/// `image_id1` and `train` `image_id2`.
pub fn matches_blob(image_id1: u32, image_id2: u32, matches: &[Match]) -> Vec<u8> {
    let swap = image_id1 > image_id2;
    matches
        .iter()
        .flat_map(|m| {
            if swap {
                [m.train, m.query]
            } else {
                [m.query, m.train]
            }
        })
        .flat_map(u32::to_le_bytes)
        .collect()
}
