//! Shared helpers of the end-to-end tests: running the binary (with a time limit, so an input that
//! would block fails the test instead of hanging it) and generating images.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A fresh folder for one test, removed when the test ends (passing or not), so that test runs do not
/// pile folders up in the temporary directory.
pub struct WorkDir(PathBuf);

impl std::ops::Deref for WorkDir {
    type Target = PathBuf;
    fn deref(&self) -> &PathBuf {
        &self.0
    }
}

impl AsRef<Path> for WorkDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for WorkDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// A fresh folder for one test.
pub fn workdir(suite: &str, name: &str) -> WorkDir {
    let dir = std::env::temp_dir().join(format!("clatch-{suite}-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    WorkDir(dir)
}

/// Runs `clatch ARGS...`; panics if it runs longer than 60 s (an input that blocks).
pub fn clatch(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_clatch"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            child.kill().ok();
            panic!("clatch {args:?} still runs after 60 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts a clean refusal: exit status 1 (not a signal, not a panic's 101) and `needle` in stderr.
pub fn assert_refused(out: &Output, needle: &str) {
    let e = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(e.contains(needle), "expected {needle:?} in: {e}");
}

/// A `width` x `height` crop of the repository's photograph, offset by `offset` pixels.
pub fn photo(width: u32, height: u32, offset: u32) -> image::GrayImage {
    let photo = image::load_from_memory(include_bytes!("../../../assets/astronaut.png"))
        .expect("the PNG decodes")
        .to_luma8();
    image::GrayImage::from_fn(width, height, |x, y| {
        *photo.get_pixel(x + offset, y + offset)
    })
}

pub fn str(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A real PNG whose IHDR says `width` x `height` (its CRC fixed, so only the size lies).
pub fn lying_png(width: u32, height: u32) -> Vec<u8> {
    let mut png = Vec::new();
    image::GrayImage::new(4, 4)
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png[16..20].copy_from_slice(&width.to_be_bytes());
    png[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

/// `mkfifo PATH`.
#[cfg(unix)]
pub fn mkfifo(path: &Path) {
    assert!(Command::new("mkfifo").arg(path).status().unwrap().success());
}

/// Every name in `dir`, sorted.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// `clatch colmap --images IMAGES --database DB --backend cpu EXTRA...`.
pub fn colmap_cpu(images: &Path, db: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "colmap",
        "--images",
        str(images),
        "--database",
        str(db),
        "--backend",
        "cpu",
    ];
    args.extend_from_slice(extra);
    clatch(&args)
}
