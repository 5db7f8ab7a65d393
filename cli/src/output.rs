//! Writing outputs without losing anything: each file goes to a temporary file in its final folder and
//! is renamed into place only when every output of the command is complete; an output that names an
//! input, or another output, is refused before any work.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::CliError;

/// Temporary files of one command, renamed into place together by [`Staged::commit`]; those not
/// committed are removed when the value is dropped (on any error).
#[derive(Default)]
pub struct Staged {
    /// `(temporary, final)` pairs, in the order they were staged.
    files: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    /// No file staged yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Writes `path`'s future content to a new temporary file beside it, flushed to disk; returns the
    /// temporary file's path (for a program that reads the file before it is committed).
    pub fn write(
        &mut self,
        path: &Path,
        write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
    ) -> Result<PathBuf, CliError> {
        let temp = self.reserve(path)?;
        let file = File::options()
            .write(true)
            .truncate(true)
            .open(&temp)
            .map_err(CliError::write(&temp))?;
        let mut out = BufWriter::new(file);
        write(&mut out).map_err(CliError::write(path))?;
        let file = out
            .into_inner()
            .map_err(|e| CliError::write(path)(e.into_error()))?;
        file.sync_all().map_err(CliError::write(path))?;
        Ok(temp)
    }

    /// A new, empty temporary file beside `path`, to be renamed onto `path` by [`Staged::commit`]
    /// (for writers that open the file themselves, as SQLite does).
    pub fn reserve(&mut self, path: &Path) -> Result<PathBuf, CliError> {
        check_writable(path)?;
        let temp = create_temp_beside(path)?;
        self.files.push((temp.clone(), path.to_path_buf()));
        Ok(temp)
    }

    /// Renames every temporary file onto its final path (replacing an older file there).
    pub fn commit(mut self) -> Result<(), CliError> {
        for (temp, path) in std::mem::take(&mut self.files) {
            if let Err(source) = std::fs::rename(&temp, &path) {
                std::fs::remove_file(&temp).ok();
                return Err(CliError::write(&path)(source));
            }
        }
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        for (temp, _) in &self.files {
            std::fs::remove_file(temp).ok();
            // SQLite's rollback journal, if a database was left open by an error.
            let mut journal = temp.clone().into_os_string();
            journal.push("-journal");
            std::fs::remove_file(journal).ok();
        }
    }
}

/// Writes one file through a temporary file renamed into place.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), CliError> {
    let mut staged = Staged::new();
    staged.write(path, write)?;
    staged.commit()
}

/// A folder of this run's own (`.NAME.clatch-PID-N.tmp` beside `path`), removed with its content when
/// dropped (what was moved out of it first is kept).
pub struct TempDir {
    path: Option<PathBuf>,
}

impl TempDir {
    /// Creates the folder beside `path`.
    pub fn beside(path: &Path) -> Result<Self, CliError> {
        let temp = create_temp_beside(path)?;
        std::fs::remove_file(&temp).map_err(CliError::write(&temp))?;
        std::fs::create_dir(&temp).map_err(CliError::write(&temp))?;
        Ok(Self { path: Some(temp) })
    }

    /// The folder's current path.
    pub fn path(&self) -> &Path {
        self.path.as_deref().unwrap_or(Path::new(""))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if let Some(temp) = &self.path {
            std::fs::remove_dir_all(temp).ok();
        }
    }
}

/// Refuses an output path that exists and is not a regular file (a folder, a device: renaming onto
/// it would replace it), or that has no file name.
pub fn check_writable(path: &Path) -> Result<(), CliError> {
    let refuse = |reason: String| CliError::OutputPath {
        path: path.to_path_buf(),
        reason,
    };
    if path.file_name().is_none() || ends_with_separator(path) {
        return Err(refuse("the path names a folder, not a file".into()));
    }
    match std::fs::metadata(path) {
        Ok(meta) if !meta.is_file() => Err(refuse(format!(
            "it is {}, not a regular file",
            clatch::decode::file_kind(&meta)
        ))),
        _ => Ok(()),
    }
}

/// Whether the path is written with a trailing separator (`out/`).
pub fn ends_with_separator(path: &Path) -> bool {
    path.as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator)
}

/// A new file `.NAME.clatch-PID-N.tmp` in `path`'s folder (created, so no other run takes it).
fn create_temp_beside(path: &Path) -> Result<PathBuf, CliError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = folder.join(format!(".{name}.clatch-{}-{n}.tmp", std::process::id()));
        match File::options().write(true).create_new(true).open(&temp) {
            Ok(_) => return Ok(temp),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(source) => return Err(CliError::write(path)(source)),
        }
    }
}

/// What a path refers to: the file it names (links followed) when there is one, else the canonical
/// folder and the name.
#[derive(Debug, PartialEq, Eq)]
enum Identity {
    File { device: u64, inode: u64 },
    Path(PathBuf),
}

fn identity(path: &Path) -> Identity {
    if let Ok(meta) = std::fs::metadata(path) {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            return Identity::File {
                device: meta.dev(),
                inode: meta.ino(),
            };
        }
        #[cfg(not(unix))]
        {
            let _ = meta;
            if let Ok(canonical) = std::fs::canonicalize(path) {
                return Identity::Path(canonical);
            }
        }
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let folder = std::fs::canonicalize(folder).unwrap_or_else(|_| folder.to_path_buf());
    Identity::Path(folder.join(path.file_name().unwrap_or_default()))
}

/// Refuses any output that is the same file as an input or as an earlier output (through links
/// too). Each path comes with its role, for the message (`"picture"`, `"image A"`).
pub fn check_distinct(
    inputs: &[(&'static str, &Path)],
    outputs: &[(&'static str, &Path)],
) -> Result<(), CliError> {
    let inputs: Vec<_> = inputs.iter().map(|&(r, p)| (r, p, identity(p))).collect();
    let mut seen: Vec<(&'static str, &Path, Identity)> = Vec::new();
    for &(role, path) in outputs {
        let id = identity(path);
        let clash = inputs
            .iter()
            .chain(seen.iter())
            .find(|(_, _, other)| *other == id);
        if let Some(&(other_role, other, _)) = clash {
            return Err(CliError::OutputClash {
                role,
                path: path.to_path_buf(),
                other_role,
                other: other.to_path_buf(),
            });
        }
        seen.push((role, path, id));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn dir(name: &str) -> crate::test_dir::TestDir {
        crate::test_dir::TestDir::new(&format!("output-{name}"))
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
    fn nothing_replaces_the_old_files_until_commit() {
        let d = dir("commit");
        let (a, b) = (d.join("a.txt"), d.join("b.txt"));
        std::fs::write(&a, "old a").unwrap();
        let mut staged = Staged::new();
        staged.write(&a, |w| w.write_all(b"new a")).unwrap();
        staged.write(&b, |w| w.write_all(b"new b")).unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert!(!b.exists());
        staged.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "new a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b");
        assert_eq!(listing(&d), ["a.txt", "b.txt"], "no temporary file left");
    }

    #[test]
    fn a_failed_write_leaves_the_old_files_and_no_temporary() {
        let d = dir("fail");
        let a = d.join("a.txt");
        std::fs::write(&a, "old a").unwrap();
        let mut staged = Staged::new();
        staged.write(&a, |w| w.write_all(b"new a")).unwrap();
        let e = staged
            .write(&d.join("b.txt"), |_| {
                Err(std::io::Error::other("disk full"))
            })
            .unwrap_err();
        assert!(e.to_string().contains("disk full"), "{e}");
        drop(staged);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert_eq!(listing(&d), ["a.txt"]);
    }

    #[cfg(unix)]
    #[test]
    fn outputs_naming_an_input_or_each_other_are_refused() {
        let d = dir("clash");
        let input = d.join("in.png");
        std::fs::write(&input, "x").unwrap();
        let link = d.join("link.png");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let inputs = [("image A", input.as_path())];
        let clash = |outputs: &[(&'static str, &Path)]| check_distinct(&inputs, outputs);
        assert!(matches!(
            clash(&[("picture", &input)]),
            Err(CliError::OutputClash {
                other_role: "image A",
                ..
            })
        ));
        assert!(clash(&[("picture", &link)]).is_err(), "through a link");
        let dotted = d.join(".").join("in.png");
        assert!(clash(&[("picture", &dotted)]).is_err(), "through ./");
        let new = d.join("new.csv");
        assert!(matches!(
            clash(&[
                ("picture", &new),
                (
                    "CSV",
                    &d.join("..").join(d.file_name().unwrap()).join("new.csv")
                )
            ]),
            Err(CliError::OutputClash {
                role: "CSV",
                other_role: "picture",
                ..
            })
        ));
        assert!(clash(&[("picture", &d.join("p.png")), ("CSV", &new)]).is_ok());
    }

    #[test]
    fn a_temporary_folder_vanishes() {
        let d = dir("tempdir");
        let target = d.join("sparse");
        std::fs::create_dir_all(target.join("new")).unwrap();
        let temp = TempDir::beside(&target).unwrap();
        std::fs::write(temp.path().join("half"), "x").unwrap();
        drop(temp);
        assert_eq!(listing(&d), ["sparse"]);
        assert_eq!(listing(&target), ["new"]);
    }

    #[test]
    fn folders_and_devices_are_not_output_files() {
        let d = dir("kinds");
        assert!(check_writable(&d).is_err());
        assert!(check_writable(Path::new("out/")).is_err());
        #[cfg(unix)]
        assert!(check_writable(Path::new("/dev/null")).is_err());
        assert!(check_writable(&d.join("new.png")).is_ok());
    }
}
