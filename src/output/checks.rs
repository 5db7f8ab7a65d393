//! The checks of output paths before any work: each is a file clatch may replace, and none is the
//! same file as an input or as another output.

use std::path::{Path, PathBuf};

use crate::output::OutputError;

/// What a path that is not a regular file is, in words ("a FIFO", "a device", "a socket", "a
/// folder"), for messages that refuse it as an input or an output.
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if meta.is_dir() {
        "a folder"
    } else {
        "not a file"
    }
}

/// Refuses an output path that exists and is not a regular file (a folder, a device: renaming onto
/// it would replace it), or that has no file name.
pub fn check_writable(path: &Path) -> Result<(), OutputError> {
    let refuse = |reason: String| OutputError::OutputPath {
        path: path.to_path_buf(),
        reason,
    };
    if path.file_name().is_none() || ends_with_separator(path) {
        return Err(refuse("the path names a folder, not a file".into()));
    }
    match std::fs::metadata(path) {
        Ok(meta) if !meta.is_file() => Err(refuse(format!(
            "it is {}, not a regular file",
            file_kind(&meta)
        ))),
        _ => check_folder_of(path, false),
    }
}

/// [`check_writable`] for an output whose folder the run creates: folders missing on its path are
/// allowed, and the nearest one that exists must be a writable folder.
pub fn check_writable_in_new_folder(path: &Path) -> Result<(), OutputError> {
    if path.file_name().is_none() || ends_with_separator(path) {
        return Err(OutputError::OutputPath {
            path: path.to_path_buf(),
            reason: "the path names a folder, not a file".into(),
        });
    }
    match std::fs::metadata(path) {
        Ok(meta) if !meta.is_file() => Err(OutputError::OutputPath {
            path: path.to_path_buf(),
            reason: format!("it is {}, not a regular file", file_kind(&meta)),
        }),
        _ => check_folder_of(path, true),
    }
}

/// Refuses, before any work, an output whose folder cannot take it: the folder is missing (unless
/// `create_missing`: then its nearest existing ancestor is checked), is a file, or is not writable
/// (a file is created there and removed again: `.probe.clatch-PID-N.tmp`, the pattern of every
/// temporary file clatch writes). The error names the folder at fault.
fn check_folder_of(path: &Path, create_missing: bool) -> Result<(), OutputError> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut existing = folder;
    let meta = loop {
        let gone = match std::fs::metadata(existing) {
            Ok(meta) => break meta,
            // Not a directory: an ancestor is a file, found on the way up.
            Err(e) => match e.kind() {
                std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory => e,
                _ => return Err(OutputError::write(existing)(e)),
            },
        };
        existing = match existing.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            Some(_) if existing != Path::new(".") => Path::new("."),
            _ => return Err(OutputError::write(existing)(gone)),
        };
    };
    if !meta.is_dir() {
        return Err(OutputError::OutputPath {
            path: existing.to_path_buf(),
            reason: format!(
                "it is {}, not a folder, so {} cannot be written in it",
                if meta.is_file() {
                    "a file"
                } else {
                    file_kind(&meta)
                },
                path.display()
            ),
        });
    }
    if existing != folder && !create_missing {
        return Err(OutputError::OutputPath {
            path: folder.to_path_buf(),
            reason: "the folder does not exist; create it first".into(),
        });
    }
    // Probed once per folder and process: a batch checks thousands of outputs in one folder.
    static WRITABLE: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let mut writable = WRITABLE.lock().unwrap_or_else(|p| p.into_inner());
    if writable.iter().any(|f| f == existing) {
        return Ok(());
    }
    let probe = super::staged::create_temp_beside(&existing.join("probe")).map_err(|_| {
        OutputError::OutputPath {
            path: existing.to_path_buf(),
            reason: "the folder is not writable".into(),
        }
    })?;
    std::fs::remove_file(&probe).ok();
    super::staged::forget_temporary(&probe);
    writable.push(existing.to_path_buf());
    Ok(())
}

/// Whether the path is written with a trailing separator (`out/`).
pub fn ends_with_separator(path: &Path) -> bool {
    path.as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator)
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
) -> Result<(), OutputError> {
    let inputs: Vec<_> = inputs.iter().map(|&(r, p)| (r, p, identity(p))).collect();
    let mut seen: Vec<(&'static str, &Path, Identity)> = Vec::new();
    for &(role, path) in outputs {
        let id = identity(path);
        let clash = inputs
            .iter()
            .chain(seen.iter())
            .find(|(_, _, other)| *other == id);
        if let Some(&(other_role, other, _)) = clash {
            return Err(OutputError::OutputClash {
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
    use crate::output::staged::tests::test_dir;

    #[cfg(unix)]
    #[test]
    fn outputs_naming_an_input_or_each_other_are_refused() {
        let d = test_dir("clash");
        let input = d.join("in.png");
        std::fs::write(&input, "x").unwrap();
        let link = d.join("link.png");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let inputs = [("image A", input.as_path())];
        let clash = |outputs: &[(&'static str, &Path)]| check_distinct(&inputs, outputs);
        assert!(matches!(
            clash(&[("picture", &input)]),
            Err(OutputError::OutputClash {
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
            Err(OutputError::OutputClash {
                role: "CSV",
                other_role: "picture",
                ..
            })
        ));
        assert!(clash(&[("picture", &d.join("p.png")), ("CSV", &new)]).is_ok());
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn folders_and_devices_are_not_output_files() {
        let d = test_dir("kinds");
        assert!(check_writable(&d).is_err());
        assert!(check_writable(Path::new("out/")).is_err());
        #[cfg(unix)]
        assert!(check_writable(Path::new("/dev/null")).is_err());
        assert!(check_writable(&d.join("new.png")).is_ok());
        std::fs::remove_dir_all(&d).ok();
    }
}
