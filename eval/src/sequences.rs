//! Homography sequences on disk: a folder of images 1..n with homographies from image 1 to each
//! other, in the Oxford layout (`img1.ppm`, `H1to2p`, ...) or the HPatches layout (`1.ppm`, `H_1_2`,
//! ...). `--data` names a sequence folder or a folder of them.

use std::path::{Path, PathBuf};

use crate::error::{EvalError, IoContext};
use crate::pairs::{EvalPair, read_homography};

/// Image extensions a sequence may use, in the order they are looked for, in any case (`img1.JPG`).
pub const IMAGE_EXTENSIONS: [&str; 5] = ["ppm", "pgm", "png", "jpg", "jpeg"];

/// How a sequence folder names its images and homographies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// `img1.ppm` ... and `H1to2p` ... (Mikolajczyk's affine-covariant data).
    Oxford,
    /// `1.ppm` ... and `H_1_2` ... (HPatches).
    Hpatches,
}

impl Layout {
    /// File stem of image `k`.
    pub fn image_stem(self, k: u32) -> String {
        match self {
            Layout::Oxford => format!("img{k}"),
            Layout::Hpatches => k.to_string(),
        }
    }

    /// File name of the homography from image 1 to image `k`.
    pub fn homography_name(self, k: u32) -> String {
        match self {
            Layout::Oxford => format!("H1to{k}p"),
            Layout::Hpatches => format!("H_1_{k}"),
        }
    }

    /// `k` if `file_name` is this layout's homography from image 1 to image `k` (k >= 2).
    fn homography_index(self, file_name: &str) -> Option<u32> {
        let digits = match self {
            Layout::Oxford => file_name.strip_prefix("H1to")?.strip_suffix('p')?,
            Layout::Hpatches => file_name.strip_prefix("H_1_")?,
        };
        // Plain decimal digits only, so `H1to+2p` or `H_1_02` are not taken for image 2's.
        let canonical = digits.bytes().all(|b| b.is_ascii_digit()) && !digits.starts_with('0');
        canonical
            .then(|| digits.parse().ok())
            .flatten()
            .filter(|&k| k >= 2)
    }

    /// The group of a sequence named `name`: the layout, then the name (`oxford-graf`).
    pub fn group(self, name: &str) -> String {
        match self {
            Layout::Oxford => format!("{GROUP_PREFIX_OXFORD}{name}"),
            Layout::Hpatches => format!("{GROUP_PREFIX_HPATCHES}{name}"),
        }
    }
}

/// Group-name prefix of Oxford-layout sequences.
pub const GROUP_PREFIX_OXFORD: &str = "oxford-";
/// Group-name prefix of HPatches-layout sequences.
pub const GROUP_PREFIX_HPATCHES: &str = "hpatches-";

/// Whether `group` holds the pairs of a sequence read from disk (not synthetic, not the sample).
pub fn is_sequence_group(group: &str) -> bool {
    group.starts_with(GROUP_PREFIX_OXFORD) || group.starts_with(GROUP_PREFIX_HPATCHES)
}

/// The sequence name of a group (`oxford-graf` gives `graf`).
pub fn sequence_of_group(group: &str) -> Option<&str> {
    group
        .strip_prefix(GROUP_PREFIX_OXFORD)
        .or_else(|| group.strip_prefix(GROUP_PREFIX_HPATCHES))
}

/// The first file among `dir/stem.{extensions}` that exists, the extension in any case.
fn image_file(dir: &Path, stem: &str) -> Option<PathBuf> {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|entry| Some(entry.ok()?.path()))
        .filter(|path| path.file_stem().is_some_and(|s| s == stem) && path.is_file())
        .collect();
    IMAGE_EXTENSIONS.iter().find_map(|ext| {
        files
            .iter()
            .find(|path| {
                path.extension()
                    .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case(ext))
            })
            .cloned()
    })
}

/// The layout of `dir` if it holds a first image (`img1.*` for Oxford, else `1.*` for HPatches).
pub fn detect_layout(dir: &Path) -> Option<Layout> {
    [Layout::Oxford, Layout::Hpatches]
        .into_iter()
        .find(|layout| image_file(dir, &layout.image_stem(1)).is_some())
}

/// The name of a sequence folder: its own name, with the `oxford_` prefix of the Oxford download's
/// folders dropped so that `oxford_graf` keeps its pairs' historical names (`graf 1-2`).
pub fn sequence_name(dir: &Path) -> Result<String, EvalError> {
    let folder = match dir.file_name() {
        Some(name) => name.to_os_string(),
        // `.` or `..`: the name of the folder they stand for.
        None => std::fs::canonicalize(dir)
            .reading(dir)?
            .file_name()
            .map(|n| n.to_os_string())
            .unwrap_or_default(),
    };
    let folder = folder.to_string_lossy();
    let name = folder.strip_prefix("oxford_").unwrap_or(&folder);
    if name.is_empty() || name.chars().any(char::is_control) {
        return Err(EvalError::Input {
            path: dir.to_path_buf(),
            reason: "a sequence is named by its folder, and this folder's name is empty or holds \
                     a control character; rename it"
                .into(),
        });
    }
    Ok(name.to_string())
}

/// Image 1 against every image k that has a homography `1 to k`, in the order of k.
pub fn sequence_pairs(dir: &Path, layout: Layout) -> Result<Vec<EvalPair>, EvalError> {
    let name = sequence_name(dir)?;
    let missing = |path: PathBuf, what: &str| EvalError::Input {
        path,
        reason: format!("{what} not found ({layout:?} layout)"),
    };
    let image = |k: u32| {
        let stem = layout.image_stem(k);
        image_file(dir, &stem).ok_or_else(|| {
            missing(
                dir.join(format!("{stem}.{}", IMAGE_EXTENSIONS.join("/."))),
                "image",
            )
        })
    };
    let image_a = image(1)?;
    let mut indices = Vec::new();
    for entry in std::fs::read_dir(dir).reading(dir)? {
        let entry = entry.reading(dir)?;
        if let Some(k) = entry
            .file_name()
            .to_str()
            .and_then(|f| layout.homography_index(f))
        {
            indices.push(k);
        }
    }
    if indices.is_empty() {
        return Err(missing(
            dir.join(layout.homography_name(2)),
            "homography file",
        ));
    }
    indices.sort_unstable();
    indices
        .into_iter()
        .map(|k| {
            let homography = dir.join(layout.homography_name(k));
            // Read now so that a malformed file stops the run before any work, naming the file.
            read_homography(&homography)?;
            Ok(EvalPair {
                name: format!("{name} 1-{k}"),
                group: layout.group(&name),
                param: None,
                image_a: image_a.clone(),
                image_b: image(k)?,
                homography,
            })
        })
        .collect()
}

/// The pairs of `data` if it is a sequence folder, else of each sequence folder inside it (sorted by
/// name); the second list names the subfolders skipped because they hold no first image.
pub fn sequences_under(data: &Path) -> Result<(Vec<EvalPair>, Vec<PathBuf>), EvalError> {
    match std::fs::metadata(data) {
        Ok(meta) if meta.is_dir() => {}
        Ok(meta) => {
            return Err(EvalError::Input {
                path: data.to_path_buf(),
                reason: format!(
                    "--data names {}, not a folder: give a homography sequence folder or a \
                     folder of them",
                    if meta.is_file() {
                        "a file"
                    } else {
                        clatch::decode::file_kind(&meta)
                    }
                ),
            });
        }
        Err(_) => {
            return Err(EvalError::Input {
                path: data.to_path_buf(),
                reason: "data folder not found".into(),
            });
        }
    }
    if let Some(layout) = detect_layout(data) {
        return Ok((sequence_pairs(data, layout)?, Vec::new()));
    }
    let mut folders = Vec::new();
    for entry in std::fs::read_dir(data).reading(data)? {
        let path = entry.reading(data)?.path();
        let hidden = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if path.is_dir() && !hidden {
            folders.push(path);
        }
    }
    folders.sort();
    let (mut pairs, mut skipped) = (Vec::new(), Vec::new());
    for folder in folders {
        match detect_layout(&folder) {
            Some(layout) => pairs.extend(sequence_pairs(&folder, layout)?),
            None => skipped.push(folder),
        }
    }
    if pairs.is_empty() {
        return Err(EvalError::Input {
            path: data.to_path_buf(),
            reason: "no homography sequence here or in its subfolders (looked for img1.* with \
                     H1to2p... (Oxford) and 1.* with H_1_2... (HPatches))"
                .into(),
        });
    }
    Ok((pairs, skipped))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("clatch-seq-{}-{name}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    const IDENTITY: &str = "1 0 0\n0 1 0\n0 0 1\n";

    /// A sequence folder of `n` (empty) images in `layout`, with homographies to each.
    fn write_sequence(dir: &Path, layout: Layout, n: u32, ext: &str) {
        std::fs::create_dir_all(dir).unwrap();
        for k in 1..=n {
            std::fs::write(dir.join(format!("{}.{ext}", layout.image_stem(k))), b"P5").unwrap();
            if k >= 2 {
                std::fs::write(dir.join(layout.homography_name(k)), IDENTITY).unwrap();
            }
        }
    }

    #[test]
    fn homography_names_parse_back_and_odd_names_are_not_taken() {
        for layout in [Layout::Oxford, Layout::Hpatches] {
            for k in [2, 6, 12] {
                assert_eq!(layout.homography_index(&layout.homography_name(k)), Some(k));
            }
        }
        for odd in [
            "H1to1p",
            "H1to02p",
            "H1to2",
            "H1to2p.txt",
            "H_1_1",
            "H_1_x",
            "H_1_+3",
        ] {
            assert_eq!(Layout::Oxford.homography_index(odd), None, "{odd}");
            assert_eq!(Layout::Hpatches.homography_index(odd), None, "{odd}");
        }
    }

    #[test]
    fn both_layouts_give_pairs_named_by_folder() {
        let root = temp_dir("layouts");
        write_sequence(&root.join("oxford_graf"), Layout::Oxford, 6, "ppm");
        write_sequence(&root.join("v_wall"), Layout::Hpatches, 4, "png");
        std::fs::create_dir_all(root.join("notes")).unwrap();

        let (pairs, skipped) = sequences_under(&root).unwrap();
        assert_eq!(skipped, [root.join("notes")]);
        let names: Vec<&str> = pairs.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "graf 1-2",
                "graf 1-3",
                "graf 1-4",
                "graf 1-5",
                "graf 1-6",
                "v_wall 1-2",
                "v_wall 1-3",
                "v_wall 1-4"
            ]
        );
        assert_eq!(pairs[0].group, "oxford-graf");
        assert_eq!(pairs[5].group, "hpatches-v_wall");
        assert_eq!(pairs[7].image_a, root.join("v_wall/1.png"));
        assert_eq!(pairs[7].image_b, root.join("v_wall/4.png"));
        assert_eq!(pairs[7].homography, root.join("v_wall/H_1_4"));
        assert!(pairs.iter().all(|p| is_sequence_group(&p.group)));
        assert_eq!(sequence_of_group(&pairs[5].group), Some("v_wall"));

        // The sequence folder itself.
        let (alone, skipped) = sequences_under(&root.join("v_wall")).unwrap();
        assert_eq!(alone, pairs[5..]);
        assert!(skipped.is_empty());
        let (dotted, _) = sequences_under(&root.join("v_wall/.")).unwrap();
        assert_eq!(dotted[0].name, "v_wall 1-2");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn malformed_sequences_are_typed_errors_naming_the_file() {
        let root = temp_dir("malformed");
        let dir = root.join("graf");
        std::fs::create_dir_all(&dir).unwrap();
        let e = sequences_under(&root).unwrap_err();
        assert!(
            matches!(e, EvalError::Input { .. })
                && e.to_string().contains("no homography sequence"),
            "{e}"
        );
        std::fs::write(dir.join("img1.ppm"), b"P5").unwrap();
        let e = sequences_under(&root).unwrap_err();
        assert!(e.to_string().contains("H1to2p"), "{e}");
        std::fs::write(dir.join("H1to2p"), IDENTITY).unwrap();
        let e = sequences_under(&root).unwrap_err();
        assert!(e.to_string().contains("img2"), "{e}");
        std::fs::write(dir.join("img2.pgm"), b"P5").unwrap();
        std::fs::write(dir.join("img3.jpg"), b"").unwrap();
        std::fs::write(dir.join("H1to3p"), "1 0 0\n0 one 0\n0 0 1\n").unwrap();
        let e = sequences_under(&root).unwrap_err();
        assert!(
            matches!(&e, EvalError::Homography { path, .. } if path.ends_with("H1to3p")),
            "{e}"
        );
        std::fs::write(dir.join("H1to3p"), IDENTITY).unwrap();
        let pairs = sequences_under(&root).unwrap().0;
        assert_eq!(pairs.len(), 2);
        assert_eq!(pairs[1].image_b, dir.join("img3.jpg"));

        // Extensions in any case: a camera's `.JPG`, a `.jpeg`.
        let upper = root.join("upper/boat");
        write_sequence(&upper, Layout::Oxford, 2, "JPG");
        std::fs::rename(upper.join("img2.JPG"), upper.join("img2.jpeg")).unwrap();
        let pairs = sequences_under(&root.join("upper")).unwrap().0;
        assert_eq!(pairs.len(), 1);
        assert_eq!(pairs[0].image_a, upper.join("img1.JPG"));
        assert_eq!(pairs[0].image_b, upper.join("img2.jpeg"));

        assert!(matches!(
            sequences_under(&root.join("nope")),
            Err(EvalError::Input { .. })
        ));
        // A comma is fine (the files are proper CSV); a control character is not.
        let comma = root.join("a,b");
        write_sequence(&comma, Layout::Hpatches, 2, "ppm");
        assert_eq!(sequences_under(&comma).unwrap().0[0].name, "a,b 1-2");
        let tab = root.join("a\tb");
        write_sequence(&tab, Layout::Hpatches, 2, "ppm");
        assert!(matches!(
            sequences_under(&tab),
            Err(EvalError::Input { path, .. }) if path == tab
        ));
        std::fs::remove_dir_all(&root).ok();
    }
}
