//! The one writer of a folder's COLMAP input: the database (cameras, images, keypoints, and for
//! verified pairs their matches and two-view geometries) and the match list, in the order every run
//! writes them.

use std::io::Write;
use std::path::Path;

use crate::colmap::camera::PinholeCamera;
use crate::colmap::database::{Database, check_match_indices};
use crate::colmap::error::ColmapError;
use crate::colmap::folder::{Photo, photo_camera};
use crate::colmap::match_list::MatchList;
use crate::colmap::two_view::TwoViewGeometry;
use crate::matching::Match;
use crate::verify::{self, Intrinsics};

/// A camera's key without a shared K: one camera per image size and EXIF focal length.
type CameraKey = ((u32, u32), Option<u16>);
/// A photo written: its name, image id and keypoint count.
type WrittenPhoto = (String, u32, usize);

/// What a [`FolderWriter`] has written so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct FolderCounts {
    /// Photos (images of the database).
    pub photos: usize,
    /// Keypoints over all photos.
    pub keypoints: usize,
    /// Pairs whose matches were added, with or without matches.
    pub pairs: usize,
    /// Matches over all pairs.
    pub matches: usize,
    /// Pairs with at least one match: the pairs of the match list (when one is written).
    pub pairs_with_matches: usize,
    /// Pairs whose two-view geometry was written ([`FolderWriter::add_geometry`]).
    pub pairs_verified: usize,
    /// Of those, pairs with inliers (a geometry the mapper uses).
    pub pairs_with_inliers: usize,
    /// Inlier matches over all verified pairs.
    pub inliers: usize,
}

/// Writes a folder's photos into a new COLMAP 3.8 database and their matches into a match list
/// (when given one) and, for pairs verified, into the database.
///
/// Photos go in first, in image-id order ([`FolderWriter::add_photo`]), then the matches of each pair
/// ([`FolderWriter::add_matches`]) in the order the pairs are listed, each followed by its
/// verification, if any ([`FolderWriter::add_geometry`]); [`FolderWriter::finish`] commits the
/// database. With one camera given, every photo shares it (and must have its size);
/// without, each distinct image size and EXIF focal length gets its own ([`photo_camera`]), in the
/// order of the photos. The same calls give the same bytes: a database is a function of its photos and
/// camera, a match list of its pairs and matches, whatever process computed them.
///
/// ```
/// use clatch::colmap::{FolderWriter, Photo};
/// use clatch::{KeyPoint, Match};
///
/// let path = std::env::temp_dir().join(format!("clatch-doc-writer-{}.db", std::process::id()));
/// # std::fs::remove_file(&path).ok();
/// let photo = |name: &str| {
///     Photo::new(name, 640, 480, vec![KeyPoint::new(10.0, 20.0), KeyPoint::new(30.0, 40.0)])
/// };
/// let mut writer = FolderWriter::create(&path, Some(Vec::new()), None)?;
/// writer.add_photo(&photo("a.png"))?;
/// writer.add_photo(&photo("b.png"))?;
/// writer.add_matches(0, 1, &[Match { query: 1, train: 0, distance: 12 }])?;
/// let list = writer.finish()?.unwrap();
/// assert_eq!(String::from_utf8(list).unwrap(), "a.png b.png\n1 0\n\n");
/// # std::fs::remove_file(&path).ok();
/// # Ok::<(), clatch::colmap::ColmapError>(())
/// ```
pub struct FolderWriter<W: Write> {
    db: Database,
    list: Option<MatchList<W>>,
    /// The given camera and its id.
    shared: Option<(u32, PinholeCamera)>,
    /// The cameras made per size and focal length, with their ids.
    cameras: Vec<(CameraKey, u32, PinholeCamera)>,
    photos: Vec<WrittenPhoto>,
    /// Each photo's camera as verification sees it.
    verify_cameras: Vec<verify::Camera>,
    counts: FolderCounts,
}

impl<W: Write> FolderWriter<W> {
    /// Creates the database at `database` (an existing file is an error) and writes the match list
    /// to `match_list` (`None`: no match list). `camera`: one camera for every photo, or `None` for
    /// one per size and focal.
    pub fn create(
        database: &Path,
        match_list: Option<W>,
        camera: Option<&PinholeCamera>,
    ) -> Result<Self, ColmapError> {
        let mut db = Database::create(database)?;
        let shared = camera
            .map(|c| db.add_camera(c).map(|id| (id, *c)))
            .transpose()?;
        Ok(Self {
            db,
            list: match_list.map(MatchList::new),
            shared,
            cameras: Vec::new(),
            photos: Vec::new(),
            verify_cameras: Vec::new(),
            counts: FolderCounts::default(),
        })
    }

    /// Adds the next photo (its camera, its image row and its keypoints); returns its index, the one
    /// [`FolderWriter::add_matches`] takes (its COLMAP image id is that plus 1).
    pub fn add_photo(&mut self, photo: &Photo) -> Result<usize, ColmapError> {
        let size = (photo.width, photo.height);
        let (camera_id, camera) = match self.shared {
            Some((id, camera)) if (camera.width, camera.height) == size => (id, camera),
            Some((_, camera)) => {
                return Err(ColmapError::ImageSizeMismatch {
                    path: photo.name.clone().into(),
                    got_w: photo.width,
                    got_h: photo.height,
                    want_w: camera.width,
                    want_h: camera.height,
                });
            }
            None => {
                let key = (size, photo.focal_35mm);
                match self.cameras.iter().find(|(k, _, _)| *k == key) {
                    Some(&(_, id, camera)) => (id, camera),
                    None => {
                        let camera = photo_camera(photo.width, photo.height, photo.focal_35mm)?;
                        let id = self.db.add_camera(&camera)?;
                        self.cameras.push((key, id, camera));
                        (id, camera)
                    }
                }
            }
        };
        let image_id = self.db.add_image(&photo.name, camera_id)?;
        self.db.set_keypoints(image_id, &photo.keypoints)?;
        self.verify_cameras.push(verify_camera(&camera));
        self.photos
            .push((photo.name.clone(), image_id, photo.keypoints.len()));
        self.counts.photos += 1;
        self.counts.keypoints += photo.keypoints.len();
        Ok(self.photos.len() - 1)
    }

    /// Appends the matches of photos `i` and `j` (indices of [`FolderWriter::add_photo`]; `query`
    /// indexes `i`'s keypoints, `train` `j`'s) to the match list, if any, every index checked. A pair
    /// without matches is left out of the list, as COLMAP needs nothing of it.
    pub fn add_matches(
        &mut self,
        i: usize,
        j: usize,
        matches: &[Match],
    ) -> Result<(), ColmapError> {
        let ((name_i, id_i, n_i), (name_j, id_j, n_j)) = written_pair(&self.photos, i, j)?;
        check_match_indices(*id_i, *id_j, matches, *n_i, *n_j)?;
        if !matches.is_empty() {
            if let Some(list) = &mut self.list {
                list.add_pair(name_i, name_j, matches)?;
            }
            self.counts.pairs_with_matches += 1;
        }
        self.counts.pairs += 1;
        self.counts.matches += matches.len();
        Ok(())
    }

    /// Writes the pair `i`, `j` whose matches were `matches` ([`FolderWriter::add_matches`]'s indices
    /// and order) and what [`crate::verify`] found for it into the database, as COLMAP's own matcher
    /// does: the matches into `matches` ([`Database::add_matches`]), the geometry into
    /// `two_view_geometries` ([`TwoViewGeometry::from_verified`]), a row in each for every pair,
    /// with or without matches.
    pub fn add_geometry(
        &mut self,
        i: usize,
        j: usize,
        matches: &[Match],
        verified: &verify::TwoViewGeometry,
    ) -> Result<(), ColmapError> {
        let ((_, id_i, _), (_, id_j, _)) = written_pair(&self.photos, i, j)?;
        let geometry = TwoViewGeometry::from_verified(*id_i, *id_j, matches, verified)?;
        self.db.add_matches(*id_i, *id_j, matches)?;
        self.db.add_two_view_geometry(&geometry)?;
        self.counts.pairs_verified += 1;
        if !geometry.inliers.is_empty() {
            self.counts.pairs_with_inliers += 1;
        }
        self.counts.inliers += geometry.inliers.len();
        Ok(())
    }

    /// Photo `i`'s camera as verification takes it: its size and, where its focal length is known
    /// (a given K, an EXIF focal length: COLMAP's `prior_focal_length`), its intrinsics, so that a
    /// pair of such photos is verified calibrated as COLMAP would.
    pub fn verify_camera(&self, i: usize) -> Option<&verify::Camera> {
        self.verify_cameras.get(i)
    }

    /// Photos written so far.
    pub fn photos(&self) -> usize {
        self.photos.len()
    }

    /// Photos, keypoints, pairs and matches written so far.
    pub fn counts(&self) -> FolderCounts {
        self.counts
    }

    /// Commits the database, flushes the match list and returns its writer (`None` without one).
    pub fn finish(self) -> Result<Option<W>, ColmapError> {
        self.db.finish()?;
        self.list.map(MatchList::into_inner).transpose()
    }
}

/// A database camera as [`crate::verify`] takes it: COLMAP's principal point is in its pixel
/// convention (centres at `+ 0.5`), verification's in clatch's.
fn verify_camera(camera: &PinholeCamera) -> verify::Camera {
    let plain = verify::Camera::new(camera.width, camera.height);
    if camera.focal_is_known {
        plain.with_intrinsics(Intrinsics::new(
            camera.fx,
            camera.fy,
            camera.cx - 0.5,
            camera.cy - 0.5,
        ))
    } else {
        plain
    }
}

/// The written photos `i` and `j` of a pair: two different ones.
fn written_pair(
    photos: &[WrittenPhoto],
    i: usize,
    j: usize,
) -> Result<(&WrittenPhoto, &WrittenPhoto), ColmapError> {
    let bad = |reason| ColmapError::BadPair {
        i,
        j,
        photos: photos.len(),
        reason,
    };
    if i == j {
        return Err(bad("a pair needs two different photos"));
    }
    match (photos.get(i), photos.get(j)) {
        (Some(a), Some(b)) => Ok((a, b)),
        _ => Err(bad("an index is not one of the photos written")),
    }
}
