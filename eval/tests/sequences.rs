//! `clatch-eval --data` on homography sequences built here: one in the Oxford layout, one in the
//! HPatches layout, read as a folder of sequences.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh folder for one test.
fn workdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("clatch-eval-seq-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `clatch-eval ARGS...` to its end.
fn clatch_eval(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_clatch-eval"))
        .args(args)
        .output()
        .unwrap()
}

/// Asserts a clean refusal: exit status 1 (not a panic's 101) and `needle` in stderr.
fn assert_refused(out: &Output, needle: &str) {
    let e = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(e.contains(needle), "expected {needle:?} in: {e}");
}

fn str(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Shifts by (dx, dy): the homography B = A moved right and down.
fn shift_text(dx: u32, dy: u32) -> String {
    format!("1 0 {dx}\n0 1 {dy}\n0 0 1\n")
}

/// Images 1..=3 of one photo shifted by 0, 4 and 8 pixels, with the homographies from image 1.
fn write_sequence(dir: &Path, image_name: impl Fn(u32) -> String, h_name: impl Fn(u32) -> String) {
    std::fs::create_dir_all(dir).unwrap();
    let base = clatch_cli::photo::embedded_photo().unwrap();
    for k in 1..=3u32 {
        let d = 4 * (k - 1);
        let shifted = image::GrayImage::from_fn(200, 160, |x, y| {
            if x >= d && y >= d {
                *base.get_pixel(x - d, y - d)
            } else {
                image::Luma([0])
            }
        });
        shifted.save(dir.join(image_name(k))).unwrap();
        if k >= 2 {
            std::fs::write(dir.join(h_name(k)), shift_text(d, d)).unwrap();
        }
    }
}

/// The rows of a CSV file, split at commas, without the header.
fn rows(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

#[test]
fn eval_reads_oxford_and_hpatches_sequences_named_by_folder() {
    let dir = workdir("layouts");
    let data = dir.join("data");
    write_sequence(
        &data.join("oxford_tiny"),
        |k| format!("img{k}.ppm"),
        |k| format!("H1to{k}p"),
    );
    write_sequence(
        &data.join("v_tiny"),
        |k| format!("{k}.png"),
        |k| format!("H_1_{k}"),
    );
    std::fs::create_dir_all(data.join("not_a_sequence")).unwrap();
    let out = dir.join("out");
    let run = clatch_eval(&[
        "--no-synthetic",
        "--data",
        str(&data),
        "--method",
        "clatch",
        "-o",
        str(&out),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("skipped"), "{stdout}");

    let summary = rows(&out.join("clatch.summary.csv"));
    let named: Vec<(&str, &str, &str)> = summary
        .iter()
        .map(|r| (r[0].as_str(), r[1].as_str(), r[2].as_str()))
        .collect();
    assert_eq!(
        named,
        [
            ("clatch", "tiny 1-2", "oxford-tiny"),
            ("clatch", "tiny 1-3", "oxford-tiny"),
            ("clatch", "v_tiny 1-2", "hpatches-v_tiny"),
            ("clatch", "v_tiny 1-3", "hpatches-v_tiny"),
        ]
    );
    // A pure shift of a photo: clatch finds correct matches on every pair.
    for row in &summary {
        let (matches, correct): (usize, usize) =
            (row[12].parse().unwrap(), row[13].parse().unwrap());
        assert!(correct > 0 && correct <= matches, "{row:?}");
    }
    let manifest = rows(&out.join("pairs.csv"));
    assert_eq!(manifest.len(), 4);
    assert!(
        manifest[3][3].ends_with("v_tiny/1.png"),
        "{:?}",
        manifest[3]
    );
    assert!(
        manifest[3][5].ends_with("v_tiny/H_1_3"),
        "{:?}",
        manifest[3]
    );

    // The same sequence given twice: pair names would clash.
    let twice = clatch_eval(&[
        "--no-synthetic",
        "--data",
        str(&data.join("v_tiny")),
        "--data",
        str(&data.join("v_tiny")),
        "--method",
        "clatch",
        "-o",
        str(&dir.join("out2")),
    ]);
    assert_refused(&twice, "two pairs are named `v_tiny 1-2`");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn pyramid_runs_with_the_default_methods_and_refuses_the_opencv_column_when_asked() {
    let dir = workdir("pyramid");
    let data = dir.join("v_tiny");
    write_sequence(&data, |k| format!("{k}.png"), |k| format!("H_1_{k}"));
    let out = dir.join("out");
    let run = clatch_eval(&[
        "--no-synthetic",
        "--data",
        str(&data),
        "--pyramid",
        "2:2",
        "-o",
        str(&out),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("clatch (OpenCV-compatible) left out"),
        "{stdout}"
    );
    let methods: Vec<String> = rows(&out.join("clatch.summary.csv"))
        .into_iter()
        .map(|r| r[0].clone())
        .collect();
    assert_eq!(methods, ["clatch", "clatch"]);

    let asked = clatch_eval(&[
        "--no-synthetic",
        "--data",
        str(&data),
        "--pyramid",
        "2:2",
        "--method",
        "clatch-opencv",
        "-o",
        str(&dir.join("out2")),
    ]);
    assert_refused(&asked, "--method clatch-opencv with --pyramid: ");
    // Refused before any output is written.
    assert!(!dir.join("out2").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// A run that fails on a pair's image leaves the last run's `pairs.csv` (and every
/// other file) as it was, and an output folder it created is removed again.
#[test]
fn a_failed_run_keeps_the_last_runs_files_and_leaves_no_folder() {
    let root = workdir("failed-run");
    let seq = root.join("oxford_wall");
    write_sequence(&seq, |k| format!("img{k}.ppm"), |k| format!("H1to{k}p"));
    let out = root.join("out");
    let args = |out: &Path| {
        vec![
            "--no-synthetic".to_owned(),
            "--backend".into(),
            "cpu".into(),
            "--method".into(),
            "clatch".into(),
            "--data".into(),
            str(&seq).into(),
            "--out".into(),
            str(out).into(),
        ]
    };
    let first = clatch_eval(&args(&out).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let before: Vec<(String, Vec<u8>)> = ["pairs.csv", "results.json", "clatch.summary.csv"]
        .iter()
        .map(|n| (n.to_string(), std::fs::read(out.join(n)).unwrap()))
        .collect();
    // A second sequence (other pairs, so another manifest) whose image 3 is cut short: its header
    // reads, its pixels do not.
    let seq2 = root.join("oxford_floor");
    write_sequence(&seq2, |k| format!("img{k}.ppm"), |k| format!("H1to{k}p"));
    let img3 = seq2.join("img3.ppm");
    let bytes = std::fs::read(&img3).unwrap();
    std::fs::write(&img3, &bytes[..bytes.len() / 2]).unwrap();
    let with_second = |out: &Path| {
        let mut a = args(out);
        a.extend(["--data".to_owned(), str(&seq2).to_owned()]);
        a
    };
    let failed = clatch_eval(
        &with_second(&out)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert_refused(&failed, "img3.ppm");
    for (name, old) in &before {
        assert_eq!(&std::fs::read(out.join(name)).unwrap(), old, "{name} kept");
    }
    let fresh = root.join("fresh");
    let failed = clatch_eval(
        &with_second(&fresh)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert_refused(&failed, "img3.ppm");
    assert!(!fresh.exists(), "no output folder left behind");
    std::fs::remove_dir_all(&root).ok();
}

/// `--data FILE` says it is a file; the settings line tells the defaults from
/// --single-scale, and says whose keypoints the OpenCV-compatible column describes.
#[test]
fn data_naming_a_file_and_the_settings_line_say_what_they_are() {
    let root = workdir("settings-line");
    let file = root.join("notes.txt");
    std::fs::write(&file, "not a folder").unwrap();
    let out = clatch_eval(&[
        "--no-synthetic",
        "--data",
        str(&file),
        "--out",
        str(&root.join("o")),
    ]);
    assert_refused(&out, "not a folder");
    assert!(!String::from_utf8_lossy(&out.stderr).contains("not found"));

    let seq = root.join("oxford_wall");
    write_sequence(&seq, |k| format!("img{k}.ppm"), |k| format!("H1to{k}p"));
    let line = |extra: &[&str]| {
        let o = root.join("o");
        let mut args = vec!["--no-synthetic", "--backend", "cpu", "--data", str(&seq)];
        args.extend(["--out", str(&o)]);
        args.extend_from_slice(extra);
        let run = clatch_eval(&args);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
        stdout
            .lines()
            .find(|l| l.trim_start().starts_with("clatch "))
            .unwrap()
            .to_owned()
    };
    let default = line(&[]);
    let single = line(&["--single-scale"]);
    assert_ne!(default, single);
    assert!(
        default.contains("pyramid 8 levels x 1.2, keypoint size 40 px"),
        "{default}"
    );
    assert!(default.contains("its own keypoints"), "{default}");
    assert!(!default.contains("the same keypoints"), "{default}");
    assert!(
        single.contains("single scale, keypoint size 64 px"),
        "{single}"
    );
    assert!(
        single.contains("the same keypoints as the clatch column"),
        "{single}"
    );
    std::fs::remove_dir_all(&root).ok();
}
