//! A folder of photos as COLMAP's input: which files are images, their names, their features, their
//! cameras. `clatch colmap` and the Python package (`clatch.colmap`, `clatch.ray`) both read folders
//! through this module, so every run writes the same database for the same folder and settings.

use std::path::{Path, PathBuf};

use image::GrayImage;

use crate::colmap::camera::PinholeCamera;
use crate::colmap::corner::Refinement;
use crate::colmap::error::ColmapError;
use crate::colmap::exif;
use crate::decode::{DecodeLimits, open_gray_with_exif, probe};
use crate::describe::WINDOW;
use crate::descriptor::DescriptorSet;
use crate::detect::DetectorConfig;
use crate::extract::Extractor;
use crate::features::Features;
use crate::gray_view::{AsGrayView, GrayView};
use crate::keypoint::KeyPoint;
use crate::prefetch::{Prefetched, extract_decoded};

/// File extensions read as images (compared without case).
pub const IMAGE_EXTENSIONS: [&str; 7] = ["jpg", "jpeg", "png", "pgm", "ppm", "pbm", "pnm"];

/// The grid keypoints are spread over for structure from motion ([`DetectorConfig::grid`]) unless the
/// caller chooses another: 8 x 8 keeps textured corners of a photo (foliage, gravel) from taking every
/// keypoint.
pub const DEFAULT_GRID: usize = 8;

/// Keypoints per photo for structure from motion unless the caller chooses another: COLMAP's own
/// budget of SIFT features (`SiftExtraction.max_num_features`, 8192). Structure from motion wants many
/// well-spread points per photo more than a fast match of each pair, so its budget is larger than the
/// library's general default of 5000 (measured: docs/bench/2026-12-02-sfm/ in the repository).
pub const DEFAULT_MAX_KEYPOINTS: usize = 8192;

/// The image files directly inside `dir` (no subfolders), sorted by path so that image ids are the
/// same on every run. A missing folder and a folder with no image are errors.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, ColmapError> {
    let read_err = |source| ColmapError::ImageDir {
        path: dir.to_path_buf(),
        source,
    };
    let mut images = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(read_err)? {
        let path = entry.map_err(read_err)?.path();
        let is_image = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)));
        if is_image && path.is_file() {
            images.push(path);
        }
    }
    if images.is_empty() {
        return Err(ColmapError::NoImages {
            path: dir.to_path_buf(),
            extensions: IMAGE_EXTENSIONS.join(", "),
        });
    }
    images.sort();
    Ok(images)
}

/// The entries of `dir` named like images ([`IMAGE_EXTENSIONS`]) that [`list_images`] skips because
/// they are not regular files, with what each is: a broken link, a FIFO, a folder, a device, a
/// socket. For a warning: a photo the user expects may be a dangling link.
pub fn skipped_entries(dir: &Path) -> Vec<(PathBuf, &'static str)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut skipped: Vec<(PathBuf, &'static str)> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|path| {
            path.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
        })
        .filter_map(|path| match std::fs::metadata(&path) {
            Ok(meta) if meta.is_file() => None,
            Ok(meta) => Some((path, crate::output::file_kind(&meta))),
            Err(_) => Some((path, "a broken link")),
        })
        .collect();
    skipped.sort();
    skipped
}

/// An image's name as COLMAP stores it: its file name (the folder is COLMAP's `--image_path`). It
/// must be UTF-8 (COLMAP stores names as text) and hold no whitespace (the match list separates names
/// with a space).
pub fn image_name(path: &Path) -> Result<String, ColmapError> {
    let refuse = |reason| ColmapError::ImageName {
        path: path.to_path_buf(),
        reason,
    };
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| refuse("the file name is not valid UTF-8"))?;
    if name.chars().any(char::is_whitespace) {
        return Err(refuse(
            "the file name holds whitespace, which COLMAP's match list cannot hold",
        ));
    }
    Ok(name.to_owned())
}

/// Refuses an image in which the detector cannot score a single pixel: it scores only pixels at least
/// [`DetectorConfig::margin`] from every border, so a side needs `2 margin + 1` pixels, and never
/// less than the library's 64x64 minimum.
pub fn check_detectable(path: &Path, width: u32, height: u32) -> Result<(), ColmapError> {
    let margin = DetectorConfig::default().margin();
    let min = (2 * margin + 1).max(WINDOW);
    if (width as usize) < min || (height as usize) < min {
        return Err(ColmapError::ImageTooSmall {
            path: path.to_path_buf(),
            width,
            height,
            margin,
            min,
        });
    }
    Ok(())
}

/// The photos of a folder, checked before any work: their names, and their sizes from the files'
/// headers (within the decoding limits, complete JPEGs, large enough to detect on).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImageFolder {
    /// The image files, in name order: image `i` of every result is `paths[i]`.
    pub paths: Vec<PathBuf>,
    /// Their names in the database ([`image_name`]).
    pub names: Vec<String>,
    /// Their sizes `(width, height)`, from the headers.
    pub sizes: Vec<(u32, u32)>,
}

impl ImageFolder {
    /// Lists `dir` ([`list_images`]) and checks every photo's name and header.
    pub fn open(dir: &Path, limits: &DecodeLimits) -> Result<Self, ColmapError> {
        let paths = list_images(dir)?;
        let names = paths
            .iter()
            .map(|p| image_name(p))
            .collect::<Result<Vec<_>, _>>()?;
        let sizes = paths
            .iter()
            .map(|p| {
                let info = probe(p, limits)?;
                check_detectable(p, info.width, info.height)?;
                Ok((info.width, info.height))
            })
            .collect::<Result<Vec<_>, ColmapError>>()?;
        Ok(Self {
            paths,
            names,
            sizes,
        })
    }

    /// The camera of the intrinsic matrix `k_text` ([`PinholeCamera::from_k_text`]) for every photo,
    /// which needs them all to have the first one's size.
    pub fn shared_camera(&self, k_text: &str) -> Result<PinholeCamera, ColmapError> {
        let (want_w, want_h) = self.sizes.first().copied().unwrap_or_default();
        let camera = PinholeCamera::from_k_text(k_text, want_w, want_h)?;
        self.check_one_size((want_w, want_h))?;
        Ok(camera)
    }

    /// Refuses a photo whose size is not `(want_w, want_h)`, as one shared camera needs.
    pub fn check_one_size(&self, (want_w, want_h): (u32, u32)) -> Result<(), ColmapError> {
        for (path, &(got_w, got_h)) in self.paths.iter().zip(&self.sizes) {
            if (got_w, got_h) != (want_w, want_h) {
                return Err(ColmapError::ImageSizeMismatch {
                    path: path.clone(),
                    got_w,
                    got_h,
                    want_w,
                    want_h,
                });
            }
        }
        Ok(())
    }
}

/// What the database holds of one photo.
///
/// `#[non_exhaustive]`, so that what is written of a photo can grow: built with [`Photo::new`] and
/// [`Photo::with_focal_35mm`].
///
/// ```
/// use clatch::KeyPoint;
/// use clatch::colmap::Photo;
///
/// let photo = Photo::new("a.jpg", 640, 480, vec![KeyPoint::new(10.0, 20.0)]).with_focal_35mm(Some(28));
/// assert_eq!((photo.width, photo.focal_35mm), (640, Some(28)));
/// ```
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Photo {
    /// Its name in the database ([`image_name`]).
    pub name: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// EXIF `FocalLengthIn35mmFilm`, if the file has it.
    pub focal_35mm: Option<u16>,
    /// Its keypoints, refined; keypoint `i` is described by row `i` of its descriptors.
    pub keypoints: Vec<KeyPoint>,
}

impl Photo {
    /// The photo named `name` in the database, `width` x `height` pixels, with `keypoints`, and no
    /// EXIF focal length.
    pub fn new(name: impl Into<String>, width: u32, height: u32, keypoints: Vec<KeyPoint>) -> Self {
        Self {
            name: name.into(),
            width,
            height,
            focal_35mm: None,
            keypoints,
        }
    }

    with_methods! {
        /// The same photo with this EXIF `FocalLengthIn35mmFilm` ([`Photo::focal_35mm`]).
        with_focal_35mm => focal_35mm: Option<u16>;
    }
}

/// The camera of a photo without a given K: the focal length from EXIF's 35 mm equivalent where the
/// photo has one (marked as known, as COLMAP marks EXIF focal lengths), else COLMAP's guess.
pub fn photo_camera(
    width: u32,
    height: u32,
    focal_35mm: Option<u16>,
) -> Result<PinholeCamera, ColmapError> {
    let guess = PinholeCamera::guess(width, height)?;
    // An EXIF focal length the camera check finds implausible (a broken tag) is no better than none.
    Ok(focal_35mm
        .and_then(|f| {
            let focal = exif::focal_pixels(f, width, height);
            PinholeCamera {
                fx: focal,
                fy: focal,
                focal_is_known: true,
                ..guess
            }
            .validated()
            .ok()
        })
        .unwrap_or(guess))
}

/// A decoded photo waiting for extraction.
struct Decoded<'a> {
    img: GrayImage,
    exif_block: Option<Vec<u8>>,
    path: &'a Path,
    name: &'a str,
}

/// Reads and checks one photo.
fn decode<'a>(
    path: &'a Path,
    name: &'a str,
    limits: &DecodeLimits,
) -> Result<Decoded<'a>, ColmapError> {
    let (img, exif_block) = open_gray_with_exif(path, limits)?;
    check_detectable(path, img.width(), img.height())?;
    Ok(Decoded {
        img,
        exif_block,
        path,
        name,
    })
}

impl AsGrayView for Decoded<'_> {
    fn gray_view(&self) -> crate::Result<GrayView<'_>> {
        self.img.gray_view()
    }
}

impl Decoded<'_> {
    fn view(&self) -> Result<GrayView<'_>, ColmapError> {
        GrayView::try_from(&self.img).map_err(|source| ColmapError::Image {
            path: self.path.to_path_buf(),
            source,
        })
    }

    /// The photo of these features, its keypoints refined, and its descriptors.
    fn photo(self, features: Features, refinement: Refinement) -> (Photo, DescriptorSet) {
        let photo = Photo {
            name: self.name.to_owned(),
            width: self.img.width(),
            height: self.img.height(),
            focal_35mm: self.exif_block.as_deref().and_then(exif::focal_length_35mm),
            keypoints: refinement.apply(&self.img, features.keypoints),
        };
        (photo, features.descriptors)
    }
}

/// Reads the photo at `path` (named `name` in the database), detects and describes it with
/// `extractor` and refines its keypoints with `refinement` (whose detector half,
/// [`Refinement::detector_subpixel`], is the extractor's to apply: set its
/// [`DetectorConfig::subpixel`] to it). The same photo gives the same bits in [`extract_photos`].
pub fn extract_photo(
    extractor: &Extractor,
    (path, name): (&Path, &str),
    limits: &DecodeLimits,
    refinement: Refinement,
) -> Result<(Photo, DescriptorSet), ColmapError> {
    let decoded = decode(path, name, limits)?;
    let features = extractor
        .detect_and_describe(&decoded.view()?)
        .map_err(|source| ColmapError::Image {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(decoded.photo(features, refinement))
}

/// [`extract_photo`] of every photo, in order: the photos decoded on worker threads ahead of the
/// extractor ([`crate::prefetch::extract_decoded`]), which takes them as a stream
/// ([`Extractor::detect_and_describe_stream`]: on the GPU several in flight on several streams).
/// `done(i)` is called as photo `i` is extracted, in order. Returns the photos and the decoders'
/// timings (their summed time, and how long extraction waited for them).
pub fn extract_photos(
    extractor: &Extractor,
    (paths, names): (&[PathBuf], &[String]),
    limits: &DecodeLimits,
    refinement: Refinement,
    done: &(dyn Fn(usize) + Sync),
) -> Result<(Vec<(Photo, DescriptorSet)>, Prefetched), ColmapError> {
    let mut photos = Vec::with_capacity(paths.len().min(names.len()));
    let decoding = extract_each_photo(
        extractor,
        (paths, names),
        limits,
        refinement,
        |i, photo, descriptors| {
            photos.push((photo, descriptors));
            done(i);
            Ok(())
        },
    )?;
    Ok((photos, decoding))
}

/// [`extract_photos`] handing each photo to `each(i, photo, descriptors)` as it is extracted, in
/// order, on the calling thread, instead of keeping them: an error of `each` stops the extraction and
/// is returned. Returns the decoders' timings.
pub fn extract_each_photo(
    extractor: &Extractor,
    (paths, names): (&[PathBuf], &[String]),
    limits: &DecodeLimits,
    refinement: Refinement,
    mut each: impl FnMut(usize, Photo, DescriptorSet) -> Result<(), ColmapError>,
) -> Result<Prefetched, ColmapError> {
    extract_decoded(
        extractor,
        paths.len().min(names.len()),
        |i| decode(&paths[i], &names[i], limits),
        |i, decoded, features| {
            let (photo, descriptors) = decoded.photo(features, refinement);
            each(i, photo, descriptors)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_and_empty_folders_are_errors() {
        let e = list_images(Path::new("/nonexistent/clatch/images")).unwrap_err();
        assert!(matches!(e, ColmapError::ImageDir { .. }), "{e}");
        let dir = std::env::temp_dir().join(format!("clatch-image-dir-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("notes.txt"), "no image").unwrap();
        let e = list_images(&dir).unwrap_err();
        assert!(matches!(e, ColmapError::NoImages { .. }), "{e}");
        std::fs::write(dir.join("b.JPG"), "").unwrap();
        std::fs::write(dir.join("a.png"), "").unwrap();
        let names: Vec<_> = list_images(&dir)
            .unwrap()
            .iter()
            .map(|p| image_name(p).unwrap())
            .collect();
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(names, ["a.png", "b.JPG"]);
        let e = image_name(Path::new("dir/my photo.jpg")).unwrap_err();
        assert!(matches!(e, ColmapError::ImageName { .. }), "{e}");
        assert!(e.to_string().contains("whitespace"), "{e}");
    }

    #[test]
    fn the_detectable_minimum_follows_the_detector_margin() {
        // The default 40-pixel keypoints: margin ceil(40 / sqrt 2) + 2 = 31, so 63 pixels, raised to
        // the library's 64.
        let path = Path::new("img.png");
        assert!(check_detectable(path, 64, 64).is_ok());
        let e = check_detectable(path, 63, 500).unwrap_err();
        assert!(
            matches!(
                e,
                ColmapError::ImageTooSmall {
                    min: 64,
                    margin: 31,
                    ..
                }
            ),
            "{e}"
        );
        assert!(check_detectable(path, 500, 63).is_err());
    }

    #[test]
    fn exif_focal_gives_a_known_focal_and_none_the_guess() {
        let known = photo_camera(3000, 2000, Some(36)).unwrap();
        assert_eq!(
            (known.fx, known.fy, known.focal_is_known),
            (3000.0, 3000.0, true)
        );
        let guess = photo_camera(3000, 2000, None).unwrap();
        assert_eq!(guess, PinholeCamera::guess(3000, 2000).unwrap());
        assert!(!guess.focal_is_known);
    }
}
