//! The Python package (`python/`) built and tested as a user installs it: `pip install ./python` into a
//! virtual environment under `target/tmp/python-package` (maturin builds the extension module with
//! cargo, release profile, in the workspace's target folder), then its pytest suite
//! (`python/tests`), which compares the package with this crate's `clatch` binary (`CLATCH_CLI`).
//!
//! Needs python3 (3.9 or later) with venv, pip, numpy, pytest and maturin importable (CI installs the
//! pinned versions, see `.ci/run`). Without them the test is reported as ignored with
//! `skipped: <reason>`, never as passed; with `CLATCH_REQUIRE_PYTHON` set (as in CI) a missing
//! prerequisite fails instead. `CLATCH_PYTHON` picks the interpreter; `CLATCH_TEST_BACKEND` (e.g.
//! `cuda`) is passed to the suite. `python/tests/test_ray.py` (`clatch.ray` on a local Ray cluster)
//! needs the base interpreter's `ray` (2.60.0 in CI) and is skipped without it, unless
//! `CLATCH_REQUIRE_RAY` is set (as in CI): then a missing Ray fails the suite. The virtual environment is kept between runs (it only holds the
//! package); the build is incremental like any cargo build.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use libtest_mimic::{Arguments, Failed, Trial};

/// Set (by CI) to make a missing prerequisite a failure instead of an ignored test.
const REQUIRE: &str = "CLATCH_REQUIRE_PYTHON";

/// Prints the interpreter's version and where its maturin is, or fails naming what is missing.
const PROBE: &str = r#"
import os, shutil, sys, sysconfig
assert sys.version_info >= (3, 9), f"python {sys.version.split()[0]} is older than 3.9"
missing = []
for module in ("venv", "pip", "numpy", "pytest", "maturin"):
    try:
        __import__(module)
    except ImportError:
        missing.append(module)
if missing:
    sys.exit("not installed: " + ", ".join(missing))
scripts = sysconfig.get_path("scripts")
maturin = shutil.which("maturin", path=os.pathsep.join([scripts, os.environ.get("PATH", "")]))
if maturin is None:
    sys.exit("the maturin command is not on PATH nor in " + scripts)
import numpy, pytest
print(sys.version.split()[0], numpy.__version__, pytest.__version__, os.path.dirname(maturin), sep="\n")
"#;

fn main() {
    let args = Arguments::from_args();
    let trial = Trial::test("python_package_pytest_suite", run_suite);
    let trial = match probe() {
        Ok(found) => {
            println!(
                "python {}, numpy {}, pytest {}, maturin in {}",
                found.python,
                found.numpy,
                found.pytest,
                found.maturin_dir.display()
            );
            trial
        }
        Err(reason) if std::env::var_os(REQUIRE).is_some() => {
            eprintln!("{REQUIRE} is set but the Python prerequisites are missing: {reason}");
            std::process::exit(1);
        }
        Err(reason) => {
            println!("skipped: {reason}");
            trial.with_ignored_flag(true)
        }
    };
    libtest_mimic::run(&args, vec![trial]).exit()
}

fn python() -> String {
    std::env::var("CLATCH_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// The repository root (this crate is `cli/`).
fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("cli/ has a parent")
        .to_path_buf()
}

struct Found {
    python: String,
    numpy: String,
    pytest: String,
    maturin_dir: PathBuf,
}

fn probe() -> Result<Found, String> {
    let output = Command::new(python())
        .args(["-c", PROBE])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python()))?;
    if !output.status.success() {
        let err = String::from_utf8_lossy(&output.stderr);
        return Err(err.lines().last().unwrap_or("the probe failed").to_string());
    }
    let out = String::from_utf8_lossy(&output.stdout);
    let lines: Vec<&str> = out.lines().collect();
    match lines.as_slice() {
        [python, numpy, pytest, maturin] => Ok(Found {
            python: python.to_string(),
            numpy: numpy.to_string(),
            pytest: pytest.to_string(),
            maturin_dir: PathBuf::from(maturin),
        }),
        _ => Err(format!("unexpected probe output: {out}")),
    }
}

/// Runs `command`, its output passed through, failing with `what` unless it succeeds.
fn run(what: &str, command: &mut Command) -> Result<(), Failed> {
    let status = command
        .stdin(Stdio::null())
        .status()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    if !status.success() {
        return Err(format!("{what} failed ({status})").into());
    }
    Ok(())
}

fn run_suite() -> Result<(), Failed> {
    let found = probe()?;
    let root = repo();
    let work = Path::new(env!("CARGO_TARGET_TMPDIR")).join("python-package");
    let venv = work.join("venv");
    let venv_python = venv.join("bin").join("python");
    // One environment per base interpreter: recreated when CLATCH_PYTHON names another one.
    let marker = work.join("base-python");
    let base = format!("{} {}", python(), found.python);
    if !venv_python.is_file() || std::fs::read_to_string(&marker).ok().as_deref() != Some(&base) {
        let _ = std::fs::remove_dir_all(&venv);
        std::fs::create_dir_all(&work)?;
        // The base interpreter's numpy, pytest and maturin are used: nothing is downloaded.
        run(
            "python -m venv",
            Command::new(python())
                .args(["-m", "venv", "--system-site-packages"])
                .arg(&venv),
        )?;
        std::fs::write(&marker, &base)?;
    }
    let path = std::env::join_paths(std::iter::once(found.maturin_dir.clone()).chain(
        std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default()),
    ))?;

    let start = Instant::now();
    run(
        "pip install ./python",
        Command::new(&venv_python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                "--no-build-isolation",
                "--no-deps",
                "--force-reinstall",
                "./python",
            ])
            .current_dir(&root)
            .env("PATH", &path),
    )?;
    let built = start.elapsed();

    let start = Instant::now();
    // From the repository root, so that `python/clatch` (the sources, without the native module)
    // cannot shadow the installed package; no bytecode or cache written into the tree.
    run(
        "pytest python/tests",
        Command::new(&venv_python)
            .args([
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                "python/tests",
            ])
            .current_dir(&root)
            .env("PATH", &path)
            .env("PYTHONDONTWRITEBYTECODE", "1")
            .env("CLATCH_CLI", env!("CARGO_BIN_EXE_clatch")),
    )?;
    println!(
        "python package: pip install {:.1} s, pytest {:.1} s",
        built.as_secs_f64(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
