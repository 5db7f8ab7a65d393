//! `clatch colmap` never loses a file: every input is checked before any work and a refused run
//! leaves nothing behind; `--force` replaces the old database only after the new one is complete,
//! and never an input.

mod common;

use std::path::Path;

use common::{assert_refused, clatch, photo, str, workdir};

fn write_photos(images: &Path, size: u32) {
    std::fs::create_dir_all(images).unwrap();
    for (i, offset) in [0u32, 40, 80].into_iter().enumerate() {
        photo(size, size, offset)
            .save(images.join(format!("view{i}.png")))
            .unwrap();
    }
}

fn colmap(images: &Path, db: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "colmap",
        "--images",
        str(images),
        "--database",
        str(db),
        "--backend",
        "cpu",
        "--no-colmap",
    ];
    args.extend_from_slice(extra);
    clatch(&args)
}

#[test]
fn force_replaces_the_database_only_after_success() {
    let dir = workdir("colmap-safety", "force");
    let images = dir.join("images");
    write_photos(&images, 200);
    let db = dir.join("out.db");
    assert!(colmap(&images, &db, &[]).status.success());
    let old = std::fs::read(&db).unwrap();

    std::fs::write(images.join("broken.jpg"), b"not a jpeg").unwrap();
    let out = colmap(&images, &db, &["--force"]);
    assert_refused(&out, "broken.jpg");
    assert_eq!(std::fs::read(&db).unwrap(), old, "the old database is kept");

    std::fs::remove_file(images.join("broken.jpg")).unwrap();
    let out = colmap(&images, &db, &["--force"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let sql = rusqlite::Connection::open(&db).unwrap();
    let n: i64 = sql
        .query_row("SELECT COUNT(*) FROM images", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 3);
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["images", "out-colmap", "out.db"],
        "no temporary file left"
    );
}

#[test]
fn a_database_naming_a_photo_is_refused_even_with_force() {
    let dir = workdir("colmap-safety", "db-photo");
    let images = dir.join("images");
    write_photos(&images, 200);
    let photo_path = images.join("view1.png");
    let before = std::fs::read(&photo_path).unwrap();
    let out = colmap(&images, &photo_path, &["--force"]);
    assert_refused(&out, "the database");
    assert!(common::stderr(&out).contains("is the same file as the image"));
    assert_eq!(
        std::fs::read(&photo_path).unwrap(),
        before,
        "the photo is untouched"
    );
}

#[test]
fn bad_inputs_are_refused_before_any_work_and_leave_nothing_behind() {
    let dir = workdir("colmap-safety", "inputs");
    let images = dir.join("images");
    write_photos(&images, 200);
    let db = dir.join("out.db");
    let k = dir.join("K.txt");
    let refused = |extra: &[&str], needle: &str| {
        let out = colmap(&images, &db, extra);
        assert_refused(&out, needle);
        assert!(!db.exists(), "{needle}: no database left");
        assert!(
            !dir.join("out-colmap").exists(),
            "{needle}: no workspace left"
        );
    };
    for (text, needle) in [
        ("300 0 100 0 300 100 0 0", "K needs 9 numbers"),
        ("nan 0 100 0 300 100 0 0 1", "finite"),
        ("-300 0 100 0 300 100 0 0 1", "positive"),
        ("300 2 100 0 300 100 0 0 1", "K must be"),
    ] {
        std::fs::write(&k, text).unwrap();
        refused(&["--camera-k", str(&k)], needle);
    }
    std::fs::write(&k, "300 0 100 0 300 100 0 0 1").unwrap();
    photo(240, 200, 0).save(images.join("view3.png")).unwrap();
    refused(
        &["--camera-k", str(&k)],
        "one camera matrix needs one image size",
    );
    std::fs::remove_file(images.join("view3.png")).unwrap();
    photo(200, 200, 10)
        .save(images.join("my photo.png"))
        .unwrap();
    refused(&[], "whitespace");
    std::fs::remove_file(images.join("my photo.png")).unwrap();
    // Corrected, the same run succeeds (an empty database no longer blocks it).
    let out = colmap(&images, &db, &["--camera-k", str(&k)]);
    assert!(out.status.success(), "{}", common::stderr(&out));
}
