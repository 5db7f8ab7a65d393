//! Running the `colmap` program (COLMAP 3.8) on a database written by `clatch colmap`, and reading
//! the figures of the model it builds.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::CliError;

/// Lines of a failed step's output quoted in the error.
const TAIL_LINES: usize = 20;

/// The `colmap` executable and the folder its logs go to.
pub struct ColmapProgram {
    program: PathBuf,
    logs: PathBuf,
}

impl ColmapProgram {
    /// `program` if it runs, `None` if there is no such program.
    pub fn find(program: &Path, logs: &Path) -> Result<Option<Self>, CliError> {
        match Command::new(program).arg("help").output() {
            Ok(_) => Ok(Some(Self {
                program: program.to_path_buf(),
                logs: logs.to_path_buf(),
            })),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(CliError::ColmapStart {
                program: program.to_path_buf(),
                step: "help",
                source,
            }),
        }
    }

    /// The options `colmap STEP -h` lists (`Mapper.min_num_matches`, ...), without their dashes;
    /// empty when the program lists none (it cannot tell, so nothing is refused for it).
    pub fn options(&self, step: &str) -> Vec<String> {
        let Ok(output) = Command::new(&self.program).args([step, "-h"]).output() else {
            return Vec::new();
        };
        let mut text = String::from_utf8_lossy(&output.stdout).into_owned();
        text.push_str(&String::from_utf8_lossy(&output.stderr));
        text.lines()
            .filter_map(|line| line.trim_start().strip_prefix("--"))
            .filter_map(|rest| rest.split_whitespace().next())
            .map(str::to_owned)
            .collect()
    }

    /// Runs `colmap STEP ARGS...`, keeps its output in `LOGS/colmap-STEP.log` and returns it; a
    /// non-zero exit is an error quoting the output's last lines.
    pub fn run(&self, step: &'static str, args: &[OsString]) -> Result<String, CliError> {
        let output = Command::new(&self.program)
            .arg(step)
            .args(args)
            .output()
            .map_err(|source| CliError::ColmapStart {
                program: self.program.clone(),
                step,
                source,
            })?;
        // COLMAP logs through glog to stderr and prints summaries to stdout: keep both.
        let mut text = String::from_utf8_lossy(&output.stdout).into_owned();
        text.push_str(&String::from_utf8_lossy(&output.stderr));
        let log = self.logs.join(format!("colmap-{step}.log"));
        clatch::output::write_file(&log, |w| w.write_all(text.as_bytes()))?;
        if !output.status.success() {
            return Err(CliError::ColmapFailed {
                step,
                status: output.status.to_string(),
                log,
                tail: tail(&text, TAIL_LINES),
            });
        }
        Ok(text)
    }
}

/// The last `n` lines of `text`.
pub fn tail(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// What `colmap model_analyzer` says about one model.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelStats {
    /// The model folder.
    pub path: PathBuf,
    /// Images with a pose.
    pub registered: usize,
    /// 3D points.
    pub points: usize,
    /// Mean track length (observations per point).
    pub mean_track_length: f64,
    /// Mean reprojection error in pixels.
    pub mean_reprojection_error: f64,
}

/// Reads the figures from `colmap model_analyzer`'s output (lines such as `Registered images: 8`,
/// `Mean reprojection error: 0.44px`, possibly behind a glog prefix).
pub fn parse_model_analyzer(path: &Path, output: &str) -> Result<ModelStats, CliError> {
    let field = |name: &'static str| -> Result<f64, CliError> {
        output
            .lines()
            .find_map(|line| {
                let rest = &line[line.find(name)? + name.len()..];
                let rest = rest.trim_start_matches(':').trim().trim_end_matches("px");
                rest.parse::<f64>().ok()
            })
            .ok_or_else(|| CliError::ModelAnalyzer {
                field: name,
                model: path.to_path_buf(),
                output: tail(output, TAIL_LINES),
            })
    };
    Ok(ModelStats {
        path: path.to_path_buf(),
        registered: field("Registered images")? as usize,
        points: field("Points")? as usize,
        mean_track_length: field("Mean track length")?,
        mean_reprojection_error: field("Mean reprojection error")?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_analyzer_figures_are_read() {
        let output = "I1123 15:02:01.1 77 model.cc:1] Cameras: 1\n\
                      Images: 11\nRegistered images: 10\nPoints: 4103\nObservations: 9000\n\
                      Mean track length: 2.193500\nMean observations per image: 900\n\
                      Mean reprojection error: 0.961234px\n";
        let stats = parse_model_analyzer(Path::new("m"), output).unwrap();
        assert_eq!(stats.registered, 10);
        assert_eq!(stats.points, 4103);
        assert_eq!(stats.mean_track_length, 2.1935);
        assert_eq!(stats.mean_reprojection_error, 0.961234);
        let e = parse_model_analyzer(Path::new("m"), "Points: 3\n").unwrap_err();
        assert!(e.to_string().contains("Registered images"), "{e}");
        assert_eq!(tail("a\nb\nc", 2), "b\nc");
    }
}
