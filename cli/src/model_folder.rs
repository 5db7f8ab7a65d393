//! The workspace's `sparse/` folder, where `clatch colmap` installs the models COLMAP's mapper builds.
//!
//! clatch replaces only what it installed itself: the model folders (`0`, `1`, ...) named in
//! `sparse/.clatch-models`, and only while they hold nothing but the files a mapper writes. Anything
//! else there (photos, notes, a model another program wrote, a file added to one of clatch's models)
//! is never moved or removed: a run that would have to is refused before any work.

use std::path::{Path, PathBuf};

use std::io::Write as _;

use crate::error::CliError;
use clatch::output::{TempDir, write_file};

/// The list of model folders clatch installed, inside `sparse/`.
pub const MANIFEST: &str = ".clatch-models";

/// Files COLMAP's mapper writes into a model folder (3.8, and the rigs and frames of later versions;
/// the text format for models converted in place).
const MODEL_FILES: &[&str] = &[
    "cameras.bin",
    "images.bin",
    "points3D.bin",
    "frames.bin",
    "rigs.bin",
    "project.ini",
    "cameras.txt",
    "images.txt",
    "points3D.txt",
];

/// `sparse/`, checked before the run.
#[derive(Debug)]
pub struct ModelFolder {
    path: PathBuf,
    /// Whether clatch's earlier models there may be replaced (`--force`).
    force: bool,
}

impl ModelFolder {
    /// Looks at `path` before any work: refuses it when it holds anything clatch did not install, and
    /// when it holds clatch's earlier models unless `force` allows replacing them.
    pub fn inspect(path: &Path, force: bool) -> Result<Self, CliError> {
        let folder = Self {
            path: path.to_path_buf(),
            force,
        };
        folder.replaceable()?;
        Ok(folder)
    }

    /// `path` for a run that writes nothing there (no COLMAP run): only its name is used.
    pub fn untouched(path: &Path) -> Self {
        Self {
            path: path.to_path_buf(),
            force: false,
        }
    }

    /// clatch's earlier models, which this run may replace; an error if it may not, or if the folder
    /// holds anything else.
    fn replaceable(&self) -> Result<Vec<String>, CliError> {
        let earlier = earlier_models(&self.path)?;
        if !earlier.is_empty() && !self.force {
            return Err(CliError::ModelsExist {
                path: self.path.clone(),
            });
        }
        Ok(earlier)
    }

    /// The folder's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Moves the model folders the mapper wrote into `built` into place, replacing the earlier ones of
    /// clatch's (which are removed only once the new ones are in place), and returns them in order.
    /// `sparse/` is looked at again first: what appeared there since [`Self::inspect`] is kept, and a
    /// new model whose name is taken by something clatch did not install is an error.
    pub fn install(&self, built: &TempDir) -> Result<Vec<PathBuf>, CliError> {
        let earlier = self.replaceable()?;
        let mut new: Vec<String> = Vec::new();
        let entries = std::fs::read_dir(built.path()).map_err(CliError::read(built.path()))?;
        for entry in entries {
            let entry = entry.map_err(CliError::read(built.path()))?;
            if entry.path().is_dir() {
                new.push(entry.file_name().to_string_lossy().into_owned());
            }
        }
        new.sort_by_key(|name| (name.len(), name.clone()));
        std::fs::create_dir_all(&self.path).map_err(CliError::write(&self.path))?;

        // An interruption waits until the models are in place (or back where they were).
        let _whole = clatch::output::Uninterrupted::new();
        // The earlier models go aside (removed with `aside` when dropped, once all is in place).
        let aside = TempDir::beside(&self.path)?;
        let mut moved_aside = Vec::new();
        let mut installed = Vec::new();
        let result = (|| {
            for name in &earlier {
                rename(&self.path.join(name), &aside.path().join(name))?;
                moved_aside.push(name.clone());
            }
            for name in &new {
                let target = self.path.join(name);
                if target.symlink_metadata().is_ok() {
                    return Err(CliError::ForeignInWorkspace {
                        folder: self.path.clone(),
                        entry: name.clone(),
                    });
                }
                rename(&built.path().join(name), &target)?;
                installed.push(name.clone());
            }
            Ok(write_file(&self.path.join(MANIFEST), |w| {
                new.iter().try_for_each(|name| writeln!(w, "{name}"))
            })?)
        })();
        if let Err(e) = result {
            // Back as it was: the new models to the build folder, the earlier ones to their place.
            for name in &installed {
                std::fs::rename(self.path.join(name), built.path().join(name)).ok();
            }
            for name in &moved_aside {
                std::fs::rename(aside.path().join(name), self.path.join(name)).ok();
            }
            return Err(e);
        }
        drop(aside);
        Ok(new.iter().map(|name| self.path.join(name)).collect())
    }
}

/// Refuses an images folder that is the workspace or lies inside its model folder `sparse`: clatch
/// writes there, and its photos would be taken for foreign files (or, by an older clatch, removed).
pub fn check_images_outside(
    images: &Path,
    workspace: &Path,
    sparse: &Path,
) -> Result<(), CliError> {
    let images_at = resolved(images);
    let refuse = |what| {
        Err(CliError::ImagesInWorkspace {
            images: images.to_path_buf(),
            what,
        })
    };
    if images_at == resolved(workspace) {
        return refuse("the workspace");
    }
    if images_at.starts_with(resolved(sparse)) {
        return refuse("inside the workspace's model folder");
    }
    Ok(())
}

/// `path` with links resolved: its longest existing ancestor made canonical, the rest appended.
fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut rest = Vec::new();
    let mut head = absolute.as_path();
    loop {
        if let Ok(canonical) = std::fs::canonicalize(head) {
            return rest.iter().rev().fold(canonical, |p, part| p.join(part));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                head = parent;
            }
            _ => return absolute,
        }
    }
}

fn rename(from: &Path, to: &Path) -> Result<(), CliError> {
    std::fs::rename(from, to).map_err(CliError::write(to))
}

/// The model folders of `sparse` that clatch installed and may replace; an error naming the first
/// entry that clatch did not install (or that has something else inside).
fn earlier_models(sparse: &Path) -> Result<Vec<String>, CliError> {
    let meta = match std::fs::symlink_metadata(sparse) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => return Err(CliError::read(sparse)(source)),
    };
    if !meta.is_dir() {
        return Err(CliError::OutputPath {
            path: sparse.to_path_buf(),
            reason: format!(
                "it is {}, not the folder of COLMAP models; choose another --workspace",
                clatch::decode::file_kind(&meta)
            ),
        });
    }
    let listed = read_manifest(sparse)?;
    let mut earlier = Vec::new();
    let entries = std::fs::read_dir(sparse).map_err(CliError::read(sparse))?;
    for entry in entries {
        let entry = entry.map_err(CliError::read(sparse))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name == MANIFEST {
            continue;
        }
        let ours = listed.contains(&name) && holds_only_model_files(&entry.path())?;
        if !ours {
            return Err(CliError::ForeignInWorkspace {
                folder: sparse.to_path_buf(),
                entry: name,
            });
        }
        earlier.push(name);
    }
    earlier.sort_by_key(|name| (name.len(), name.clone()));
    Ok(earlier)
}

/// The names in `sparse/.clatch-models` (none when there is no such file).
fn read_manifest(sparse: &Path) -> Result<Vec<String>, CliError> {
    let path = sparse.join(MANIFEST);
    match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => return Err(CliError::read(&path)(source)),
        Ok(meta) if !meta.is_file() => {
            return Err(CliError::ForeignInWorkspace {
                folder: sparse.to_path_buf(),
                entry: MANIFEST.into(),
            });
        }
        Ok(_) => {}
    }
    let text = crate::text_input::read_text(&path, "model list")?;
    // Only plain model numbers: a hand-edited list cannot make clatch take `..` or a photo.
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && l.bytes().all(|b| b.is_ascii_digit()))
        .map(str::to_owned)
        .collect())
}

/// Whether `path` is a real folder (not a link) holding only regular files a mapper writes.
fn holds_only_model_files(path: &Path) -> Result<bool, CliError> {
    let meta = std::fs::symlink_metadata(path).map_err(CliError::read(path))?;
    if !meta.is_dir() {
        return Ok(false);
    }
    for entry in std::fs::read_dir(path).map_err(CliError::read(path))? {
        let entry = entry.map_err(CliError::read(path))?;
        let is_file = entry.file_type().map_err(CliError::read(path))?.is_file();
        let name = entry.file_name();
        if !is_file || !MODEL_FILES.iter().any(|f| name == *f) {
            return Ok(false);
        }
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_dir::TestDir;

    fn dir(name: &str) -> TestDir {
        TestDir::new(&format!("model-folder-{name}"))
    }

    fn build(beside: &Path, models: &[&str]) -> TempDir {
        let built = TempDir::beside(beside).unwrap();
        for m in models {
            std::fs::create_dir(built.path().join(m)).unwrap();
            std::fs::write(built.path().join(m).join("images.bin"), m).unwrap();
        }
        built
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn models_replace_only_clatchs_own_earlier_models() {
        let root = dir("replace");
        let sparse = root.join("sparse");
        let first = ModelFolder::inspect(&sparse, false).unwrap();
        let installed = first.install(&build(&sparse, &["0", "1"])).unwrap();
        assert_eq!(installed, [sparse.join("0"), sparse.join("1")]);
        assert_eq!(listing(&sparse), [MANIFEST, "0", "1"]);

        // A rerun needs --force; with it, the earlier two give way to the one new model.
        assert!(matches!(
            ModelFolder::inspect(&sparse, false),
            Err(CliError::ModelsExist { .. })
        ));
        let again = ModelFolder::inspect(&sparse, true).unwrap();
        again.install(&build(&sparse, &["0"])).unwrap();
        assert_eq!(listing(&sparse), [MANIFEST, "0"]);
        assert_eq!(std::fs::read(sparse.join("0/images.bin")).unwrap(), b"0");
        assert_eq!(listing(&root), ["sparse"], "no temp left");
    }

    #[test]
    fn nothing_clatch_did_not_install_is_ever_replaced() {
        let root = dir("foreign");
        let sparse = root.join("sparse");
        std::fs::create_dir(&sparse).unwrap();
        // A photo, a text model of COLMAP's own, a note inside one of clatch's models.
        std::fs::write(sparse.join("A.png"), "photo").unwrap();
        let refused = ModelFolder::inspect(&sparse, true).unwrap_err();
        assert!(refused.to_string().contains("A.png"), "{refused}");
        std::fs::remove_file(sparse.join("A.png")).unwrap();

        std::fs::create_dir(sparse.join("0")).unwrap();
        std::fs::write(sparse.join("0/cameras.txt"), "colmap's own").unwrap();
        assert!(
            ModelFolder::inspect(&sparse, true).is_err(),
            "not in the list"
        );
        std::fs::write(sparse.join(MANIFEST), "0\n").unwrap();
        ModelFolder::inspect(&sparse, true).unwrap();
        std::fs::write(sparse.join("0/notes.md"), "mine").unwrap();
        assert!(
            ModelFolder::inspect(&sparse, true).is_err(),
            "a note inside"
        );
        // A list naming `..` or a photo's name takes nothing.
        std::fs::write(sparse.join(MANIFEST), "..\nA.png\n").unwrap();
        assert!(ModelFolder::inspect(&sparse, true).is_err());
        assert_eq!(
            std::fs::read(sparse.join("0/notes.md")).unwrap(),
            b"mine",
            "untouched"
        );
    }

    #[test]
    fn what_appears_during_the_run_is_kept_and_refused() {
        let root = dir("late");
        let sparse = root.join("sparse");
        let folder = ModelFolder::inspect(&sparse, false).unwrap();
        std::fs::create_dir_all(sparse.join("0")).unwrap();
        std::fs::write(sparse.join("0/mine.txt"), "late").unwrap();
        let built = build(&sparse, &["0"]);
        assert!(folder.install(&built).is_err());
        assert_eq!(std::fs::read(sparse.join("0/mine.txt")).unwrap(), b"late");
        assert!(
            built.path().join("0/images.bin").exists(),
            "new model kept aside"
        );
    }

    #[test]
    fn an_images_folder_where_clatch_writes_is_refused() {
        let root = dir("images");
        let sparse = root.join("ws/sparse");
        std::fs::create_dir_all(&sparse).unwrap();
        assert!(check_images_outside(&sparse, &root.join("ws"), &sparse).is_err());
        assert!(check_images_outside(&sparse.join("a/b"), &root.join("ws"), &sparse).is_err());
        let ws = root.join("ws");
        assert!(check_images_outside(&ws, &ws, &sparse).is_err());
        assert!(check_images_outside(&ws.join("./sparse/../"), &ws, &sparse).is_err());
        // Through a link too.
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&sparse, root.join("link")).unwrap();
            assert!(check_images_outside(&root.join("link"), &ws, &sparse).is_err());
        }
        // COLMAP's own layout, photos beside the model folder, is fine.
        std::fs::create_dir_all(ws.join("images")).unwrap();
        check_images_outside(&ws.join("images"), &ws, &sparse).unwrap();
        check_images_outside(&root.join("elsewhere"), &ws, &sparse).unwrap();
    }

    #[test]
    fn a_file_named_sparse_is_refused() {
        let root = dir("file");
        std::fs::write(root.join("sparse"), "mine").unwrap();
        assert!(ModelFolder::inspect(&root.join("sparse"), true).is_err());
        assert_eq!(std::fs::read(root.join("sparse")).unwrap(), b"mine");
    }
}
