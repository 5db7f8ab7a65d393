//! What the repository's own text may not say: a path outside the repository (a reader's clone has
//! none of them) or an issue number of a tracker no reader can open. Bench logs (`docs/bench/**/*.txt`
//! and the like) are records of what a tool printed and are left as they are.

use std::path::{Path, PathBuf};

const SKIPPED_FOLDERS: &[&str] = &[
    "target",
    ".git",
    ".venv",
    "node_modules",
    "bench",
    ".gpu",
    "wheels",
];
const TEXT_EXTENSIONS: &[&str] = &["rs", "md", "py", "pyi", "sh", "toml", "cu", "h", "yml"];

fn text_files(folder: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        let Ok(kind) = entry.file_type() else {
            continue;
        };
        if kind.is_dir() {
            if !SKIPPED_FOLDERS.contains(&name.as_str()) && !name.starts_with('.') || name == ".ci"
            {
                text_files(&path, out);
            }
        } else if kind.is_file()
            && path
                .extension()
                .is_some_and(|e| TEXT_EXTENSIONS.contains(&e.to_string_lossy().as_ref()))
        {
            out.push(path);
        }
    }
}

/// "issue 28", "Issue #3": a number of this project's tracker. A public project's issue, named with
/// its repository ("rust-lang/docs.rs issue 655"), is one a reader can open.
fn names_an_issue(line: &str) -> bool {
    let lower = line.to_ascii_lowercase();
    lower.match_indices("issue").any(|(at, word)| {
        let rest = lower[at + word.len()..].trim_start_matches([' ', '#']);
        let repository = lower[..at]
            .split_whitespace()
            .last()
            .is_some_and(|w| w.contains('/'));
        rest.starts_with(|c: char| c.is_ascii_digit()) && !repository
    })
}

#[test]
fn no_text_names_a_path_outside_the_repository_or_an_issue_number() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    text_files(root, &mut files);
    assert!(
        files.len() > 50,
        "found only {} files under {}",
        files.len(),
        root.display()
    );
    let this_file = Path::new(file!()).file_name().expect("a file name");
    let mut found = Vec::new();
    for file in files.iter().filter(|f| f.file_name() != Some(this_file)) {
        let Ok(text) = std::fs::read_to_string(file) else {
            continue;
        };
        for (number, line) in text.lines().enumerate() {
            if line.contains("../shared") || line.contains("/work/") || names_an_issue(line) {
                found.push(format!(
                    "{}:{}: {}",
                    file.display(),
                    number + 1,
                    line.trim()
                ));
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}

#[test]
fn issue_numbers_are_recognised() {
    assert!(names_an_issue("fixed in issue 28"));
    assert!(names_an_issue("see Issue #3"));
    assert!(!names_an_issue("an issue with the tracker"));
    assert!(!names_an_issue("issues of 2026"));
    assert!(!names_an_issue(
        "its maintainers, rust-lang/docs.rs issue 655"
    ));
}
