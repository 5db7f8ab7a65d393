//! Running the `colmap` program (COLMAP 3.8) on a database written by `clatch colmap`, and reading
//! the figures of the model it builds.

use std::ffi::OsString;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use crate::error::CliError;

/// Lines of a failed step's output quoted in the error.
const TAIL_LINES: usize = 20;

/// The `colmap` executable and the folder its logs go to.
pub struct ColmapProgram {
    program: PathBuf,
    logs: PathBuf,
    /// The longest a step may run before it is killed.
    timeout: Duration,
}

impl ColmapProgram {
    /// `program` if it runs, `None` if there is no such program.
    pub fn find(program: &Path, logs: &Path, timeout: Duration) -> Result<Option<Self>, CliError> {
        let mut command = Command::new(program);
        command.arg("help");
        match run_bounded(command, HELP_TIMEOUT) {
            Ok(_) => Ok(Some(Self {
                program: program.to_path_buf(),
                logs: logs.to_path_buf(),
                timeout,
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
        let mut command = Command::new(&self.program);
        command.args([step, "-h"]);
        let Ok((_, text)) = run_bounded(command, HELP_TIMEOUT) else {
            return Vec::new();
        };
        text.lines()
            .filter_map(|line| line.trim_start().strip_prefix("--"))
            .filter_map(|rest| rest.split_whitespace().next())
            .map(str::to_owned)
            .collect()
    }

    /// Runs `colmap STEP ARGS...`, keeps its output in `LOGS/colmap-STEP.log` and returns it; a
    /// non-zero exit is an error quoting the output's last lines; a step still running after the
    /// program's time limit is killed ([`CliError::ColmapTimeout`]).
    pub fn run(&self, step: &'static str, args: &[OsString]) -> Result<String, CliError> {
        let mut command = Command::new(&self.program);
        command.arg(step).args(args);
        let (status, text) =
            run_bounded(command, self.timeout).map_err(|source| CliError::ColmapStart {
                program: self.program.clone(),
                step,
                source,
            })?;
        let log = self.logs.join(format!("colmap-{step}.log"));
        clatch::output::write_file(&log, |w| w.write_all(text.as_bytes()))?;
        let Some(status) = status else {
            return Err(CliError::ColmapTimeout {
                step,
                seconds: self.timeout.as_secs(),
                log,
            });
        };
        if !status.success() {
            return Err(CliError::ColmapFailed {
                step,
                status: status.to_string(),
                log,
                tail: tail(&text, TAIL_LINES),
            });
        }
        Ok(text)
    }
}

/// How long `colmap help` and `colmap STEP -h` may take.
const HELP_TIMEOUT: Duration = Duration::from_secs(60);

/// Runs `command` with its stdout and stderr captured (stdout first in the text: COLMAP logs through
/// glog to stderr and prints summaries to stdout), killed after `timeout` (status `None`), and
/// registered for the interruption handler, which kills it if the run is interrupted.
fn run_bounded(
    mut command: Command,
    timeout: Duration,
) -> std::io::Result<(Option<ExitStatus>, String)> {
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    // Read on threads of their own, so that a chatty step never blocks on a full pipe.
    let read = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut pipe) = pipe {
                pipe.read_to_end(&mut bytes).ok();
            }
            bytes
        })
    };
    let stdout = read(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let stderr = read(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let child = crate::interrupt::Child::register(child);
    let began = Instant::now();
    let status = loop {
        let mut process = child.process();
        if let Some(status) = process.try_wait()? {
            break Some(status);
        }
        if began.elapsed() >= timeout {
            process.kill().ok();
            process.wait().ok();
            break None;
        }
        drop(process);
        std::thread::sleep(Duration::from_millis(50));
    };
    drop(child);
    let mut text = String::new();
    // A grandchild that keeps the pipes open (a shell's background job) is not waited for.
    for reader in [stdout, stderr] {
        if status.is_some() || reader.is_finished() {
            text.push_str(&String::from_utf8_lossy(&reader.join().unwrap_or_default()));
        }
    }
    Ok((status, text))
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
