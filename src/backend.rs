//! Where the work runs. Every backend returns the same bits; only speed differs.

use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::cuda::SetUpSteps;

use crate::error::{Error, Result};
use crate::names::ParseNameError;

/// The compute backend of an [`crate::Extractor`] or [`crate::Matcher`].
///
/// Both variants exist in every build, so code that chooses a backend needs no `cfg`: without the
/// `cuda` feature, `Backend::Cuda` is refused at construction with [`Error::BackendUnavailable`].
///
/// ```
/// use clatch::{Backend, Error, Extractor, ExtractorConfig};
///
/// match Extractor::new(Backend::Cuda { device: 0 }, ExtractorConfig::default()) {
///     Ok(extractor) => println!("extracting on {}", extractor.backend()),
///     Err(Error::BackendUnavailable { reason, .. }) => println!("no GPU ({reason}); using the CPU"),
///     Err(other) => return Err(other),
/// }
/// # Ok::<(), clatch::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Backend {
    /// The CPU: rayon over all cores with the `cpu` feature (the default), one thread without it.
    /// This is the reference implementation.
    Cpu,
    /// An NVIDIA GPU. Needs the `cuda` feature, a driver and the device.
    Cuda {
        /// Device ordinal, as in `CUDA_VISIBLE_DEVICES` order.
        device: usize,
    },
}

impl Backend {
    /// CUDA device 0 when the `cuda` feature is compiled in and a device is usable, else the CPU.
    pub fn auto() -> Self {
        let gpu = Backend::Cuda { device: 0 };
        if gpu.ensure_available().is_ok() {
            gpu
        } else {
            Backend::Cpu
        }
    }

    /// Checks that this backend can run here (always true for the CPU): for CUDA that the feature is
    /// compiled in, the driver loads, the device exists and clatch's kernels load on it.
    pub fn ensure_available(&self) -> Result<()> {
        match *self {
            Backend::Cpu => Ok(()),
            Backend::Cuda { device } => cuda_available(device),
        }
    }

    /// How long each step of this backend's set-up took in this process, once it has run and
    /// succeeded (by [`Backend::ensure_available`], [`Backend::start`] or the first extractor or
    /// matcher); `None` for the CPU, which needs none, and for a GPU not set up (yet). Waits for a
    /// set-up in progress on another thread.
    ///
    /// ```
    /// use clatch::Backend;
    ///
    /// assert_eq!(Backend::Cpu.set_up_steps(), None);
    /// if let Some(steps) = (Backend::Cuda { device: 0 }).set_up_steps() {
    ///     println!("set-up {:?}: {steps}", steps.total());
    /// }
    /// ```
    pub fn set_up_steps(&self) -> Option<SetUpSteps> {
        match *self {
            Backend::Cpu => None,
            Backend::Cuda { device } => cuda_set_up_steps(device),
        }
    }

    /// Starts [`Backend::ensure_available`]'s work on a thread of its own and returns at once, so
    /// that the set-up (on a GPU the driver, the context and the kernels: a quarter of a second on an
    /// H200) overlaps the caller's own work, such as reading and decoding the first images. An
    /// [`crate::Extractor::starting`] made from the handle is usable at once; its first call waits
    /// for the set-up. Extractors and matchers made the usual way meanwhile wait for it too, rather
    /// than repeating it. The CPU needs no set-up: its handle is ready at once.
    ///
    /// ```
    /// use clatch::{Backend, Extractor, ExtractorConfig, GrayView};
    ///
    /// let start = Backend::Cpu.start()?;
    /// let extractor = Extractor::starting(&start, ExtractorConfig::default())?;
    /// let pixels = clatch::synthetic::rectangles(200, 150, 3)?; // decoding, while the backend starts
    /// let features = extractor.detect_and_describe(&GrayView::new(&pixels, 200, 150, 200)?)?;
    /// let set_up = start.wait()?; // how long the set-up took, or why it failed
    /// assert!(set_up.as_secs() < 60 && !features.keypoints.is_empty());
    /// # Ok::<(), clatch::Error>(())
    /// ```
    ///
    /// What is known without any set-up is an error at once: a build without the `cuda` feature, or
    /// no CUDA driver on the machine.
    pub fn start(self) -> Result<BackendStart> {
        let thread = match self {
            Backend::Cpu => None,
            Backend::Cuda { device } => {
                cuda_driver_present(device)?;
                Some(std::thread::spawn(move || {
                    let began = Instant::now();
                    self.ensure_available().map(|()| began.elapsed())
                }))
            }
        };
        Ok(BackendStart {
            backend: self,
            thread,
        })
    }
}

/// A backend's set-up running on a thread of its own: [`Backend::start`].
///
/// Keep the handle for as long as the set-up should run beside your work: dropping it waits for the
/// set-up to end, so that no thread is ever left inside the driver when the program exits (an early
/// error return then comes back after the set-up, not during it).
#[derive(Debug)]
#[must_use = "wait for the set-up to learn whether the backend is usable"]
pub struct BackendStart {
    backend: Backend,
    /// None for the CPU, which needs no set-up.
    thread: Option<JoinHandle<Result<Duration>>>,
}

impl BackendStart {
    /// The backend being set up.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// Whether the set-up has ended (well or not): [`BackendStart::wait`] then returns at once.
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Waits for the set-up and returns how long it took (zero for the CPU), or the error
    /// [`Backend::ensure_available`] gives.
    pub fn wait(mut self) -> Result<Duration> {
        match self.thread.take() {
            None => Ok(Duration::ZERO),
            Some(thread) => thread.join().unwrap_or_else(|_| {
                Err(Error::Internal {
                    operation: "the backend's set-up",
                    message: format!("the set-up thread of {} panicked", self.backend),
                })
            }),
        }
    }
}

impl Drop for BackendStart {
    fn drop(&mut self) {
        if let Some(thread) = self.thread.take() {
            // The outcome is the caller's to ask for with `wait`; dropped, it is only waited for.
            let _ = thread.join();
        }
    }
}

#[cfg(feature = "cuda")]
fn cuda_available(device: usize) -> Result<()> {
    crate::cuda::ensure_available(device)
}

#[cfg(not(feature = "cuda"))]
fn cuda_available(device: usize) -> Result<()> {
    Err(crate::cuda::unavailable(device, crate::cuda::NOT_BUILT))
}

#[cfg(feature = "cuda")]
fn cuda_set_up_steps(device: usize) -> Option<SetUpSteps> {
    crate::cuda::set_up_steps(device)
}

#[cfg(not(feature = "cuda"))]
fn cuda_set_up_steps(_device: usize) -> Option<SetUpSteps> {
    None
}

#[cfg(feature = "cuda")]
fn cuda_driver_present(device: usize) -> Result<()> {
    crate::cuda::check_driver(device)
}

#[cfg(not(feature = "cuda"))]
fn cuda_driver_present(device: usize) -> Result<()> {
    cuda_available(device)
}

/// The names [`Backend`]'s `FromStr` accepts, as its error lists them.
const BACKEND_NAMES: &[&str] = &["auto", "cpu", "cuda", "cuda:N"];

impl Backend {
    /// The name `FromStr` reads back as this backend: `cpu`, or `cuda:N` for device N. (`Display`
    /// writes the CPU's thread count besides: `cpu (16 threads)`.)
    ///
    /// ```
    /// use clatch::Backend;
    ///
    /// assert_eq!(Backend::Cpu.name(), "cpu");
    /// let gpu = Backend::Cuda { device: 1 };
    /// assert_eq!(gpu.name(), "cuda:1");
    /// assert_eq!(gpu.name().parse::<Backend>()?, gpu);
    /// # Ok::<(), clatch::ParseNameError>(())
    /// ```
    pub fn name(&self) -> String {
        match self {
            Backend::Cpu => "cpu".into(),
            Backend::Cuda { device } => format!("cuda:{device}"),
        }
    }
}

/// Reads a backend by name: `cpu`; `cuda` (device 0) or `cuda:N` (device N, in decimal digits); or
/// `auto`, which is [`Backend::auto`] and so checks the device while it is parsed. Anything else
/// (other case, spaces) is a [`ParseNameError`] listing these names.
///
/// ```
/// use clatch::Backend;
///
/// assert_eq!("cpu".parse::<Backend>()?, Backend::Cpu);
/// assert_eq!("cuda".parse::<Backend>()?, Backend::Cuda { device: 0 });
/// assert_eq!("cuda:2".parse::<Backend>()?, Backend::Cuda { device: 2 });
/// let error = "gpu".parse::<Backend>().unwrap_err();
/// assert_eq!(error.accepted(), ["auto", "cpu", "cuda", "cuda:N"]);
/// # Ok::<(), clatch::ParseNameError>(())
/// ```
impl std::str::FromStr for Backend {
    type Err = ParseNameError;

    fn from_str(name: &str) -> std::result::Result<Self, ParseNameError> {
        let ordinal = |d: &&str| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit());
        match name {
            "auto" => Ok(Backend::auto()),
            "cpu" => Ok(Backend::Cpu),
            "cuda" => Ok(Backend::Cuda { device: 0 }),
            _ => name
                .strip_prefix("cuda:")
                .filter(ordinal)
                .and_then(|d| d.parse().ok())
                .map(|device| Backend::Cuda { device })
                .ok_or_else(|| ParseNameError::new("backend", name, BACKEND_NAMES.to_vec())),
        }
    }
}

impl Default for Backend {
    fn default() -> Self {
        Self::auto()
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Backend::Cpu => write!(f, "cpu ({} threads)", crate::parallel::threads()),
            Backend::Cuda { device } => write!(f, "cuda:{device}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    #[test]
    fn dropping_a_start_waits_for_its_set_up() {
        let done = Arc::new(AtomicBool::new(false));
        let flag = done.clone();
        let start = BackendStart {
            backend: Backend::Cuda { device: 0 },
            thread: Some(std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(50));
                flag.store(true, Ordering::SeqCst);
                Ok(Duration::from_millis(50))
            })),
        };
        drop(start);
        assert!(done.load(Ordering::SeqCst), "the set-up was still running");
    }

    #[test]
    fn backend_names_read_back() {
        for backend in [
            Backend::Cpu,
            Backend::Cuda { device: 0 },
            Backend::Cuda { device: 17 },
        ] {
            assert_eq!(backend.name().parse::<Backend>(), Ok(backend));
        }
        assert_eq!("cuda".parse::<Backend>(), Ok(Backend::Cuda { device: 0 }));
        assert!(matches!(
            "auto".parse::<Backend>(),
            Ok(Backend::Cpu | Backend::Cuda { device: 0 })
        ));
        for wrong in [
            "",
            "gpu",
            "CPU",
            "cpu ",
            " cuda",
            "cuda:",
            "cuda:x",
            "cuda:-1",
            "cuda:+1",
            "cuda:1.0",
            "cuda:99999999999999999999999",
            "cuda0",
        ] {
            let error = wrong.parse::<Backend>().unwrap_err();
            assert_eq!((error.option(), error.given()), ("backend", wrong));
            assert_eq!(error.accepted(), BACKEND_NAMES);
        }
    }

    #[test]
    fn a_panicking_set_up_is_an_internal_error() {
        let start = BackendStart {
            backend: Backend::Cuda { device: 0 },
            thread: Some(std::thread::spawn(|| panic!("set-up (on purpose)"))),
        };
        assert!(matches!(start.wait(), Err(Error::Internal { .. })));
    }
}
