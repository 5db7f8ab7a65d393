//! A fresh temporary folder for one unit test, removed when the test ends (passing or not).

use std::path::{Path, PathBuf};

pub struct TestDir(PathBuf);

impl TestDir {
    /// `clatch-<what>-<pid>` in the temporary directory, emptied first.
    pub fn new(what: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("clatch-{what}-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}
