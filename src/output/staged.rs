//! Temporary files and folders beside their final paths, renamed into place together or removed.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::output::OutputError;
use crate::output::checks::check_writable;

/// Temporary files of one run, renamed into place together by [`Staged::commit`]; those not
/// committed are removed when the value is dropped (on any error).
#[derive(Debug, Default)]
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
    ) -> Result<PathBuf, OutputError> {
        let (temp, file) = self.open(path)?;
        let mut out = BufWriter::new(file);
        write(&mut out).map_err(OutputError::write(path))?;
        let file = out
            .into_inner()
            .map_err(|e| OutputError::write(path)(e.into_error()))?;
        file.sync_all().map_err(OutputError::write(path))?;
        Ok(temp)
    }

    /// A new temporary file beside `path`, open for writing, to be renamed onto `path` by
    /// [`Staged::commit`]; and its path.
    pub fn open(&mut self, path: &Path) -> Result<(PathBuf, File), OutputError> {
        let temp = self.reserve(path)?;
        let file = File::options()
            .write(true)
            .truncate(true)
            .open(&temp)
            .map_err(OutputError::write(&temp))?;
        Ok((temp, file))
    }

    /// A new, empty temporary file beside `path`, to be renamed onto `path` by [`Staged::commit`]
    /// (for writers that open the file themselves, as SQLite does).
    pub fn reserve(&mut self, path: &Path) -> Result<PathBuf, OutputError> {
        check_writable(path)?;
        let temp = create_temp_beside(path)?;
        self.files.push((temp.clone(), path.to_path_buf()));
        Ok(temp)
    }

    /// Renames every temporary file onto its final path (replacing an older file there).
    pub fn commit(mut self) -> Result<(), OutputError> {
        for (temp, path) in std::mem::take(&mut self.files) {
            if let Err(source) = std::fs::rename(&temp, &path) {
                std::fs::remove_file(&temp).ok();
                return Err(OutputError::write(&path)(source));
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
) -> Result<(), OutputError> {
    let mut staged = Staged::new();
    staged.write(path, write)?;
    staged.commit()
}

/// A folder of this run's own (`.NAME.clatch-PID-N.tmp` beside `path`), removed with its content when
/// dropped (what was moved out of it first is kept).
#[derive(Debug)]
pub struct TempDir {
    path: Option<PathBuf>,
}

impl TempDir {
    /// Creates the folder beside `path`.
    pub fn beside(path: &Path) -> Result<Self, OutputError> {
        let temp = create_temp_beside(path)?;
        std::fs::remove_file(&temp).map_err(OutputError::write(&temp))?;
        std::fs::create_dir(&temp).map_err(OutputError::write(&temp))?;
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

/// A new file `.NAME.clatch-PID-N.tmp` in `path`'s folder (created, so no other run takes it).
pub(super) fn create_temp_beside(path: &Path) -> Result<PathBuf, OutputError> {
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
            Err(source) => return Err(OutputError::write(path)(source)),
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use std::io::Write;

    /// An empty temporary folder for one unit test (the test removes it once it passed).
    pub fn test_dir(what: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("clatch-output-{what}-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        dir
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
        let d = test_dir("commit");
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
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_failed_write_leaves_the_old_files_and_no_temporary() {
        let d = test_dir("fail");
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
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_temporary_folder_vanishes() {
        let d = test_dir("tempdir");
        let target = d.join("sparse");
        std::fs::create_dir_all(target.join("new")).unwrap();
        let temp = TempDir::beside(&target).unwrap();
        std::fs::write(temp.path().join("half"), "x").unwrap();
        drop(temp);
        assert_eq!(listing(&d), ["sparse"]);
        assert_eq!(listing(&target), ["new"]);
        std::fs::remove_dir_all(&d).ok();
    }
}
