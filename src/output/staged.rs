//! Temporary files and folders beside their final paths, renamed into place together or removed.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

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

    /// Renames every temporary file onto its final path (replacing an older file there). An
    /// interruption ([`remove_temporaries`]) waits until every rename is done.
    pub fn commit(mut self) -> Result<(), OutputError> {
        let _whole = Uninterrupted::new();
        for (temp, path) in std::mem::take(&mut self.files) {
            let renamed = std::fs::rename(&temp, &path);
            forget_temporary(&temp);
            if let Err(source) = renamed {
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
            remove_temporary(temp);
            forget_temporary(temp);
        }
    }
}

/// SQLite's side files of a database at a temporary path (a run interrupted while it, or COLMAP, had
/// the database open leaves them).
const SQLITE_SIDE_FILES: [&str; 3] = ["-journal", "-wal", "-shm"];

/// Removes one temporary file or folder of this process, and SQLite's side files of it.
fn remove_temporary(temp: &Path) {
    match std::fs::symlink_metadata(temp) {
        Ok(meta) if meta.is_dir() => {
            std::fs::remove_dir_all(temp).ok();
        }
        Ok(_) => {
            std::fs::remove_file(temp).ok();
        }
        Err(_) => {}
    }
    for side in SQLITE_SIDE_FILES {
        let mut path = temp.as_os_str().to_owned();
        path.push(side);
        std::fs::remove_file(path).ok();
    }
}

/// The temporary files and folders this process has made and not yet renamed or removed.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Renames in progress that an interruption must let finish ([`Uninterrupted`]).
static UNINTERRUPTED: AtomicUsize = AtomicUsize::new(0);

/// Set by [`remove_temporaries`]: the process is ending, and no thread may make another file.
static CLOSING: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Runs `make` (which creates a file of this process's and registers it) unless the process is
/// ending: then the thread waits for the exit instead, so that no file is made after
/// [`remove_temporaries`] collected the list.
pub(crate) fn while_open<T>(make: impl FnOnce(&mut Vec<PathBuf>) -> T) -> T {
    let mut all = TEMPORARIES.lock().unwrap_or_else(|p| p.into_inner());
    // A group of renames under way ([`Uninterrupted`]) finishes, with the files it needs.
    if CLOSING.load(Ordering::SeqCst) && IN_SECTION.get() == 0 {
        drop(all);
        loop {
            std::thread::park();
        }
    }
    make(&mut all)
}

/// Forgets a temporary path (renamed into place, or removed).
pub(crate) fn forget_temporary(path: &Path) {
    let mut all = TEMPORARIES.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(i) = all.iter().rposition(|p| p == path) {
        all.swap_remove(i);
    }
}

/// While one is alive, [`remove_temporaries`] waits: a group of renames (a [`Staged::commit`], the
/// installation of COLMAP models) is never cut half-way by an interruption. Not `Send`: a section
/// belongs to the thread that opened it (which may still make the files it needs meanwhile).
#[derive(Debug)]
pub struct Uninterrupted(std::marker::PhantomData<*const ()>);

impl Uninterrupted {
    /// Holds [`remove_temporaries`] off until the value is dropped.
    pub fn new() -> Self {
        // Counted under the gate: once the process is ending, no group of renames starts.
        while_open(|_| UNINTERRUPTED.fetch_add(1, Ordering::SeqCst));
        IN_SECTION.set(IN_SECTION.get() + 1);
        Self(std::marker::PhantomData)
    }
}

impl Default for Uninterrupted {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for Uninterrupted {
    fn drop(&mut self) {
        IN_SECTION.set(IN_SECTION.get() - 1);
        UNINTERRUPTED.fetch_sub(1, Ordering::SeqCst);
    }
}

thread_local! {
    /// [`Uninterrupted`] sections this thread is in.
    static IN_SECTION: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Removes every temporary file and folder this process has made and not yet renamed into place
/// (with SQLite's side files of a temporary database) and every lock it holds, for a handler of
/// SIGINT or SIGTERM that ends the process next: no `.NAME.clatch-PID-N.tmp` is left behind.
/// Waits (up to 30 s) for renames in progress ([`Uninterrupted`]) to finish first. Only paths this
/// process created are touched.
pub fn remove_temporaries() {
    {
        let _all = TEMPORARIES.lock().unwrap_or_else(|p| p.into_inner());
        CLOSING.store(true, Ordering::SeqCst);
    }
    // No group of renames starts any more; those under way finish.
    let began = std::time::Instant::now();
    while UNINTERRUPTED.load(Ordering::SeqCst) > 0 && began.elapsed().as_secs() < 30 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    remove_temporaries_where(|_| true);
    super::lock::remove_held_locks();
}

/// Removes this process's temporaries for which `chosen` holds (the tests' own only).
fn remove_temporaries_where(chosen: impl Fn(&Path) -> bool) {
    let mine: Vec<PathBuf> = {
        let mut all = TEMPORARIES.lock().unwrap_or_else(|p| p.into_inner());
        let (mine, others) = std::mem::take(&mut *all)
            .into_iter()
            .partition(|p| chosen(p));
        *all = others;
        mine
    };
    for temp in &mine {
        remove_temporary(temp);
    }
}

/// Folders already swept by this process.
static SWEPT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Removes, once per folder and process, what runs that no longer exist left in `folder`: only
/// entries named exactly as clatch names its temporary files and folders,
/// `.NAME.clatch-PID-N.tmp` (and SQLite's `-journal`, `-wal`, `-shm` of them), whose `PID` is not a
/// running process; never a link, never anything else. Where running processes cannot be listed
/// (no `/proc`), nothing is removed.
pub fn sweep_stale_temporaries(folder: &Path) {
    {
        let mut swept = SWEPT.lock().unwrap_or_else(|p| p.into_inner());
        if swept.iter().any(|f| f == folder) {
            return;
        }
        swept.push(folder.to_path_buf());
    }
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(folder) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(temporary_pid) else {
            continue;
        };
        if pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists() {
            continue;
        }
        let path = entry.path();
        match std::fs::symlink_metadata(&path) {
            Ok(meta) if meta.file_type().is_symlink() => {}
            Ok(meta) if meta.is_dir() => {
                std::fs::remove_dir_all(&path).ok();
            }
            Ok(_) => {
                std::fs::remove_file(&path).ok();
            }
            Err(_) => {}
        }
    }
}

/// The process id in a name of clatch's temporary pattern `.NAME.clatch-PID-N.tmp` (or one of
/// SQLite's side files of it), `None` for any other name.
pub fn temporary_pid(name: &str) -> Option<u32> {
    let name = SQLITE_SIDE_FILES
        .iter()
        .find_map(|side| name.strip_suffix(side))
        .unwrap_or(name);
    let rest = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (stem, numbers) = rest.rsplit_once(".clatch-")?;
    let (pid, n) = numbers.split_once('-')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if stem.is_empty() || !digits(pid) || !digits(n) {
        return None;
    }
    pid.parse().ok()
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
            forget_temporary(temp);
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
    sweep_stale_temporaries(folder);
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = folder.join(format!(".{name}.clatch-{}-{n}.tmp", std::process::id()));
        let made = while_open(|all| {
            let made = File::options().write(true).create_new(true).open(&temp);
            if made.is_ok() {
                all.push(temp.clone());
            }
            made
        });
        match made {
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
    fn only_clatchs_own_temporary_names_are_recognised() {
        for (name, pid) in [
            (".out.db.clatch-4242-0.tmp", Some(4242)),
            (".out.db.clatch-4242-17.tmp-wal", Some(4242)),
            (".out.db.clatch-4242-17.tmp-shm", Some(4242)),
            (".a.b.clatch-1-2.tmp-journal", Some(1)),
            ("out.db.clatch-4242-0.tmp", None),
            (".out.db.clatch-4242-0.tmp.bak", None),
            (".out.db.clatch-42x-0.tmp", None),
            (".out.db.clatch-4242.tmp", None),
            (".clatch-4242-0.tmp", None),
            (".out.db.clatch-4242-0.tmp-wal2", None),
            ("notes.txt", None),
        ] {
            assert_eq!(temporary_pid(name), pid, "{name}");
        }
    }

    /// The sweep removes what a killed run left, and nothing else: not a file of a running process
    /// (this one, or process 1), not a name that only looks like clatch's, not a link named exactly
    /// like a stale temporary file (nor what it points to), not the user's files.
    #[cfg(target_os = "linux")]
    #[test]
    fn the_sweep_removes_only_stale_temporaries_of_dead_processes() {
        let d = test_dir("sweep");
        // A process id that is not running: the largest a pid can be, plus one.
        let dead = std::fs::read_to_string("/proc/sys/kernel/pid_max")
            .ok()
            .and_then(|s| s.trim().parse::<u32>().ok())
            .unwrap_or(4_194_304)
            + 1;
        let me = std::process::id();
        let stale = [
            format!(".out.db.clatch-{dead}-0.tmp"),
            format!(".out.db.clatch-{dead}-0.tmp-wal"),
            format!(".out.db.clatch-{dead}-0.tmp-shm"),
        ];
        for name in &stale {
            std::fs::write(d.join(name), "stale").unwrap();
        }
        let model = d.join(format!(".sparse.clatch-{dead}-3.tmp"));
        std::fs::create_dir_all(model.join("0")).unwrap();
        std::fs::write(model.join("0/images.bin"), "m").unwrap();
        let kept = [
            format!(".out.db.clatch-{me}-0.tmp"),
            ".out.db.clatch-1-0.tmp".to_owned(),
            format!("out.db.clatch-{dead}-0.tmp"),
            format!(".out.db.clatch-{dead}-0.tmp.bak"),
            format!(".notes.clatch-{dead}-x.tmp"),
            "photo.jpg".to_owned(),
        ];
        for name in &kept {
            std::fs::write(d.join(name), "keep").unwrap();
        }
        let target = d.join("precious.txt");
        std::fs::write(&target, "the user's").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(&target, d.join(format!(".x.clatch-{dead}-9.tmp"))).unwrap();
        sweep_stale_temporaries(&d);
        let mut want: Vec<String> = kept.to_vec();
        want.push("precious.txt".into());
        want.push(format!(".x.clatch-{dead}-9.tmp"));
        want.sort();
        assert_eq!(listing(&d), want);
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "the user's");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn an_interruption_removes_this_process_temporaries() {
        let d = test_dir("interrupt");
        std::fs::write(d.join("a.txt"), "old").unwrap();
        let mut staged = Staged::new();
        let temp = staged
            .write(&d.join("a.txt"), |w| w.write_all(b"new"))
            .unwrap();
        let mut side = temp.clone().into_os_string();
        side.push("-wal");
        std::fs::write(&side, "wal").unwrap();
        let folder = TempDir::beside(&d.join("sparse")).unwrap();
        std::fs::create_dir(folder.path().join("0")).unwrap();
        // What `remove_temporaries` does, for this test's folder only (other tests run meanwhile).
        remove_temporaries_where(|p| p.starts_with(&d));
        assert_eq!(listing(&d), ["a.txt"]);
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "old");
        std::mem::forget(staged);
        std::mem::forget(folder);
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
