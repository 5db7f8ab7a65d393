//! Nothing lost: outputs that name an input or each other are refused before any work, pictures are
//! written in the format their extension names, and a failed run leaves older outputs as they were.

mod common;

use std::path::Path;

use common::{assert_refused, clatch, listing, photo, str, workdir};

fn two_photos(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let (a, b) = (dir.join("A.png"), dir.join("B.png"));
    photo(200, 200, 0).save(&a).unwrap();
    photo(200, 200, 30).save(&b).unwrap();
    (a, b)
}

#[test]
fn match_refuses_outputs_that_name_an_input_or_each_other() {
    let dir = workdir("outputs", "match");
    let (a, b) = two_photos(&dir);
    let (a_bytes, b_bytes) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let link = dir.join("link.png");
    #[cfg(unix)]
    std::os::unix::fs::symlink(&a, &link).unwrap();
    let same = dir.join("same.png");
    let picture = dir.join("m.png");
    let csv_b = [str(&b)];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["-o", str(&a)], "the picture"),
        #[cfg(unix)]
        (vec!["-o", str(&link)], "the picture"),
        (vec!["--matches-csv", csv_b[0]], "the matches CSV"),
        (
            vec!["-o", str(&same), "--matches-csv", str(&same)],
            "the matches CSV",
        ),
    ];
    for (extra, role) in cases {
        let mut args = vec!["match", str(&a), str(&b), "--backend", "cpu"];
        args.extend(extra.iter().copied());
        if !extra.contains(&"-o") {
            args.extend(["-o", str(&picture)]);
        }
        let out = clatch(&args);
        assert_refused(&out, role);
        assert!(common::stderr(&out).contains("is the same file as"));
    }
    assert_eq!(std::fs::read(&a).unwrap(), a_bytes, "image A untouched");
    assert_eq!(std::fs::read(&b).unwrap(), b_bytes, "image B untouched");
    assert!(!same.exists());
}

#[test]
fn ppm_and_pgm_pictures_are_p6_and_p5() {
    let dir = workdir("outputs", "pnm");
    let (a, b) = two_photos(&dir);
    for (name, magic) in [("m.ppm", "P6"), ("m.pgm", "P5")] {
        let path = dir.join(name);
        let out = clatch(&[
            "match",
            str(&a),
            str(&b),
            "-o",
            str(&path),
            "--backend",
            "cpu",
        ]);
        assert!(out.status.success(), "{}", common::stderr(&out));
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..2], magic.as_bytes(), "{name}");
        let decoded = image::open(&path).unwrap();
        assert_eq!(
            decoded.width(),
            400,
            "{name}: two 200-pixel images side by side"
        );
    }
}

#[test]
fn extract_refuses_a_folder_prefix() {
    let dir = workdir("outputs", "prefix");
    let (a, _) = two_photos(&dir);
    let out_dir = dir.join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    for prefix in [
        format!("{}/", out_dir.display()),
        out_dir.display().to_string(),
    ] {
        let out = clatch(&["extract", str(&a), "-o", &prefix]);
        assert_refused(&out, "prefix names a folder");
    }
    assert_eq!(
        std::fs::read_dir(&out_dir).unwrap().count(),
        0,
        "no hidden .keypoints.csv"
    );
}

/// Files in `dir`, sorted.
#[test]
fn extract_keeps_the_old_outputs_when_the_new_set_cannot_be_complete() {
    let dir = workdir("outputs", "extract");
    let (a, _) = two_photos(&dir);
    let prefix = dir.join("feat");
    let csv = dir.join("feat.keypoints.csv");
    let json = dir.join("feat.keypoints.json");
    std::fs::write(&csv, "old csv").unwrap();
    std::fs::write(&json, "old json").unwrap();
    // The descriptors' path is a folder: the set cannot be written, so nothing may be replaced.
    std::fs::create_dir(dir.join("feat.descriptors.npy")).unwrap();
    let out = clatch(&["extract", str(&a), "-o", str(&prefix), "--backend", "cpu"]);
    assert_refused(&out, "feat.descriptors.npy");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), "old csv");
    assert_eq!(std::fs::read_to_string(&json).unwrap(), "old json");
    std::fs::remove_dir(dir.join("feat.descriptors.npy")).unwrap();
    let out = clatch(&["extract", str(&a), "-o", str(&prefix), "--backend", "cpu"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(
        std::fs::read_to_string(&csv)
            .unwrap()
            .starts_with("x,y,size")
    );
    assert_eq!(
        listing(&dir),
        [
            "A.png",
            "B.png",
            "feat.descriptors.npy",
            "feat.keypoints.csv",
            "feat.keypoints.json"
        ],
        "no temporary file left"
    );
}

#[test]
fn extract_of_several_images_writes_each_as_its_own_call_would() {
    let dir = workdir("outputs", "extract_many");
    let (a, b) = two_photos(&dir);
    let c = dir.join("C.png");
    photo(240, 180, 60).save(&c).unwrap();
    let folder = dir.join("features");
    let out = clatch(&[
        "extract",
        str(&a),
        str(&b),
        str(&c),
        "-o",
        str(&folder),
        "--backend",
        "cpu",
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("images/s"), "{stdout}");
    assert!(stdout.contains("decode"), "{stdout}");
    for (image, stem) in [(&a, "A"), (&b, "B"), (&c, "C")] {
        let prefix = dir.join(format!("single_{stem}"));
        let single = clatch(&[
            "extract",
            str(image),
            "-o",
            str(&prefix),
            "--backend",
            "cpu",
        ]);
        assert!(single.status.success(), "{}", common::stderr(&single));
        for suffix in [".keypoints.csv", ".keypoints.json", ".descriptors.npy"] {
            let many = std::fs::read(folder.join(format!("{stem}{suffix}"))).unwrap();
            let one = std::fs::read(dir.join(format!("single_{stem}{suffix}"))).unwrap();
            assert_eq!(many, one, "{stem}{suffix}");
        }
    }
    // Two images of one stem would write the same files: refused before any work.
    let other = dir.join("other");
    std::fs::create_dir_all(&other).unwrap();
    let twin = other.join("A.png");
    photo(200, 200, 5).save(&twin).unwrap();
    let out = clatch(&[
        "extract",
        str(&a),
        str(&twin),
        "-o",
        str(&folder),
        "--backend",
        "cpu",
    ]);
    assert!(!out.status.success());
    // Both inputs named.
    assert!(
        common::stderr(&out).contains("would both write their files as A.*"),
        "{}",
        common::stderr(&out)
    );
}

/// The report says what was timed: with the defaults (a pyramid describes inside detection) one
/// `detect+desc` row, not a `describe` row of 0.00 ms; with a single scale, both rows.
#[test]
fn the_report_times_description_only_where_it_ran_apart() {
    let dir = workdir("outputs", "timing");
    let (image, prefix) = (dir.join("a.png"), dir.join("a"));
    photo(320, 240, 0).save(&image).unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "extract",
            str(&image),
            "-o",
            str(&prefix),
            "--backend",
            "cpu",
        ];
        args.extend_from_slice(extra);
        let out = clatch(&args);
        assert!(out.status.success(), "{}", common::stderr(&out));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let defaults = run(&[]);
    assert!(defaults.contains("detect+desc"), "{defaults}");
    assert!(!defaults.contains("describe "), "{defaults}");
    let single = run(&["--single-scale"]);
    assert!(
        single.contains("describe ") && !single.contains("detect+desc"),
        "{single}"
    );
}
