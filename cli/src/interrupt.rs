//! Ending cleanly on SIGINT, SIGTERM and SIGHUP: the running `colmap` step is killed, every
//! temporary file and folder of this process and its locks are removed
//! ([`clatch::output::remove_temporaries`], which waits for renames in progress), and the process
//! exits with 130 (128 + SIGINT's number, as shells report an interrupted command). SIGKILL cannot be
//! caught: what such a run leaves is swept by the next run that writes into the same folder
//! ([`clatch::output::sweep_stale_temporaries`]).

use std::process::Child as Process;
use std::sync::{Arc, Mutex};

/// The running child processes.
static CHILDREN: Mutex<Vec<Arc<Mutex<Process>>>> = Mutex::new(Vec::new());

/// Installs the handler; a failure to install it is a warning (the run works, an interruption then
/// leaves its temporary files to the next run's sweep).
pub fn install() {
    if let Err(e) = ctrlc::set_handler(|| {
        for child in std::mem::take(&mut *lock(&CHILDREN)) {
            let mut child = lock(&child);
            child.kill().ok();
            child.wait().ok();
        }
        clatch::output::remove_temporaries();
        eprintln!("clatch: interrupted; its temporary files are removed, nothing was replaced");
        std::process::exit(130);
    }) {
        eprintln!(
            "clatch: warning: cannot handle interruptions ({e}); temporary files of an interrupted run are removed by the next one"
        );
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A child process killed by the handler if the run is interrupted; unregistered when dropped.
pub struct Child(Arc<Mutex<Process>>);

impl Child {
    /// Registers `process`.
    pub fn register(process: Process) -> Self {
        let shared = Arc::new(Mutex::new(process));
        lock(&CHILDREN).push(shared.clone());
        Self(shared)
    }

    /// The process, for waiting on it.
    pub fn process(&self) -> std::sync::MutexGuard<'_, Process> {
        lock(&self.0)
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        lock(&CHILDREN).retain(|c| !Arc::ptr_eq(c, &self.0));
    }
}
