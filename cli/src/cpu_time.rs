//! CPU time of this process, to report beside wall time: on a machine shared with other work, wall
//! time says more about the neighbours than about the program.

use std::time::Duration;

/// User plus system CPU time of this process and its finished children, where the system reports it
/// (Linux: `/proc/self/stat`); `None` elsewhere.
pub fn process_cpu_time() -> Option<Duration> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15, cutime 16,
    // cstime 17 (proc(5)), in clock ticks of 1/100 s on Linux.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<u64> = rest
        .split_whitespace()
        .skip(11)
        .take(4)
        .map(|f| f.parse().ok())
        .collect::<Option<_>>()?;
    let ticks: u64 = fields.iter().sum();
    Some(Duration::from_millis(ticks * 10))
}

/// Wall and CPU time of a stage.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTime {
    /// Wall-clock time.
    pub wall: Duration,
    /// CPU time (all threads, and the COLMAP child processes the stage waited for), if known.
    pub cpu: Option<Duration>,
}

/// Times a stage: call [`Stopwatch::stop`] at its end.
pub struct Stopwatch {
    wall: std::time::Instant,
    cpu: Option<Duration>,
}

impl Stopwatch {
    /// Starts timing now.
    pub fn start() -> Self {
        Self {
            wall: std::time::Instant::now(),
            cpu: process_cpu_time(),
        }
    }

    /// Wall and CPU time since [`Stopwatch::start`].
    pub fn stop(&self) -> StageTime {
        StageTime {
            wall: self.wall.elapsed(),
            cpu: self
                .cpu
                .zip(process_cpu_time())
                .map(|(start, end)| end.saturating_sub(start)),
        }
    }
}

impl std::fmt::Display for StageTime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:.2} s", self.wall.as_secs_f64())?;
        if let Some(cpu) = self.cpu {
            write!(f, " (cpu {:.2} s)", cpu.as_secs_f64())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Only Linux has /proc/self/stat; elsewhere the reports simply leave CPU time out.
    #[cfg(target_os = "linux")]
    #[test]
    fn cpu_time_grows_with_work() {
        let watch = Stopwatch::start();
        // Spin until the process has used 50 ms of CPU (or give up after 20 s of wall time).
        let mut x = 0u64;
        while watch.stop().cpu.unwrap() < Duration::from_millis(50)
            && watch.wall.elapsed() < Duration::from_secs(20)
        {
            for i in 0..1_000_000u64 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
            }
            std::hint::black_box(x);
        }
        let t = watch.stop();
        assert!(t.cpu.unwrap() >= Duration::from_millis(50), "{t}");
        assert!(t.wall >= Duration::from_millis(10), "{t}");
        assert!(t.to_string().contains(" s (cpu "), "{t}");
    }
}
