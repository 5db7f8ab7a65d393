//! The command-line findings of the reliability review: batches that go on past a bad
//! image, outputs checked before the work, locks, COLMAP failures that keep the work done, plausible
//! camera matrices, corrupt images and decoder allocations, messages that name what the user set.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_refused, clatch, listing, photo, str, workdir};

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

/// A small image in a batch no longer stops it: every good image's three files are
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

/// With --fail-fast a bad header is found before any work and nothing is written; a rerun that
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

/// An output folder that is missing, or a file, is found before any work (before the corrupt
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
    common::colmap_cpu(images, db, extra)
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

/// `x.db` and `x.sqlite` get workspaces of their own; a database without extension, whose
/// default workspace is `x.db`'s, is refused instead of replacing its match list.
#[test]
fn databases_of_one_stem_never_share_a_match_list() {
    let dir = workdir("reliability", "stems");
    let images = colmap_photos(&dir);
    let out = colmap(&images, &dir.join("x.db"), &["--no-colmap", "--match-list"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let list = dir.join("x-colmap/matches.txt");
    let first = std::fs::read(&list).unwrap();
    let out = colmap(
        &images,
        &dir.join("x.sqlite"),
        &["--no-colmap", "--threshold", "40", "--match-list"],
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
        &["--no-colmap", "--threshold", "40", "--match-list"],
    );
    assert_refused(&out, "holds the match list of the database x.db");
    assert_eq!(std::fs::read(&list).unwrap(), first);
    assert!(!dir.join("x").exists());
}

/// A second run on a database that a running one is writing is refused, naming the holder;
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
        .args(["--backend", "cpu", "--no-verify", "--colmap", str(&slow)])
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

/// What COLMAP would refuse at the end is refused before any work (a mistyped mapper option, a
/// single photo); when COLMAP fails, the database is kept and the message says so.
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
    assert_refused(&out, "is kept (every photo's features and the matches)");
    assert!(common::stderr(&out).contains("no good initial pair"));
    assert!(common::stderr(&out).contains("colmap mapper --database_path"));
    let sql = rusqlite::Connection::open(&db).unwrap();
    let n: i64 = sql
        .query_row("SELECT COUNT(*) FROM images", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 4);
    // Verified: the matches are in the database, and no match list is written.
    let matched: i64 = sql
        .query_row("SELECT COUNT(*) FROM matches WHERE rows > 0", [], |r| {
            r.get(0)
        })
        .unwrap();
    assert!(matched > 0);
    assert!(!dir.join("out-colmap/matches.txt").exists());
    assert!(
        !dir.join("out-colmap/sparse").exists(),
        "no model installed"
    );
}

/// Every name under `dir` (recursively) that holds `.clatch-`: temporary files, folders and locks.
fn clatch_leftovers(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if name.contains(".clatch-") && name != ".clatch-database" {
                found.push(path.display().to_string());
            }
            if path.is_dir() && !path.is_symlink() {
                stack.push(path);
            }
        }
    }
    found
}

/// Starts `clatch colmap` with a `colmap` whose matches_importer sleeps (writing its pid to
/// `DIR/colmap.pid` first), and waits until it runs.
#[cfg(unix)]
fn start_colmap_that_hangs(dir: &Path, images: &Path, db: &Path) -> std::process::Child {
    let pid_file = dir.join("colmap.pid");
    let hang = script(
        dir,
        "hanging-colmap",
        &format!(
            "[ \"$1\" = matches_importer ] && {{ echo $$ > '{}'; exec sleep 60; }}\nexit 0",
            pid_file.display()
        ),
    );
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_clatch"))
        .args(["colmap", "--images", str(images), "--database", str(db)])
        .args(["--backend", "cpu", "--no-verify", "--colmap", str(&hang)])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let began = std::time::Instant::now();
    while std::fs::read_to_string(&pid_file).map_or(true, |s| s.trim().is_empty()) {
        assert!(began.elapsed().as_secs() < 30, "COLMAP never started");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child
}

#[cfg(unix)]
fn signal(pid: u32, name: &str) {
    let ok = std::process::Command::new("kill")
        .args([&format!("-{name}"), &pid.to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{name} {pid}");
}

/// SIGTERM or SIGINT during COLMAP's steps stops COLMAP and removes every temporary file,
/// folder and lock; nothing is put in place.
#[cfg(target_os = "linux")]
#[test]
fn an_interrupted_colmap_run_leaves_nothing_behind() {
    for sig in ["TERM", "INT"] {
        let dir = workdir("reliability", &format!("signal-{sig}"));
        let images = colmap_photos(&dir);
        let db = dir.join("out.db");
        let mut run = start_colmap_that_hangs(&dir, &images, &db);
        let colmap_pid: u32 = std::fs::read_to_string(dir.join("colmap.pid"))
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        assert!(!clatch_leftovers(&dir).is_empty(), "it is mid-run");
        signal(run.id(), sig);
        let status = run.wait().unwrap();
        assert_eq!(status.code(), Some(130), "{sig}");
        assert_eq!(clatch_leftovers(&dir), Vec::<String>::new(), "{sig}");
        assert!(!db.exists());
        let began = std::time::Instant::now();
        while Path::new(&format!("/proc/{colmap_pid}")).exists() {
            // A zombie reaped by init can linger a moment.
            let state =
                std::fs::read_to_string(format!("/proc/{colmap_pid}/stat")).unwrap_or_default();
            if state.contains(") Z") {
                break;
            }
            assert!(began.elapsed().as_secs() < 10, "{sig}: COLMAP still runs");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
}

/// What a SIGKILLed run leaves (temporary database, match list, model folder, locks) is swept by
/// the next run in the same folders, and only that.
#[cfg(target_os = "linux")]
#[test]
fn the_next_run_sweeps_what_a_killed_run_left() {
    let dir = workdir("reliability", "sigkill");
    let images = colmap_photos(&dir);
    let db = dir.join("out.db");
    let mut run = start_colmap_that_hangs(&dir, &images, &db);
    let colmap_pid = std::fs::read_to_string(dir.join("colmap.pid")).unwrap();
    signal(run.id(), "KILL");
    run.wait().unwrap();
    signal(colmap_pid.trim().parse().unwrap(), "KILL");
    let left = clatch_leftovers(&dir);
    assert!(left.iter().any(|p| p.ends_with(".tmp")), "{left:?}");
    // A file of the user's that merely looks like one stays.
    let lookalike = dir.join("out-colmap/notes.clatch-1-1.tmp");
    std::fs::write(&lookalike, "mine").unwrap();
    let out = colmap(&images, &db, &["--no-colmap"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert_eq!(
        clatch_leftovers(&dir),
        [lookalike.display().to_string()],
        "only the user's file"
    );
}

/// A K that COLMAP would spin or abort on, or whose principal point lies outside the photos, is
/// refused before any work; a COLMAP step that runs past --colmap-timeout is stopped with a typed
/// error (the database and match list kept).
#[cfg(unix)]
#[test]
fn implausible_cameras_are_refused_and_colmap_is_bounded_in_time() {
    let dir = workdir("reliability", "k-and-timeout");
    let images = colmap_photos(&dir);
    let db = dir.join("out.db");
    let k = dir.join("K.txt");
    for (text, needle) in [
        (
            "1e-300 0 80 0 1e-300 80 0 0 1",
            "implausible for a 160x160 image",
        ),
        ("1e308 0 80 0 1e308 80 0 0 1", "implausible"),
        ("200 0 500 0 200 80 0 0 1", "outside the 160x160 image"),
    ] {
        std::fs::write(&k, text).unwrap();
        let out = colmap(&images, &db, &["--no-colmap", "--camera-k", str(&k)]);
        assert_refused(&out, needle);
        assert!(!db.exists());
    }
    let slow = script(
        &dir,
        "slow-mapper",
        "[ \"$2\" = -h ] && exit 0\n[ \"$1\" = mapper ] && exec sleep 60\nexit 0",
    );
    let began = std::time::Instant::now();
    let out = colmap(
        &images,
        &db,
        &["--colmap", str(&slow), "--colmap-timeout", "1"],
    );
    assert_refused(&out, "colmap mapper still ran after 1 s");
    assert!(began.elapsed().as_secs() < 30);
    assert!(db.exists(), "kept");
}

/// A JPEG cut and marked as ended again, a JPEG whose header was patched larger, a PGM
/// sample above MAXVAL are refused as corrupt (as `djpeg` reports them), not decoded into flat
/// fill; an empty file says so.
#[test]
fn corrupt_images_are_refused_and_an_empty_file_is_named_so() {
    let dir = workdir("reliability", "corrupt");
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
        .encode_image(&photo(320, 240, 0))
        .unwrap();
    let mut cut = jpeg[..jpeg.len() / 4].to_vec();
    cut.extend_from_slice(&[0xFF, 0xD9]);
    let mut patched = jpeg.clone();
    let sof = patched.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap() + 5;
    patched[sof..sof + 4].copy_from_slice(&[0x27, 0x10, 0x27, 0x10]);
    let mut pgm = b"P5\n100 100\n200\n".to_vec();
    pgm.resize(pgm.len() + 100 * 100, 100);
    pgm[20] = 250;
    for (name, bytes, needle) in [
        ("cut.jpg", cut, "corrupt image"),
        ("patched.jpg", patched, "corrupt image"),
        ("hot.pgm", pgm, "above the file's MAXVAL 200"),
        ("empty.png", Vec::new(), "the file is empty"),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let out = extract(&[&path], &dir.join("out"), &[]);
        assert_refused(&out, needle);
        assert!(common::stderr(&out).contains(name));
        assert!(!dir.join("out.keypoints.csv").exists());
    }
    let whole = dir.join("whole.jpg");
    std::fs::write(&whole, &jpeg).unwrap();
    let out = extract(&[&whole], &dir.join("out"), &[]);
    assert!(out.status.success(), "{}", common::stderr(&out));
}

/// 548x342 pixels of the photograph (its 512-pixel crop mirrored at the edges).
fn big_photo() -> image::GrayImage {
    let p = photo(512, 342, 0);
    image::GrayImage::from_fn(548, 342, |x, y| {
        *p.get_pixel(if x < 512 { x } else { 1023 - x }, y)
    })
}

/// A 548x342 PNG whose iCCP chunk inflates to `icc_bytes` of zeros.
fn icc_bomb(icc_bytes: usize) -> Vec<u8> {
    use std::io::Write;
    let mut png = Vec::new();
    big_photo()
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..icc_bytes >> 20 {
        z.write_all(&zeros).unwrap();
    }
    let mut data = b"bomb\0\0".to_vec();
    data.extend(z.finish().unwrap());
    let mut chunk = (data.len() as u32).to_be_bytes().to_vec();
    chunk.extend_from_slice(b"iCCP");
    chunk.extend_from_slice(&data);
    let crc = crc32fast::hash(&chunk[4..]);
    chunk.extend_from_slice(&crc.to_be_bytes());
    // After the signature (8 bytes) and IHDR (25).
    png.splice(33..33, chunk);
    png
}

/// The largest VmHWM (peak resident memory, KiB) seen of `child` until it ends.
#[cfg(target_os = "linux")]
fn peak_kib(child: &mut std::process::Child) -> u64 {
    let mut peak = 0;
    while child.try_wait().unwrap().is_none() {
        if let Ok(status) = std::fs::read_to_string(format!("/proc/{}/status", child.id())) {
            let kib = status
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
                .unwrap_or(0);
            peak = peak.max(kib);
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    peak
}

/// An ICC profile that inflates to 512 MiB in a 548x342 PNG (a 1.5 MB image) is cut off by the
/// decoder's allocation cap (its pixels plus 16 MiB of metadata, whatever --max-pixels allows): the
/// profile is dropped (the PNG decoder ignores a profile it cannot read), the image read, and the
/// run's peak resident memory stays far below the bomb.
#[cfg(target_os = "linux")]
#[test]
fn a_decompression_bomb_in_png_metadata_is_refused_in_bounded_memory() {
    let dir = workdir("reliability", "icc-bomb");
    let bomb = dir.join("bomb.png");
    std::fs::write(&bomb, icc_bomb(512 << 20)).unwrap();
    for extra in [&[][..], &["--max-pixels", "1000000000"]] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_clatch"))
            .args([
                "extract",
                str(&bomb),
                "-o",
                str(&dir.join("out")),
                "--backend",
                "cpu",
            ])
            .args(extra)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let peak = peak_kib(&mut child);
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", common::stderr(&out));
        assert!(
            peak < 150 << 10,
            "{extra:?}: peak resident memory {peak} KiB"
        );
    }
    // The same image without the bomb is read.
    let plain = dir.join("plain.png");
    big_photo().save(&plain).unwrap();
    let out = extract(&[&plain], &dir.join("out"), &[]);
    assert!(out.status.success(), "{}", common::stderr(&out));
}

/// --pyramid 8 and a --keypoint-size too large for the default pyramid name the options as
/// given (not the library's `pyramid.levels`); --single-scale on an image too small for its 64-pixel
/// windows warns why it found nothing.
#[test]
fn sizes_are_explained_in_the_options_the_user_set() {
    let dir = workdir("reliability", "sizes");
    let out = clatch(&["demo", "--pyramid", "8", "-o", str(&dir.join("d.png"))]);
    assert_refused(&out, "--pyramid 8:2 with the default keypoint size 40");
    assert!(!common::stderr(&out).contains("pyramid.levels"));
    let out = clatch(&[
        "demo",
        "--keypoint-size",
        "500",
        "-o",
        str(&dir.join("d.png")),
    ]);
    assert_refused(&out, "--keypoint-size at most 285");
    let small = dir.join("small.png");
    photo(90, 90, 100).save(&small).unwrap();
    let out = extract(&[&small], &dir.join("s"), &["--single-scale"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let e = common::stderr(&out);
    assert!(
        e.contains("warning") && e.contains("no keypoints: it is 90x90"),
        "{e}"
    );
    assert!(e.contains("48 pixels from every border"), "{e}");
}

/// Two inputs of one name in a multi-image extract are both named; entries of a colmap folder
/// named like images but skipped (a broken link, a FIFO, a folder) are listed in a warning.
#[test]
fn skipped_and_clashing_inputs_are_named() {
    let dir = workdir("reliability", "names");
    for sub in ["a", "b"] {
        std::fs::create_dir(dir.join(sub)).unwrap();
        photo(100, 100, 0)
            .save(dir.join(sub).join("x.png"))
            .unwrap();
    }
    let (a, b) = (dir.join("a/x.png"), dir.join("b/x.png"));
    let out = extract(&[&a, &b], &dir.join("out"), &[]);
    assert_refused(&out, str(&a));
    assert!(
        common::stderr(&out).contains(str(&b)),
        "{}",
        common::stderr(&out)
    );
    assert!(!dir.join("out/x.keypoints.csv").exists());

    let images = colmap_photos(&dir);
    std::fs::create_dir(images.join("folder.jpg")).unwrap();
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(dir.join("gone.jpg"), images.join("dangling.jpg")).unwrap();
        common::mkfifo(&images.join("pipe.png"));
    }
    let out = colmap(&images, &dir.join("out.db"), &["--no-colmap"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let e = common::stderr(&out);
    assert!(e.contains("warning: skipped"), "{e}");
    assert!(e.contains("folder.jpg (a folder)"), "{e}");
    #[cfg(unix)]
    {
        assert!(e.contains("dangling.jpg (a broken link)"), "{e}");
        assert!(e.contains("pipe.png (a FIFO)"), "{e}");
    }
}

/// SIGTERM in the middle of a multi-image `extract` leaves no temporary file: every image's
/// files are either all in place or absent.
#[cfg(target_os = "linux")]
#[test]
fn an_interrupted_extract_leaves_no_temporary_file() {
    let dir = workdir("reliability", "extract-signal");
    let first = dir.join("p0.png");
    let p = photo(512, 512, 0);
    image::GrayImage::from_fn(1024, 1024, |x, y| *p.get_pixel(x % 512, y % 512))
        .save(&first)
        .unwrap();
    let images: Vec<PathBuf> = (0..60)
        .map(|i| {
            let path = dir.join(format!("p{i}.png"));
            if i > 0 {
                std::fs::copy(&first, &path).unwrap();
            }
            path
        })
        .collect();
    let out = dir.join("out");
    let mut run = std::process::Command::new(env!("CARGO_BIN_EXE_clatch"))
        .arg("extract")
        .args(&images)
        .args(["-o", str(&out), "--backend", "cpu"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let began = std::time::Instant::now();
    while !out.join("p0.descriptors.npy").exists() {
        assert!(began.elapsed().as_secs() < 60, "nothing written");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    signal(run.id(), "TERM");
    assert_eq!(run.wait().unwrap().code(), Some(130));
    assert_eq!(clatch_leftovers(&dir), Vec::<String>::new());
    let names = listing(&out);
    for i in 0..60 {
        let of_image = [".keypoints.csv", ".keypoints.json", ".descriptors.npy"]
            .iter()
            .filter(|s| names.contains(&format!("p{i}{s}")))
            .count();
        assert!(
            of_image == 0 || of_image == 3,
            "p{i}: {of_image} of 3 files"
        );
    }
}
