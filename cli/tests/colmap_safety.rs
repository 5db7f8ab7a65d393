//! `clatch colmap` never loses a file: every input is checked before any work and a refused run
//! leaves nothing behind; `--force` replaces the old database only after the new one is complete,
//! and never an input.

mod common;

use std::path::Path;

use common::{assert_refused, photo, str, workdir};

fn write_photos(images: &Path, size: u32) {
    std::fs::create_dir_all(images).unwrap();
    for (i, offset) in [0u32, 40, 80].into_iter().enumerate() {
        photo(size, size, offset)
            .save(images.join(format!("view{i}.png")))
            .unwrap();
    }
}

/// `clatch colmap` on the CPU without COLMAP.
fn colmap(images: &Path, db: &Path, extra: &[&str]) -> std::process::Output {
    colmap_with(images, db, &["--no-colmap"], extra)
}

/// `clatch colmap --images IMAGES --database DB --backend cpu` with `how` and `extra` after.
fn colmap_with(images: &Path, db: &Path, how: &[&str], extra: &[&str]) -> std::process::Output {
    common::colmap_cpu(images, db, &[how, extra].concat())
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

/// A `colmap` stand-in that succeeds: its mapper writes one binary model (`OUT/0/*.bin`) and its
/// model analyzer prints the figures clatch reads.
#[cfg(unix)]
fn succeeding_colmap(dir: &Path) -> std::path::PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let fake = dir.join("fake-colmap");
    std::fs::write(
        &fake,
        "#!/bin/sh\nstep=\"$1\"; shift\ncase \"$step\" in\n\
         mapper) while [ $# -gt 0 ]; do [ \"$1\" = --output_path ] && out=\"$2\"; shift; done\n\
           mkdir -p \"$out/0\" && for f in cameras images points3D; do echo m > \"$out/0/$f.bin\"; done ;;\n\
         model_analyzer) printf 'Registered images: 3\\nPoints: 9\\nMean track length: 2\\nMean reprojection error: 0.5px\\n' ;;\n\
         esac\n",
    )
    .unwrap();
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    fake
}

/// Every file under `dir`, with its bytes, in order.
fn snapshot(dir: &Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push((path.clone(), std::fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

/// A run that succeeds (COLMAP included) removes nothing the user put in the workspace: not photos
/// in its `sparse/` (the images folder there is refused), not a model or notes of the user's, with
/// or without --force; --force replaces only the models clatch installed itself.
#[cfg(unix)]
#[test]
fn a_successful_run_never_removes_what_the_user_put_in_the_workspace() {
    let dir = workdir("colmap-safety", "workspace");
    let fake = succeeding_colmap(&dir);
    let run = |images: &Path, db: &Path, extra: &[&str]| {
        colmap_with(images, db, &["--colmap", str(&fake)], extra)
    };

    // Photos in WORKSPACE/sparse: refused before any work, every photo kept.
    let project = dir.join("p");
    write_photos(&project.join("sparse"), 200);
    let before = snapshot(&project);
    for force in [&[][..], &["--force"][..]] {
        let mut extra = vec!["--workspace", str(&project)];
        extra.extend_from_slice(force);
        let out = run(&project.join("sparse"), &project.join("db.db"), &extra);
        assert_refused(&out, "where clatch writes");
        assert_eq!(snapshot(&project), before, "every photo is still there");
    }

    // A text model and notes of the user's in the default workspace's sparse/.
    let images = dir.join("images");
    write_photos(&images, 200);
    let db = dir.join("out.db");
    let sparse = dir.join("out-colmap/sparse");
    std::fs::create_dir_all(sparse.join("0")).unwrap();
    std::fs::write(sparse.join("0/cameras.txt"), "# the user's model").unwrap();
    std::fs::write(sparse.join("notes.md"), "the user's notes").unwrap();
    let before = snapshot(&sparse);
    for force in [&[][..], &["--force"][..]] {
        let out = run(&images, &db, force);
        assert_refused(&out, "which clatch did not write");
        assert_eq!(snapshot(&sparse), before, "the user's files are kept");
        assert!(!db.exists());
    }

    // Once they are gone, a run installs its model; a rerun needs --force and replaces only it.
    std::fs::remove_dir_all(&sparse).unwrap();
    let out = run(&images, &db, &[]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(sparse.join("0/images.bin").exists());
    assert!(String::from_utf8_lossy(&out.stdout).contains("registered"));
    assert_refused(&run(&images, &db, &[]), "already");
    let out = run(&images, &db, &["--force"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    // A note the user adds beside clatch's model, or inside it, stops the next --force run.
    for note in [sparse.join("mine.txt"), sparse.join("0/mine.txt")] {
        std::fs::write(&note, "keep me").unwrap();
        let before = snapshot(&dir.join("out-colmap"));
        assert_refused(
            &run(&images, &db, &["--force"]),
            "which clatch did not write",
        );
        assert_eq!(snapshot(&dir.join("out-colmap")), before);
        std::fs::remove_file(&note).unwrap();
    }
}
