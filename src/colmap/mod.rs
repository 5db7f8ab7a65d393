//! Handing keypoints and matches to [COLMAP](https://colmap.github.io) 3.8 for structure from motion
//! (feature `colmap`, which turns on `image`).
//!
//! A folder of photos goes to COLMAP through one function, [`FolderJob::run`]: the command-line
//! tool's `clatch colmap`, the Python package's `clatch.colmap.match_folder` and its Ray driver
//! `clatch.ray` all call it or its stages, so they write the same bytes. Its stages:
//! - [`FolderJob::plan`]: every check before any work ([`FolderPlan`]: the settings, [`ImageFolder`]
//!   (which files, their names and sizes), the camera, the pairs ([`resolve_pairs`]), the outputs);
//! - [`FolderPlan::run`]: [`extract_photos`] (features with the positions refined by a
//!   [`Refinement`]), [`match_photo_pairs`] (any subset of the pairs, wherever their photos'
//!   descriptors are) and [`FolderOutput`] (every pair verified, by default, and the one
//!   [`FolderWriter`] of the database and, if any, the match list, in one order, under temporary
//!   names);
//! - [`WrittenFolder::commit`]: both files renamed into place, only once both are complete.
//!
//! ```no_run
//! use clatch::colmap::FolderJob;
//!
//! let report = FolderJob::new("photos/", "out.db").run(None)?;
//! println!("{} photos, {} pairs", report.counts.photos, report.counts.pairs);
//! # Ok::<(), clatch::colmap::ColmapError>(())
//! ```
//!
//! COLMAP cannot match binary descriptors and needs none: it gets keypoints in its SQLite database
//! ([`Database`]) and either the verified matches, as its own matcher writes them (`matches` and
//! `two_view_geometries`, the only match table its `mapper` reads: [`Database::add_matches`] and
//! [`Database::add_two_view_geometry`] of a [`TwoViewGeometry`], into a new database or one opened by
//! [`Database::open_existing`]; the folder run's default, [`crate::verify`]), or putative matches
//! as a text file ([`MatchList`]) that `colmap matches_importer --match_type raw` reads, verifies
//! geometrically and stores in both tables ([`FolderJob::without_verification`]).
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
mod folder_output;
mod job;
mod match_list;
mod pairs;
mod plan;
mod report;
mod run;
pub mod schema;
pub mod two_view;
mod writer;

pub use camera::{
    DEFAULT_FOCAL_FACTOR, MAX_FOCAL_RATIO, MIN_FOCAL_RATIO, PINHOLE_MODEL_ID, PinholeCamera,
};
pub use corner::{Refinement, refine_corners};
pub use database::{Database, check_match_indices};
pub use error::ColmapError;
pub use folder::{
    DEFAULT_GRID, DEFAULT_MAX_KEYPOINTS, IMAGE_EXTENSIONS, ImageFolder, Photo, check_detectable,
    extract_each_photo, extract_photo, extract_photos, image_name, list_images, photo_camera,
    skipped_entries,
};
pub use folder_output::{FolderOutput, WrittenFolder};
pub use job::{FolderCamera, FolderJob, MATCH_LIST_NAME, Overwrite, default_workspace};
pub use match_list::MatchList;
pub use pairs::{PhotoRef, match_photo_pairs, resolve_pairs};
pub use plan::FolderPlan;
pub use report::{FolderProgress, FolderReport, FolderStage, FolderTimes};
pub use two_view::{Matrix3, RelativePose, TwoViewGeometry};
pub use writer::{FolderCounts, FolderWriter};

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
