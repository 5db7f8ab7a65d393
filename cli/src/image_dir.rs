//! The images of a folder, as `clatch colmap` reads them.

use std::path::{Path, PathBuf};

use crate::error::CliError;

/// File extensions read as images (compared without case).
pub const IMAGE_EXTENSIONS: [&str; 7] = ["jpg", "jpeg", "png", "pgm", "ppm", "pbm", "pnm"];

/// The image files directly inside `dir` (no subfolders), sorted by name so that image ids are
/// the same on every run. A missing folder and a folder with no image are errors.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, CliError> {
    let read_err = |source| CliError::ImageDir {
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
        return Err(CliError::NoImages {
            path: dir.to_path_buf(),
            extensions: IMAGE_EXTENSIONS.join(", "),
        });
    }
    images.sort();
    Ok(images)
}

/// An image's name as COLMAP stores it: its file name (the folder is COLMAP's `--image_path`). It
/// must be UTF-8 (COLMAP stores names as text) and hold no whitespace (the match list separates names
/// with a space).
pub fn colmap_name(path: &Path) -> Result<String, CliError> {
    let refuse = |reason| CliError::ImageName {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_and_empty_folders_are_errors() {
        let e = list_images(Path::new("/nonexistent/clatch/images")).unwrap_err();
        assert!(matches!(e, CliError::ImageDir { .. }), "{e}");
        let dir = std::env::temp_dir().join(format!("clatch-image-dir-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("notes.txt"), "no image").unwrap();
        let e = list_images(&dir).unwrap_err();
        assert!(matches!(e, CliError::NoImages { .. }), "{e}");
        std::fs::write(dir.join("b.JPG"), "").unwrap();
        std::fs::write(dir.join("a.png"), "").unwrap();
        let names: Vec<_> = list_images(&dir)
            .unwrap()
            .iter()
            .map(|p| colmap_name(p).unwrap())
            .collect();
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(names, ["a.png", "b.JPG"]);
        let e = colmap_name(Path::new("dir/my photo.jpg")).unwrap_err();
        assert!(matches!(e, CliError::ImageName { .. }), "{e}");
        assert!(e.to_string().contains("whitespace"), "{e}");
    }
}
