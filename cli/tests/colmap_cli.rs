//! `clatch colmap` end to end without COLMAP: the database and match list it writes for a folder of
//! generated photos, and its errors (missing folder, no image, undecodable image, a failing `colmap`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rusqlite::Connection;

fn workdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("clatch-colmap-cli-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(dir.join("images")).unwrap();
    dir
}

/// Three 320x320 crops of the repository's photograph, shifted by 40 px, as PNG files.
fn write_photos(dir: &Path) {
    let photo = image::load_from_memory(include_bytes!("../../assets/astronaut.png"))
        .expect("the PNG decodes")
        .to_luma8();
    for (i, &offset) in [0u32, 40, 80].iter().enumerate() {
        let img =
            image::GrayImage::from_fn(320, 320, |x, y| *photo.get_pixel(x + offset, y + offset));
        img.save(dir.join(format!("images/view{i}.png"))).unwrap();
    }
}

fn clatch(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_clatch"))
        .arg("colmap")
        .args(args)
        .output()
        .unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn writes_database_and_match_list() {
    let dir = workdir("ok");
    write_photos(&dir);
    let db = dir.join("out.db");
    let out = clatch(&[
        "--images",
        dir.join("images").to_str().unwrap(),
        "--database",
        db.to_str().unwrap(),
        "--backend",
        "cpu",
        "--no-colmap",
        "--match-list",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let sql = Connection::open(&db).unwrap();
    let names: Vec<String> = sql
        .prepare("SELECT name FROM images ORDER BY image_id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(names, ["view0.png", "view1.png", "view2.png"]);
    // Without K: COLMAP's guess, not marked as known.
    let (params, prior): (Vec<u8>, i64) = sql
        .query_row("SELECT params, prior_focal_length FROM cameras", [], |r| {
            Ok((r.get(0)?, r.get(1)?))
        })
        .unwrap();
    assert_eq!(f64::from_le_bytes(params[..8].try_into().unwrap()), 384.0);
    assert_eq!(prior, 0);
    let counts: Vec<usize> = sql
        .prepare("SELECT rows FROM keypoints ORDER BY image_id")
        .unwrap()
        .query_map([], |r| r.get::<_, i64>(0))
        .unwrap()
        .map(|r| r.unwrap() as usize)
        .collect();
    // The match list: every pair once, names first, indices within both images' keypoints.
    let list = std::fs::read_to_string(dir.join("out-colmap/matches.txt")).unwrap();
    let mut pairs = 0;
    for block in list.split("\n\n").filter(|b| !b.is_empty()) {
        let mut lines = block.lines();
        let header: Vec<&str> = lines.next().unwrap().split(' ').collect();
        let index = |name: &str| names.iter().position(|n| n == name).unwrap();
        let (a, b) = (index(header[0]), index(header[1]));
        assert!(a < b, "pairs are written in image order");
        let rows: Vec<(usize, usize)> = lines
            .map(|l| {
                let (p, q) = l.split_once(' ').unwrap();
                (p.parse().unwrap(), q.parse().unwrap())
            })
            .collect();
        assert!(rows.len() >= 20, "{header:?}: {} matches", rows.len());
        assert!(rows.iter().all(|&(p, q)| p < counts[a] && q < counts[b]));
        pairs += 1;
    }
    assert_eq!(pairs, 3);
    // Verified by default: the database holds every pair's matches, as many as the list's.
    let (stored, rows): (i64, i64) = sql
        .query_row("SELECT COUNT(*), SUM(rows) FROM matches", [], |r| {
            Ok((r.get(0)?, r.get(1)?))
        })
        .unwrap();
    let listed = list
        .lines()
        .filter(|l| l.split(' ').all(|w| w.parse::<u32>().is_ok()))
        .count();
    assert_eq!((stored, rows as usize), (3, listed));
    // The database is never overwritten without --force.
    let again = clatch(&[
        "--images",
        dir.join("images").to_str().unwrap(),
        "--database",
        db.to_str().unwrap(),
        "--no-colmap",
    ]);
    assert!(!again.status.success());
    assert!(
        stderr(&again).contains("already exists"),
        "{}",
        stderr(&again)
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn failures_are_reported_with_their_cause() {
    let dir = workdir("errors");
    let db = dir.join("out.db");
    let run = |images: &Path, extra: &[&str]| {
        std::fs::remove_file(&db).ok();
        let mut args = vec![
            "--images",
            images.to_str().unwrap(),
            "--database",
            db.to_str().unwrap(),
            "--backend",
            "cpu",
        ];
        args.extend_from_slice(extra);
        let out = clatch(&args);
        assert!(!out.status.success());
        stderr(&out)
    };
    let e = run(&dir.join("missing"), &["--no-colmap"]);
    assert!(e.contains("cannot list the image folder"), "{e}");
    let e = run(&dir.join("images"), &["--no-colmap"]);
    assert!(e.contains("no image in"), "{e}");
    std::fs::write(dir.join("images/broken.jpg"), b"not a jpeg").unwrap();
    let e = run(&dir.join("images"), &["--no-colmap"]);
    assert!(
        e.contains("cannot decode image") && e.contains("broken.jpg"),
        "{e}"
    );
    std::fs::remove_file(dir.join("images/broken.jpg")).unwrap();

    // A `colmap` that fails: its last output lines are in the error.
    write_photos(&dir);
    let fake = dir.join("fake-colmap");
    std::fs::write(
        &fake,
        "#!/bin/sh\necho \"fake colmap: $1 broke\" >&2\n[ \"$1\" = help ] || exit 3\n",
    )
    .unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
        // Verified by clatch, the mapper is COLMAP's first step; with --no-verify, matches_importer.
        let e = run(&dir.join("images"), &["--colmap", fake.to_str().unwrap()]);
        assert!(e.contains("colmap mapper failed"), "{e}");
        assert!(e.contains("fake colmap: mapper broke"), "{e}");
        assert!(e.contains("the database") && e.contains("is kept"), "{e}");
        let e = run(
            &dir.join("images"),
            &["--colmap", fake.to_str().unwrap(), "--no-verify", "--force"],
        );
        assert!(e.contains("colmap matches_importer failed"), "{e}");
        assert!(e.contains("fake colmap: matches_importer broke"), "{e}");
        assert!(e.contains("and the match list"), "{e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
