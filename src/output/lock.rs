//! Exclusive locks on what a run writes, so that two runs never write one database or workspace at
//! once: the second is refused with [`OutputError::Locked`], naming the process that holds the lock.

use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crate::output::OutputError;

/// An exclusive lock on an output (a file or a folder) held by this process: the lock file
/// `.NAME.clatch-lock` beside it, locked with the operating system's advisory file lock (released
/// by the kernel when the process ends, however it ends) and holding this process's id. The lock
/// file is removed when the last clone is dropped.
#[derive(Clone, Debug)]
pub struct OutputLock(Arc<Held>);

#[derive(Debug)]
struct Held {
    target: PathBuf,
    path: PathBuf,
    file: File,
}

impl OutputLock {
    /// Locks `target`, whose folder must exist; an error naming the holder if another process
    /// (or another lock of this one) holds it.
    pub fn acquire(target: &Path) -> Result<Self, OutputError> {
        let path = lock_path(target);
        // A holder that ends removes the lock file: a file opened just before that is locked by
        // no one else, so the lock taken is checked to still be the file at `path`.
        for _ in 0..16 {
            // Only clatch's own lock file is ever opened: never a link, a folder, or a file of the
            // user's that happens to bear the name (it would be truncated, then removed).
            if let Ok(meta) = std::fs::symlink_metadata(&path)
                && (!meta.is_file() || !holds_a_pid(&path))
            {
                return Err(OutputError::OutputPath {
                    path: path.clone(),
                    reason: "it is not a clatch lock file (clatch keeps its lock there); move it"
                        .into(),
                });
            }
            // Made and registered together, never once the process is ending (its handler removes
            // the registered lock files).
            let opened = super::staged::while_open(|_| {
                let file = File::options()
                    .read(true)
                    .write(true)
                    .create(true)
                    .truncate(false)
                    .open(&path)?;
                let locked = file.try_lock();
                if locked.is_ok() {
                    HELD.lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .push(path.clone());
                }
                Ok::<_, std::io::Error>((file, locked))
            });
            let (mut file, locked) = opened.map_err(OutputError::write(&path))?;
            match locked {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    let mut text = String::new();
                    file.read_to_string(&mut text).ok();
                    return Err(OutputError::Locked {
                        path: target.to_path_buf(),
                        holder: text.trim().parse().ok(),
                        lock: path,
                    });
                }
                Err(std::fs::TryLockError::Error(source)) => {
                    return Err(OutputError::write(&path)(source));
                }
            }
            if !same_file(&file, &path) {
                forget_held(&path);
                continue;
            }
            file.set_len(0).map_err(OutputError::write(&path))?;
            file.rewind().map_err(OutputError::write(&path))?;
            writeln!(file, "{}", std::process::id()).map_err(OutputError::write(&path))?;
            return Ok(Self(Arc::new(Held {
                target: target.to_path_buf(),
                path,
                file,
            })));
        }
        Err(OutputError::OutputPath {
            path: path.clone(),
            reason: "its lock file keeps being replaced by other runs".into(),
        })
    }

    /// What is locked.
    pub fn target(&self) -> &Path {
        &self.0.target
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        // Removed while still locked, so no other run can lock this file once it is gone.
        std::fs::remove_file(&self.path).ok();
        self.file.unlock().ok();
        forget_held(&self.path);
    }
}

fn forget_held(path: &Path) {
    let mut held = HELD.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(i) = held.iter().position(|p| p == path) {
        held.swap_remove(i);
    }
}

/// The lock files this process holds.
static HELD: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Removes the lock files this process holds (the process ends next; the system releases the locks).
pub(crate) fn remove_held_locks() {
    for path in std::mem::take(&mut *HELD.lock().unwrap_or_else(|p| p.into_inner())) {
        std::fs::remove_file(path).ok();
    }
}

/// Whether `path` is empty or holds a process id, as clatch's lock files do.
fn holds_a_pid(path: &Path) -> bool {
    let mut text = String::new();
    let read = File::open(path).and_then(|f| f.take(64).read_to_string(&mut text));
    read.is_ok() && text.trim().bytes().all(|b| b.is_ascii_digit())
}

/// `.NAME.clatch-lock` beside `target`.
pub fn lock_path(target: &Path) -> PathBuf {
    let name = target.file_name().unwrap_or_default().to_string_lossy();
    let folder = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    folder.join(format!(".{name}.clatch-lock"))
}

fn same_file(file: &File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (file.metadata(), std::fs::metadata(path)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (file, path);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::staged::tests::test_dir;

    #[test]
    fn a_second_lock_is_refused_naming_the_holder_and_the_file_goes_with_the_last() {
        let d = test_dir("lock");
        let target = d.join("out.db");
        let lock = OutputLock::acquire(&target).unwrap();
        let e = OutputLock::acquire(&target).unwrap_err();
        assert!(
            matches!(e, OutputError::Locked { holder: Some(pid), .. } if pid == std::process::id()),
            "{e}"
        );
        assert!(e.to_string().contains("out.db"), "{e}");
        let clone = lock.clone();
        drop(lock);
        assert!(OutputLock::acquire(&target).is_err(), "a clone holds it");
        drop(clone);
        assert!(!lock_path(&target).exists());
        drop(OutputLock::acquire(&target).unwrap());
        std::fs::remove_dir_all(&d).ok();
    }

    /// A file of the user's, or a link, that bears the lock file's name is never written or removed.
    #[test]
    fn a_users_file_by_the_lock_files_name_is_left_alone() {
        let d = test_dir("lock-hostile");
        let target = d.join("out.db");
        std::fs::write(lock_path(&target), "my notes").unwrap();
        let e = OutputLock::acquire(&target).unwrap_err();
        assert!(e.to_string().contains("not a clatch lock file"), "{e}");
        assert_eq!(
            std::fs::read_to_string(lock_path(&target)).unwrap(),
            "my notes"
        );
        std::fs::remove_file(lock_path(&target)).unwrap();
        #[cfg(unix)]
        {
            let precious = d.join("precious.txt");
            std::fs::write(&precious, "12345").unwrap();
            std::os::unix::fs::symlink(&precious, lock_path(&target)).unwrap();
            assert!(OutputLock::acquire(&target).is_err());
            assert_eq!(std::fs::read_to_string(&precious).unwrap(), "12345");
            assert!(
                std::fs::symlink_metadata(lock_path(&target)).is_ok(),
                "the link stays"
            );
        }
        // A stale lock file of a killed run (its pid inside) is taken over and removed after.
        std::fs::remove_file(lock_path(&target)).ok();
        std::fs::write(lock_path(&target), "4194305\n").unwrap();
        drop(OutputLock::acquire(&target).unwrap());
        assert!(!lock_path(&target).exists());
        std::fs::remove_dir_all(&d).ok();
    }
}
