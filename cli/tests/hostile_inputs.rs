//! Hostile input files, generated here, through the whole binary: each gets a clean error (exit 1,
//! the file named) or a correct result, never an abort, a hang or a silent wrong answer.

mod common;

use common::{assert_refused, clatch, lying_png, photo, str, workdir};

#[test]
fn a_lying_png_header_is_refused_by_every_command_before_decoding() {
    let dir = workdir("hostile", "lying");
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let lying = dir.join("images/huge.png");
    std::fs::write(&lying, lying_png(200_000, 200_000)).unwrap();
    let good = dir.join("good.png");
    photo(200, 200, 0).save(&good).unwrap();
    let prefix = dir.join("out");
    let picture = dir.join("m.png");
    let db = dir.join("db.db");
    for args in [
        vec![
            "extract",
            str(&lying),
            "-o",
            str(&prefix),
            "--backend",
            "cpu",
        ],
        vec![
            "match",
            str(&good),
            str(&lying),
            "-o",
            str(&picture),
            "--backend",
            "cpu",
        ],
        vec![
            "colmap",
            "--images",
            str(&dir.join("images")),
            "--database",
            str(&db),
            "--no-colmap",
        ],
    ] {
        let out = clatch(&args);
        assert_refused(&out, "the header says 200000x200000");
        assert!(common::stderr(&out).contains("huge.png"));
    }
    assert!(!picture.exists() && !db.exists());
}

#[test]
fn max_pixels_sets_the_limit() {
    let dir = workdir("hostile", "max-pixels");
    let img = dir.join("img.png");
    photo(200, 150, 0).save(&img).unwrap();
    let prefix = dir.join("out");
    let run = |max: &str| {
        clatch(&[
            "extract",
            str(&img),
            "-o",
            str(&prefix),
            "--max-pixels",
            max,
        ])
    };
    assert_refused(&run("29999"), "more than allowed (29999 pixels");
    assert!(run("30000").status.success());
}

#[test]
fn a_truncated_jpeg_is_refused() {
    let dir = workdir("hostile", "truncated");
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
        .encode_image(&photo(300, 300, 0))
        .unwrap();
    let whole = dir.join("whole.jpg");
    std::fs::write(&whole, &jpeg).unwrap();
    let prefix = dir.join("out");
    assert!(
        clatch(&["extract", str(&whole), "-o", str(&prefix)])
            .status
            .success()
    );
    for cut in [1000, jpeg.len() / 2] {
        let path = dir.join("cut.jpg");
        std::fs::write(&path, &jpeg[..cut]).unwrap();
        let out = clatch(&["extract", str(&path), "-o", str(&prefix)]);
        assert_refused(&out, "JPEG data is truncated");
    }
}

/// Keypoints in an `extract` CSV.
fn keypoints(prefix: &std::path::Path) -> usize {
    let csv = std::fs::read_to_string(format!("{}.keypoints.csv", prefix.display())).unwrap();
    csv.lines().count() - 1
}

#[test]
fn twelve_bit_data_in_a_sixteen_bit_png_gives_keypoints() {
    let dir = workdir("hostile", "16bit");
    let gray = photo(256, 256, 100);
    let twelve = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(256, 256, |x, y| {
        image::Luma([u16::from(gray.get_pixel(x, y).0[0]) * 16])
    });
    let path = dir.join("twelve.png");
    twelve.save(&path).unwrap();
    let prefix = dir.join("out");
    let out = clatch(&[
        "extract",
        str(&path),
        "-o",
        str(&prefix),
        "--backend",
        "cpu",
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    // Keeping the high byte gave values 0..15, in which no FAST corner passes the threshold 20.
    assert!(keypoints(&prefix) > 100, "{} keypoints", keypoints(&prefix));
}

#[test]
fn images_too_small_for_any_keypoint_are_refused() {
    let dir = workdir("hostile", "small");
    let prefix = dir.join("out");
    let small = dir.join("small.png");
    photo(63, 200, 0).save(&small).unwrap();
    let out = clatch(&["extract", str(&small), "-o", str(&prefix)]);
    assert_refused(&out, "clatch needs at least 64x64 pixels");
    let ok = dir.join("ok.png");
    photo(64, 64, 0).save(&ok).unwrap();
    assert!(
        clatch(&["extract", str(&ok), "-o", str(&prefix)])
            .status
            .success()
    );
}

#[test]
fn a_near_one_pyramid_factor_is_refused() {
    let out = clatch(&["demo", "--pyramid", "32:1.0000153"]);
    assert_eq!(out.status.code(), Some(2), "a usage error");
    assert!(
        common::stderr(&out).contains("near-identical"),
        "{}",
        common::stderr(&out)
    );
}

#[cfg(unix)]
#[test]
fn fifos_and_devices_are_refused_without_blocking() {
    let dir = workdir("hostile", "fifo");
    let fifo = dir.join("pipe.png");
    common::mkfifo(&fifo);
    let good = dir.join("good.png");
    photo(200, 200, 0).save(&good).unwrap();
    let picture = dir.join("m.png");
    let prefix = dir.join("out");
    assert_refused(
        &clatch(&["extract", str(&fifo), "-o", str(&prefix)]),
        "not a regular file (a FIFO)",
    );
    assert_refused(
        &clatch(&["match", str(&good), str(&fifo), "-o", str(&picture)]),
        "not a regular file (a FIFO)",
    );
    for homography in [str(&fifo), "/dev/zero"] {
        let out = clatch(&[
            "match",
            str(&good),
            str(&good),
            "-o",
            str(&picture),
            "--homography",
            homography,
        ]);
        assert_refused(&out, "not a regular file");
    }
    let big = dir.join("H-big");
    std::fs::write(&big, vec![b'1'; 100_000]).unwrap();
    let out = clatch(&[
        "match",
        str(&good),
        str(&good),
        "-o",
        str(&picture),
        "--homography",
        str(&big),
    ]);
    assert_refused(&out, "more than 65536 bytes");
    std::fs::create_dir_all(dir.join("images")).unwrap();
    photo(200, 200, 0).save(dir.join("images/a.png")).unwrap();
    let out = clatch(&[
        "colmap",
        "--images",
        str(&dir.join("images")),
        "--database",
        str(&dir.join("db.db")),
        "--camera-k",
        str(&fifo),
        "--no-colmap",
    ]);
    assert_refused(&out, "not a regular file (a FIFO)");
    assert!(!picture.exists());
}

#[test]
fn a_homography_file_with_a_byte_order_mark_is_read() {
    let dir = workdir("hostile", "bom");
    let good = dir.join("good.png");
    photo(200, 200, 0).save(&good).unwrap();
    let h = dir.join("H");
    std::fs::write(&h, "\u{feff}1 0 0\n0 1 0\n0 0 1\n").unwrap();
    let picture = dir.join("m.png");
    let out = clatch(&[
        "match",
        str(&good),
        str(&good),
        "-o",
        str(&picture),
        "--homography",
        str(&h),
        "--backend",
        "cpu",
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("inliers"));
}

#[path = "../../tests/common/palette_png.rs"]
mod palette_png_writer;

/// A 128x128 palette PNG with `entries` colours, indices 0 and 1 in 8-pixel stripes except one pixel
/// `bad_index`.
fn palette_png(entries: usize, bad_index: u8) -> Vec<u8> {
    let palette: Vec<[u8; 3]> = (0..entries).map(|i| [i as u8 * 60, 90, 30]).collect();
    palette_png_writer::palette_png(128, 128, &palette, |x, y| {
        if (x, y) == (60, 60) {
            bad_index
        } else {
            (x / 8 % 2) as u8
        }
    })
}

#[test]
fn a_palette_png_with_indices_past_its_palette_is_refused() {
    let dir = workdir("hostile", "palette");
    let prefix = dir.join("out");
    let good = dir.join("good.png");
    std::fs::write(&good, palette_png(3, 2)).unwrap();
    let out = clatch(&["extract", str(&good), "-o", str(&prefix)]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let bad = dir.join("bad.png");
    std::fs::write(&bad, palette_png(3, 7)).unwrap();
    let out = clatch(&["extract", str(&bad), "-o", str(&prefix)]);
    assert_refused(&out, "past the end of its 3-colour palette");
}

/// `RAYON_NUM_THREADS` far above the machine's cores is capped with a warning, not obeyed (3000
/// threads made a 70 ms run take minutes and, under a memory limit, die).
#[test]
fn a_huge_thread_count_is_capped() {
    let dir = workdir("hostile", "threads");
    let image = dir.join("a.png");
    photo(160, 120, 0).save(&image).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_clatch"))
        .args([
            "extract",
            str(&image),
            "-o",
            str(&dir.join("a")),
            "--backend",
            "cpu",
        ])
        .env("RAYON_NUM_THREADS", "3000")
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("RAYON_NUM_THREADS=3000 is more than"),
        "{stderr}"
    );
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads: usize = stdout
        .split("cpu (")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no backend line in: {stdout}"));
    assert!(threads <= 4 * cores, "{threads} threads on {cores} cores");
}
