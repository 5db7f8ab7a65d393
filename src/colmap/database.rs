//! Writing cameras, images, keypoints and matches into a new COLMAP 3.8 database.

use std::collections::HashMap;
use std::path::Path;

use rusqlite::{Connection, params};

use crate::colmap::camera::{PINHOLE_MODEL_ID, PinholeCamera};
use crate::colmap::error::ColmapError;
use crate::colmap::schema::SCHEMA_3_8;
use crate::colmap::two_view::{TwoViewBlobs, TwoViewGeometry};
use crate::colmap::{keypoints_blob, matches_blob, pair_id};
use crate::keypoint::KeyPoint;
use crate::matching::Match;

/// A new COLMAP 3.8 database being written. Everything goes into one transaction, committed by
/// [`Database::finish`]; a database dropped before that keeps its tables but none of the rows.
///
/// ```
/// use clatch::colmap::{Database, PinholeCamera};
/// use clatch::{KeyPoint, Match};
///
/// let path = std::env::temp_dir().join(format!("clatch-doc-{}.db", std::process::id()));
/// # std::fs::remove_file(&path).ok();
/// let mut db = Database::create(&path)?;
/// let camera = db.add_camera(&PinholeCamera::guess(640, 480)?)?;
/// let a = db.add_image("a.png", camera)?;
/// let b = db.add_image("b.png", camera)?;
/// db.set_keypoints(a, &[KeyPoint::new(10.0, 20.0), KeyPoint::new(30.0, 40.0)])?;
/// db.set_keypoints(b, &[KeyPoint::new(11.0, 21.0)])?;
/// db.add_matches(a, b, &[Match { query: 1, train: 0, distance: 12 }])?;
/// db.finish()?;
/// # std::fs::remove_file(&path).ok();
/// # Ok::<(), clatch::colmap::ColmapError>(())
/// ```
pub struct Database {
    connection: Connection,
    /// Keypoint count of every image, 0 until its keypoints are written.
    keypoints: HashMap<u32, Option<usize>>,
    pairs: std::collections::HashSet<u64>,
    /// Pairs of `two_view_geometries`, written now or found by [`Database::open_existing`].
    verified_pairs: std::collections::HashSet<u64>,
}

impl Database {
    /// Creates the file with COLMAP 3.8's tables. An existing file is an error, never overwritten.
    pub fn create(path: &Path) -> Result<Self, ColmapError> {
        if path.exists() {
            return Err(ColmapError::DatabaseExists {
                path: path.display().to_string(),
            });
        }
        let connection = Connection::open(path).map_err(ColmapError::sql("opening the file"))?;
        connection
            .execute_batch(SCHEMA_3_8)
            .map_err(ColmapError::sql("creating the COLMAP 3.8 tables"))?;
        connection
            .execute_batch("BEGIN")
            .map_err(ColmapError::sql("starting the transaction"))?;
        Ok(Self {
            connection,
            keypoints: HashMap::new(),
            pairs: Default::default(),
            verified_pairs: Default::default(),
        })
    }

    /// Opens a COLMAP 3.8 database written before (by [`Database::create`], `clatch colmap` or
    /// COLMAP), to add rows to it: typically [`Database::add_two_view_geometry`] for pairs verified
    /// outside COLMAP. Its images, keypoint counts and pairs are read first, so indices and
    /// duplicates are checked as for a new database. Nothing is changed until [`Database::finish`].
    pub fn open_existing(path: &Path) -> Result<Self, ColmapError> {
        if !path.is_file() {
            return Err(ColmapError::DatabaseMissing {
                path: path.display().to_string(),
            });
        }
        let connection = Connection::open_with_flags(
            path,
            rusqlite::OpenFlags::SQLITE_OPEN_READ_WRITE | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(ColmapError::sql("opening the file"))?;
        let read_ids =
            |sql: &str, operation: &'static str| -> Result<Vec<(i64, i64)>, ColmapError> {
                let mut statement = connection
                    .prepare(sql)
                    .map_err(ColmapError::sql(operation))?;
                let rows = statement
                    .query_map([], |row| Ok((row.get(0)?, row.get(1)?)))
                    .map_err(ColmapError::sql(operation))?;
                rows.collect::<Result<_, _>>()
                    .map_err(ColmapError::sql(operation))
            };
        let mut keypoints: HashMap<u32, Option<usize>> = HashMap::new();
        for (image_id, _) in read_ids("SELECT image_id, 0 FROM images", "reading the images")? {
            keypoints.insert(image_id as u32, None);
        }
        let counts = read_ids(
            "SELECT image_id, rows FROM keypoints",
            "reading the keypoint counts",
        )?;
        for (image_id, rows) in counts {
            keypoints.insert(image_id as u32, Some(rows as usize));
        }
        let pair_ids = |table: &str, operation| {
            read_ids(&format!("SELECT pair_id, 0 FROM {table}"), operation)
                .map(|rows| rows.into_iter().map(|(id, _)| id as u64).collect())
        };
        let pairs = pair_ids("matches", "reading the matched pairs")?;
        let verified_pairs = pair_ids("two_view_geometries", "reading the verified pairs")?;
        connection
            .execute_batch("BEGIN")
            .map_err(ColmapError::sql("starting the transaction"))?;
        Ok(Self {
            connection,
            keypoints,
            pairs,
            verified_pairs,
        })
    }

    /// Adds a camera; returns its `camera_id` (from 1).
    pub fn add_camera(&mut self, camera: &PinholeCamera) -> Result<u32, ColmapError> {
        let camera = camera.validated()?;
        self.connection
            .execute(
                "INSERT INTO cameras (model, width, height, params, prior_focal_length) \
                 VALUES (?1, ?2, ?3, ?4, ?5)",
                params![
                    PINHOLE_MODEL_ID,
                    camera.width,
                    camera.height,
                    camera.params_blob(),
                    i64::from(camera.focal_is_known)
                ],
            )
            .map_err(ColmapError::sql("inserting a camera"))?;
        self.last_id("reading the new camera id")
    }

    /// Adds an image seen by `camera_id`; `name` is its path relative to the folder that COLMAP will
    /// be given as `--image_path`. Returns its `image_id` (from 1).
    pub fn add_image(&mut self, name: &str, camera_id: u32) -> Result<u32, ColmapError> {
        let bad = |reason| ColmapError::InvalidImageName {
            name: name.into(),
            reason,
        };
        if name.is_empty() {
            return Err(bad("it is empty"));
        }
        if name.starts_with('/') {
            return Err(bad("it must be relative to the image folder"));
        }
        let taken: bool = self
            .connection
            .query_row(
                "SELECT EXISTS(SELECT 1 FROM images WHERE name = ?1)",
                [name],
                |row| row.get(0),
            )
            .map_err(ColmapError::sql("looking up an image name"))?;
        if taken {
            return Err(bad("another image has this name"));
        }
        self.connection
            .execute(
                "INSERT INTO images (name, camera_id) VALUES (?1, ?2)",
                params![name, camera_id],
            )
            .map_err(ColmapError::sql("inserting an image"))?;
        let id = self.last_id("reading the new image id")?;
        self.keypoints.insert(id, None);
        Ok(id)
    }

    /// Writes the keypoints of `image_id` (see [`keypoints_blob`] for the conversion to COLMAP's
    /// conventions). Keypoint `i` is the one that match indices `i` refer to.
    pub fn set_keypoints(
        &mut self,
        image_id: u32,
        keypoints: &[KeyPoint],
    ) -> Result<(), ColmapError> {
        let entry = self
            .keypoints
            .get_mut(&image_id)
            .ok_or(ColmapError::UnknownImage { image_id })?;
        if entry.is_some() {
            return Err(ColmapError::Duplicate {
                what: format!("keypoints of image {image_id}"),
            });
        }
        let rows = i64::try_from(keypoints.len()).map_err(|_| ColmapError::TooMany {
            what: "keypoints",
            count: keypoints.len(),
        })?;
        self.connection
            .execute(
                "INSERT INTO keypoints (image_id, rows, cols, data) VALUES (?1, ?2, 4, ?3)",
                params![image_id, rows, keypoints_blob(keypoints)],
            )
            .map_err(ColmapError::sql("inserting keypoints"))?;
        *entry = Some(keypoints.len());
        Ok(())
    }

    fn keypoint_count(&self, image_id: u32) -> Result<usize, ColmapError> {
        match self.keypoints.get(&image_id) {
            Some(Some(n)) => Ok(*n),
            _ => Err(ColmapError::UnknownImage { image_id }),
        }
    }

    /// Writes putative matches between two images into the `matches` table: `query` indexes the
    /// keypoints of `image_id1`, `train` those of `image_id2`. Both images' keypoints must be written
    /// first; every index is checked against them. The blob is stored in COLMAP's order (the smaller
    /// image id's column first), swapping columns when `image_id1 > image_id2`; a pair without
    /// matches has `rows` 0 and NULL `data`, as COLMAP 3.8 binds an empty matrix.
    ///
    /// COLMAP's mapper reads only verified matches (`two_view_geometries`,
    /// [`Database::add_two_view_geometry`]); COLMAP's own matcher writes both tables for every pair.
    /// Pairs that COLMAP should verify go to `colmap matches_importer` through a
    /// [`crate::colmap::MatchList`] instead, and not here: it writes this table itself.
    pub fn add_matches(
        &mut self,
        image_id1: u32,
        image_id2: u32,
        matches: &[Match],
    ) -> Result<(), ColmapError> {
        if image_id1 == image_id2 {
            return Err(ColmapError::SamePair {
                image_id: image_id1,
            });
        }
        let (n1, n2) = (
            self.keypoint_count(image_id1)?,
            self.keypoint_count(image_id2)?,
        );
        check_match_indices(image_id1, image_id2, matches, n1, n2)?;
        let pair = pair_id(image_id1, image_id2);
        if !self.pairs.insert(pair) {
            return Err(ColmapError::Duplicate {
                what: format!("matches of pair ({image_id1}, {image_id2})"),
            });
        }
        self.connection
            .execute(
                "INSERT INTO matches (pair_id, rows, cols, data) VALUES (?1, ?2, 2, ?3)",
                params![
                    pair as i64,
                    matches.len() as i64,
                    (!matches.is_empty()).then(|| matches_blob(image_id1, image_id2, matches))
                ],
            )
            .map_err(ColmapError::sql("inserting matches"))?;
        Ok(())
    }

    /// Writes the verified geometry of a pair into `two_view_geometries`, the table COLMAP's `mapper`
    /// reads, so that it can run without `matches_importer`. The pair may be given in either order
    /// ([`TwoViewGeometry::in_colmap_order`] turns it round as COLMAP does); both images' keypoints
    /// must be in the database, every inlier index is checked against them, and a pair can be
    /// written once. See [`crate::colmap::two_view`] for the layout.
    ///
    /// ```
    /// use clatch::colmap::{Database, PinholeCamera, TwoViewGeometry};
    /// use clatch::verify::GeometryConfig;
    /// use clatch::KeyPoint;
    ///
    /// let path = std::env::temp_dir().join(format!("clatch-doc-tvg-{}.db", std::process::id()));
    /// # std::fs::remove_file(&path).ok();
    /// let mut db = Database::create(&path)?;
    /// let camera = db.add_camera(&PinholeCamera::guess(640, 480)?)?;
    /// let a = db.add_image("a.png", camera)?;
    /// let b = db.add_image("b.png", camera)?;
    /// db.set_keypoints(a, &[KeyPoint::new(10.0, 20.0), KeyPoint::new(30.0, 40.0)])?;
    /// db.set_keypoints(b, &[KeyPoint::new(11.0, 21.0)])?;
    /// let verified = TwoViewGeometry {
    ///     f: Some([[0.0, -1e-4, 0.01], [1e-4, 0.0, -0.02], [-0.01, 0.02, 1.0]]),
    ///     ..TwoViewGeometry::new(b, a, vec![[0, 1]], GeometryConfig::Uncalibrated)
    /// };
    /// db.add_two_view_geometry(&verified)?;
    /// db.finish()?;
    /// # std::fs::remove_file(&path).ok();
    /// # Ok::<(), clatch::colmap::ColmapError>(())
    /// ```
    pub fn add_two_view_geometry(&mut self, geometry: &TwoViewGeometry) -> Result<(), ColmapError> {
        geometry.check()?;
        let (image_id1, image_id2) = (geometry.image_id1, geometry.image_id2);
        let (n1, n2) = (
            self.keypoint_count(image_id1)?,
            self.keypoint_count(image_id2)?,
        );
        let pairs = geometry.inliers.iter().map(|&[k1, k2]| (k1, k2));
        check_index_pairs(image_id1, image_id2, pairs, n1, n2)?;
        let rows = i64::try_from(geometry.inliers.len()).map_err(|_| ColmapError::TooMany {
            what: "inlier matches",
            count: geometry.inliers.len(),
        })?;
        let pair = geometry.pair_id();
        if self.verified_pairs.contains(&pair) {
            return Err(ColmapError::Duplicate {
                what: format!("two-view geometry of pair ({image_id1}, {image_id2})"),
            });
        }
        let blobs = TwoViewBlobs::of(&geometry.in_colmap_order()?);
        self.connection
            .execute(
                "INSERT INTO two_view_geometries (pair_id, rows, cols, data, config, F, E, H, qvec, tvec) \
                 VALUES (?1, ?2, 2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
                params![
                    pair as i64,
                    rows,
                    blobs.inliers,
                    i64::from(geometry.config.colmap_code()),
                    blobs.f,
                    blobs.e,
                    blobs.h,
                    blobs.qvec,
                    blobs.tvec
                ],
            )
            .map_err(ColmapError::sql("inserting a two-view geometry"))?;
        self.verified_pairs.insert(pair);
        Ok(())
    }

    /// Commits everything written.
    pub fn finish(self) -> Result<(), ColmapError> {
        self.connection
            .execute_batch("COMMIT")
            .map_err(ColmapError::sql("committing"))
    }

    fn last_id(&self, operation: &'static str) -> Result<u32, ColmapError> {
        u32::try_from(self.connection.last_insert_rowid()).map_err(|_| ColmapError::TooMany {
            what: operation,
            count: self.connection.last_insert_rowid() as usize,
        })
    }
}

/// Checks that every match index is a keypoint of its image (`n1` keypoints in image 1, `n2` in 2).
pub fn check_match_indices(
    image_id1: u32,
    image_id2: u32,
    matches: &[Match],
    n1: usize,
    n2: usize,
) -> Result<(), ColmapError> {
    let pairs = matches.iter().map(|m| (m.query, m.train));
    check_index_pairs(image_id1, image_id2, pairs, n1, n2)
}

/// Checks index pairs `(keypoint of image 1, keypoint of image 2)` against the keypoint counts.
fn check_index_pairs(
    image_id1: u32,
    image_id2: u32,
    pairs: impl Iterator<Item = (u32, u32)>,
    n1: usize,
    n2: usize,
) -> Result<(), ColmapError> {
    for (index, (k1, k2)) in pairs.enumerate() {
        for (image_id, keypoint, keypoints) in [(image_id1, k1, n1), (image_id2, k2, n2)] {
            if keypoint as usize >= keypoints {
                return Err(ColmapError::MatchOutOfRange {
                    index,
                    image_id1,
                    image_id2,
                    image_id,
                    keypoint,
                    keypoints,
                });
            }
        }
    }
    Ok(())
}
