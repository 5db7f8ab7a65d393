//! OpenCV's columns: `scripts/eval_opencv.py` run with a given Python on the manifest, writing
//! `PREFIX.summary.csv` and `PREFIX.pr.csv` for the run to merge.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::EvalArgs;
use crate::error::EvalError;

/// `scripts/eval_opencv.py` of this crate's source folder, wherever the command runs from.
pub fn default_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/eval_opencv.py")
}

/// The script to run: `--opencv-script`, else [`default_script`]; refused before any work when it
/// is not a file (a binary copied away from its source folder needs `--opencv-script`).
pub fn script(args: &EvalArgs) -> Result<PathBuf, EvalError> {
    let script = args.opencv_script.clone().unwrap_or_else(default_script);
    if script.is_file() {
        Ok(script)
    } else {
        Err(EvalError::Script {
            command: format!("the OpenCV script {}", script.display()),
            reason: "no such file; give its path with --opencv-script".into(),
        })
    }
}

/// The command that runs `script` with `python` on the manifest, writing to `prefix` with the
/// run's matcher rules.
pub fn command(
    args: &EvalArgs,
    python: &Path,
    script: &Path,
    manifest: &Path,
    prefix: &Path,
) -> Command {
    let mut command = Command::new(python);
    command
        .arg(script)
        .arg("--manifest")
        .arg(manifest)
        .arg("--out")
        .arg(prefix)
        .arg("--inlier-px")
        .arg(args.check.inlier_px.to_string())
        .arg("--max-keypoints")
        .arg(
            (args.detect.max_keypoints)
                .unwrap_or(clatch::ExtractorConfig::default().detector.max_keypoints)
                .to_string(),
        );
    // The same matcher rules; the distance limit is in Hamming bits and has no SIFT counterpart.
    match args.matching.config().ratio {
        Some(ratio) => command.arg("--ratio").arg(ratio.to_string()),
        None => command.arg("--no-ratio"),
    };
    if args.matching.no_cross_check {
        command.arg("--no-cross-check");
    }
    command
}

/// Runs `command` to its end; a failure to start or a failing exit is an error naming it.
pub fn run(mut command: Command) -> Result<(), EvalError> {
    let shown = format!("{command:?}");
    let status = command.status().map_err(|e| EvalError::Script {
        command: shown.clone(),
        reason: e.to_string(),
    })?;
    if status.success() {
        Ok(())
    } else {
        Err(EvalError::Script {
            command: shown,
            reason: status.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn args(extra: &[&str]) -> EvalArgs {
        EvalArgs::try_parse_from([&["clatch-eval"][..], extra].concat()).unwrap()
    }

    #[test]
    fn the_script_is_found_from_anywhere_or_named() {
        let found = script(&args(&[])).unwrap();
        assert!(found.is_absolute() && found.ends_with("eval/scripts/eval_opencv.py"));
        let named = std::env::temp_dir().join(format!("clatch-opencv-{}.py", std::process::id()));
        std::fs::write(&named, "").unwrap();
        assert_eq!(
            script(&args(&["--opencv-script", named.to_str().unwrap()])).unwrap(),
            named
        );
        std::fs::remove_file(&named).unwrap();
        let e = script(&args(&["--opencv-script", named.to_str().unwrap()])).unwrap_err();
        assert!(e.to_string().contains("--opencv-script"), "{e}");
    }

    #[test]
    fn the_script_gets_the_runs_matcher_rules() {
        let shown = |extra: &[&str]| {
            let c = command(
                &args(extra),
                Path::new("python3"),
                Path::new("s.py"),
                Path::new("pairs.csv"),
                Path::new("out/opencv"),
            );
            c.get_args()
                .map(|a| a.to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join(" ")
        };
        assert_eq!(
            shown(&[]),
            "s.py --manifest pairs.csv --out out/opencv --inlier-px 3 --max-keypoints 5000 --ratio 0.8"
        );
        assert_eq!(
            shown(&[
                "--no-ratio",
                "--no-cross-check",
                "--max-keypoints",
                "100",
                "--inlier-px",
                "1.5"
            ]),
            "s.py --manifest pairs.csv --out out/opencv --inlier-px 1.5 --max-keypoints 100 \
             --no-ratio --no-cross-check"
        );
        let e = run(Command::new("/nonexistent/python")).unwrap_err();
        assert!(matches!(e, EvalError::Script { .. }), "{e}");
        let e = run(Command::new("false")).unwrap_err();
        assert!(e.to_string().contains("exit status: 1"), "{e}");
    }
}
