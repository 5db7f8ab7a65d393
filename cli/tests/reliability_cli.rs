//! The command-line findings of the reliability review (issue 28): batches that go on past a bad
//! image, outputs checked before the work, locks, COLMAP failures that keep the work done, plausible
//! camera matrices, corrupt images and decoder allocations, messages that name what the user set.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_refused, clatch, photo, str, workdir};

/// Every file name in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Four photos `p0.png` .. `p3.png` in `dir`.
fn four_photos(dir: &Path) -> Vec<PathBuf> {
    (0..4u32)
        .map(|i| {
            let path = dir.join(format!("p{i}.png"));
            photo(160, 160, 20 * i).save(&path).unwrap();
            path
        })
        .collect()
}

/// A PNG whose header is fine and whose pixel data stops half-way.
fn truncated_png(path: &Path) {
    let mut bytes = Vec::new();
    photo(160, 160, 5)
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(path, bytes).unwrap();
}

fn extract(images: &[&Path], out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["extract"];
    args.extend(images.iter().map(|p| str(p)));
    args.extend(["-o", str(out), "--backend", "cpu"]);
    args.extend_from_slice(extra);
    clatch(&args)
}

/// C2 and H4: a small image in a batch no longer stops it: every good image's three files are
/// written, the failures are listed, the exit status is 1, and the message names no 64x64 "window".
#[test]
fn a_batch_goes_on_past_bad_images_and_lists_them() {
    let dir = workdir("reliability", "keep-going");
    let photos = four_photos(&dir);
    let small = dir.join("small.png");
    photo(50, 50, 0).save(&small).unwrap();
    let broken = dir.join("broken.png");
    truncated_png(&broken);
    let out_dir = dir.join("out");
    let inputs = [photos[0].as_path(), &broken, &photos[1], &small, &photos[2]];
    let out = extract(&inputs, &out_dir, &[]);
    assert_refused(&out, "2 of 5 images failed");
    let e = common::stderr(&out);
    assert!(e.contains("small.png") && e.contains("broken.png"), "{e}");
    assert!(e.contains("at least 64x64 pixels"), "{e}");
    assert!(!e.contains("descriptor window"), "{e}");
    let mut want: Vec<String> = ["p0", "p1", "p2"]
        .iter()
        .flat_map(|s| {
            [".keypoints.csv", ".keypoints.json", ".descriptors.npy"].map(|x| format!("{s}{x}"))
        })
        .collect();
    want.sort();
    assert_eq!(
        listing(&out_dir),
        want,
        "the good images' files, nothing else"
    );
}

/// H4: with --fail-fast a bad header is found before any work and nothing is written; a rerun that
/// fails part-way leaves every earlier result as it was (no mix of old and new files).
#[test]
fn fail_fast_writes_nothing_or_everything() {
    let dir = workdir("reliability", "fail-fast");
    let photos = four_photos(&dir);
    let out_dir = dir.join("out");
    let small = dir.join("small.png");
    photo(50, 50, 0).save(&small).unwrap();
    let inputs = [photos[0].as_path(), &photos[1], &photos[2], &small];
    let out = extract(&inputs, &out_dir, &["--fail-fast"]);
    assert_refused(&out, "small.png");
    assert!(
        !out_dir.exists() || listing(&out_dir).is_empty(),
        "nothing written"
    );

    let all: Vec<&Path> = photos.iter().map(PathBuf::as_path).collect();
    let first = extract(&all, &out_dir, &[]);
    assert!(first.status.success(), "{}", common::stderr(&first));
    let before: Vec<Vec<u8>> = listing(&out_dir)
        .iter()
        .map(|n| std::fs::read(out_dir.join(n)).unwrap())
        .collect();
    // Other settings, and the 4th image's data broken after a good header.
    truncated_png(&photos[3]);
    let out = extract(&all, &out_dir, &["--fail-fast", "--threshold", "40"]);
    assert_refused(&out, "p3.png");
    let after: Vec<Vec<u8>> = listing(&out_dir)
        .iter()
        .map(|n| std::fs::read(out_dir.join(n)).unwrap())
        .collect();
    assert_eq!(after, before, "the earlier results, all of them, unchanged");
    assert_eq!(listing(&out_dir).len(), 12, "no temporary file left");
}

/// H9: an output folder that is missing, or a file, is found before any work (before the corrupt
/// image is decoded) and named as the fault; `--workspace` naming a file says so.
#[test]
fn output_folders_are_checked_before_the_work() {
    let dir = workdir("reliability", "out-folder");
    let broken = dir.join("broken.png");
    truncated_png(&broken);
    let good = four_photos(&dir);
    let missing = dir.join("missing");
    let out = extract(&[&broken], &missing.join("x"), &[]);
    assert_refused(&out, "does not exist");
    assert!(common::stderr(&out).contains(str(&missing)));

    let out = clatch(&[
        "match",
        str(&broken),
        str(&good[0]),
        "-o",
        str(&missing.join("m.png")),
        "--backend",
        "cpu",
    ]);
    assert_refused(&out, "does not exist");

    let file = dir.join("A.png");
    std::fs::write(&file, "the user's").unwrap();
    let out = extract(&[&broken], &file.join("x"), &[]);
    assert_refused(&out, "not a folder");

    let images = dir.join("images");
    std::fs::create_dir(&images).unwrap();
    for p in &good {
        std::fs::copy(p, images.join(p.file_name().unwrap())).unwrap();
    }
    let out = clatch(&[
        "colmap",
        "--images",
        str(&images),
        "--database",
        str(&dir.join("out.db")),
        "--workspace",
        str(&file),
        "--no-colmap",
        "--backend",
        "cpu",
    ]);
    assert_refused(&out, "it is a file, not a folder");
    assert!(!common::stderr(&out).contains("File exists"));
    assert_eq!(std::fs::read(&file).unwrap(), b"the user's");
    assert!(!dir.join("out.db").exists());
}

/// A folder of four photos for `clatch colmap`.
fn colmap_photos(dir: &Path) -> PathBuf {
    let images = dir.join("images");
    std::fs::create_dir_all(&images).unwrap();
    for i in 0..4u32 {
        photo(160, 160, 20 * i)
            .save(images.join(format!("v{i}.png")))
            .unwrap();
    }
    images
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
    ];
    args.extend_from_slice(extra);
    clatch(&args)
}

/// An executable shell script `name` in `dir`.
#[cfg(unix)]
fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

/// H10: `x.db` and `x.sqlite` get workspaces of their own; a database without extension, whose
/// default workspace is `x.db`'s, is refused instead of replacing its match list.
#[test]
fn databases_of_one_stem_never_share_a_match_list() {
    let dir = workdir("reliability", "stems");
    let images = colmap_photos(&dir);
    let out = colmap(&images, &dir.join("x.db"), &["--no-colmap"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let list = dir.join("x-colmap/matches.txt");
    let first = std::fs::read(&list).unwrap();
    let out = colmap(
        &images,
        &dir.join("x.sqlite"),
        &["--no-colmap", "--threshold", "40"],
    );
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(dir.join("x.sqlite-colmap/matches.txt").exists());
    assert_eq!(
        std::fs::read(&list).unwrap(),
        first,
        "x.db's match list kept"
    );
    let out = colmap(
        &images,
        &dir.join("x"),
        &["--no-colmap", "--threshold", "40"],
    );
    assert_refused(&out, "holds the match list of the database x.db");
    assert_eq!(std::fs::read(&list).unwrap(), first);
    assert!(!dir.join("x").exists());
}

/// H10: a second run on a database that a running one is writing is refused, naming the holder;
/// the first completes.
#[cfg(unix)]
#[test]
fn a_second_concurrent_run_on_one_database_is_refused() {
    let dir = workdir("reliability", "concurrent");
    let images = colmap_photos(&dir);
    let slow = script(
        &dir,
        "slow-colmap",
        "[ \"$1\" = matches_importer ] && sleep 4\nexit 0",
    );
    let db = dir.join("out.db");
    let mut first = std::process::Command::new(env!("CARGO_BIN_EXE_clatch"))
        .args(["colmap", "--images", str(&images), "--database", str(&db)])
        .args(["--backend", "cpu", "--colmap", str(&slow)])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lock = dir.join(".out.db.clatch-lock");
    let began = std::time::Instant::now();
    while !dir.join("out-colmap/.matches.txt.clatch-lock").exists() {
        assert!(began.elapsed().as_secs() < 30, "the first run never locked");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(lock.exists());
    let out = colmap(&images, &db, &["--no-colmap", "--force"]);
    assert_refused(&out, "being written by another clatch run");
    assert!(
        common::stderr(&out).contains(&format!("process {}", first.id())),
        "{}",
        common::stderr(&out)
    );
    let status = first.wait().unwrap();
    assert!(status.success());
    assert!(db.exists());
    assert!(!lock.exists(), "the lock file goes with the run");
}

/// A `colmap` stand-in whose `mapper -h` lists two options and whose mapper exits with `mapper_exit`.
#[cfg(unix)]
fn listing_colmap(dir: &Path, mapper_exit: u8) -> PathBuf {
    script(
        dir,
        "listing-colmap",
        &format!(
            "if [ \"$2\" = -h ]; then printf '  --database_path arg\\n  --Mapper.min_num_matches arg (=15)\\n  \
             --Mapper.init_min_num_inliers arg (=100)\\n'; exit 0; fi\n\
             [ \"$1\" = mapper ] && {{ echo 'no good initial pair' >&2; exit {mapper_exit}; }}\nexit 0"
        ),
    )
}

/// H6: what COLMAP would refuse at the end is refused before any work (a mistyped mapper option, a
/// single photo); when COLMAP fails, the database and match list are kept and the message says so.
#[cfg(unix)]
#[test]
fn colmap_failures_are_found_first_or_keep_the_work() {
    let dir = workdir("reliability", "colmap-fails");
    let images = colmap_photos(&dir);
    let colmap_ok = listing_colmap(&dir, 0);
    let db = dir.join("out.db");
    let with = |program: &Path, extra: &[&str]| {
        let mut all = vec!["--colmap", str(program)];
        all.extend_from_slice(extra);
        colmap(&images, &db, &all)
    };
    let out = with(
        &colmap_ok,
        &["--mapper-option", "Mapper.init_min_num_inlier=50"],
    );
    assert_refused(&out, "did you mean Mapper.init_min_num_inliers?");
    assert!(!db.exists());
    assert_refused(
        &with(&colmap_ok, &["--mapper-option", "Mapper.min_num_matches"]),
        "not KEY=VALUE",
    );

    let one = dir.join("one");
    std::fs::create_dir(&one).unwrap();
    std::fs::copy(images.join("v0.png"), one.join("v0.png")).unwrap();
    let out = colmap(&one, &db, &["--colmap", str(&colmap_ok)]);
    assert_refused(&out, "needs at least 2");
    assert!(!db.exists());

    let failing = dir.join("failing");
    std::fs::create_dir(&failing).unwrap();
    let colmap_fails = listing_colmap(&failing, 3);
    let out = with(&colmap_fails, &[]);
    assert_refused(&out, "are kept");
    assert!(common::stderr(&out).contains("no good initial pair"));
    assert!(common::stderr(&out).contains("colmap mapper --database_path"));
    let sql = rusqlite::Connection::open(&db).unwrap();
    let n: i64 = sql
        .query_row("SELECT COUNT(*) FROM images", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 4);
    assert!(dir.join("out-colmap/matches.txt").exists());
    assert!(
        !dir.join("out-colmap/sparse").exists(),
        "no model installed"
    );
}
