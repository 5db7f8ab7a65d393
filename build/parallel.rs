//! Runs the compiler's commands side by side: one nvcc per kernel file and architecture, so the CUDA build
//! takes about (all the work) / (cores) rather than the sum of its steps.

use std::process::Command;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// How many commands run at once: cargo's job count (`NUM_JOBS`, from `-j` or the number of cores).
pub fn threads() -> usize {
    std::env::var("NUM_JOBS")
        .ok()
        .and_then(|n| n.parse().ok())
        .or_else(|| std::thread::available_parallelism().ok().map(Into::into))
        .unwrap_or(1)
        .max(1)
}

/// Runs every command, `threads` at a time, taking them in the order given (put the longest first), and
/// returns each one's output (stdout, then stderr) in that order. On a failure no further command starts,
/// and once those running have ended the build stops with the failed command line and its output.
pub fn run_all(commands: Vec<Command>, threads: usize) -> Vec<String> {
    let count = commands.len();
    let queue = Mutex::new(commands.into_iter().enumerate());
    let outputs = Mutex::new(vec![String::new(); count]);
    let failures = Mutex::new(Vec::new());
    let failed = AtomicBool::new(false);
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, count.max(1)) {
            scope.spawn(|| {
                while !failed.load(Ordering::Relaxed) {
                    let Some((index, mut command)) = lock(&queue).next() else {
                        break;
                    };
                    match run(&mut command) {
                        Ok(text) => lock(&outputs)[index] = text,
                        Err(report) => {
                            failed.store(true, Ordering::Relaxed);
                            lock(&failures).push(report);
                        }
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap_or_else(|p| p.into_inner());
    if !failures.is_empty() {
        panic!("clatch: kernel build failed:\n{}", failures.join("\n"));
    }
    outputs.into_inner().unwrap_or_else(|p| p.into_inner())
}

/// Runs one command: its output, or on failure the exact command line with its output.
pub fn run(command: &mut Command) -> Result<String, String> {
    let output = command
        .output()
        .map_err(|e| format!("  {command:?}\ncannot run it: {e}"))?;
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    if output.status.success() {
        Ok(text)
    } else {
        Err(format!("  {command:?}\n{text}"))
    }
}

/// A poisoned lock means another worker panicked, which the scope re-raises: its data is still usable.
fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|p| p.into_inner())
}
