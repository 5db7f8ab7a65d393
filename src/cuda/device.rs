//! One loaded device: context, kernels and the constant tables, created once per ordinal.

use std::collections::HashMap;
#[cfg(feature = "internals")]
use std::sync::OnceLock;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use cudarc::driver::{CudaContext, CudaEvent, CudaFunction, CudaSlice, CudaStream, sys};
use cudarc::nvrtc::Ptx;

use super::error::driver_error;
#[cfg(feature = "internals")]
use super::kernels::BENCH_KERNELS;
use super::kernels::{KERNELS, Kernel, KernelFile, tensor_cores_on};
use super::matching_tensor::{self, MatchKernel};
use super::memory::arena::LanePool;
use super::ptx;
use super::registry::PerOrdinal;
use super::set_up::SetUpSteps;
use crate::angle::{quadrant_boundaries, rotation_table};
use crate::describe::triplets::TRIPLETS;
use crate::error::{Error, Result};

/// A CUDA device with clatch's kernels loaded and its tables uploaded.
#[derive(Debug)]
pub struct GpuDevice {
    pub(crate) ctx: Arc<CudaContext>,
    kernels: HashMap<Kernel, CudaFunction>,
    pub(crate) rotation: CudaSlice<i32>,
    pub(crate) triplets: CudaSlice<u8>,
    /// `angle::quadrant_boundaries()`, flattened `(x, y)` pairs: the detector's orientation bins.
    pub(crate) boundaries: CudaSlice<i64>,
    pub(crate) pitch_alignment: usize,
    pub(crate) multiprocessors: usize,
    /// Compute capability, `86` for 8.6: which bench kernel files load.
    #[cfg(feature = "internals")]
    capability: u32,
    /// Whether the tensor-core kNN kernels are loaded (compute capability 8.0 and later).
    tensor_cores: bool,
    /// The kNN kernels asked for with `CLATCH_MATCH_KERNEL`, if any.
    match_kernel_override: Option<MatchKernel>,
    name: String,
    /// Whether kernels are loaded from PTX rather than the fatbins (`CLATCH_FORCE_PTX=1`).
    #[cfg(feature = "internals")]
    force_ptx: bool,
    #[cfg(feature = "internals")]
    bench_kernels: OnceLock<HashMap<Kernel, CudaFunction>>,
    /// Idle streams with their scratch arenas, for blocking calls and batches.
    pub(crate) lanes: LanePool,
    /// Descriptor weight tables uploaded so far, by value.
    weights: Mutex<HashMap<Vec<i32>, Arc<CudaSlice<i32>>>>,
    /// How long each step of [`GpuDevice::load`] took.
    set_up: SetUpSteps,
}

use super::set_up::unavailable;

/// The devices loaded so far, one slot per ordinal: different devices load side by side.
static DEVICES: PerOrdinal<GpuDevice> = PerOrdinal::new();

/// The loaded device `ordinal`, created on first use and shared afterwards.
pub fn device(ordinal: usize) -> Result<Arc<GpuDevice>> {
    DEVICES.get_or_load(ordinal, || {
        let began = Instant::now();
        check_driver(ordinal)?;
        let count = CudaContext::device_count()
            .map_err(|e| unavailable(ordinal, format!("no CUDA device ({e:?})")))?;
        if ordinal >= count.max(0) as usize {
            return Err(unavailable(
                ordinal,
                format!("no CUDA device {ordinal} ({count} present)"),
            ));
        }
        GpuDevice::load(ordinal, began.elapsed())
    })
}

/// [`crate::Backend::set_up_steps`] of device `ordinal`: `None` until it has loaded. Never loads it.
pub(crate) fn set_up_steps(ordinal: usize) -> Option<SetUpSteps> {
    DEVICES.get(ordinal).map(|dev| dev.set_up)
}

/// The driver library loads (cudarc panics on any call without it): the check that costs nothing.
pub(crate) fn check_driver(ordinal: usize) -> Result<()> {
    // SAFETY: only tries to open the driver library.
    if unsafe { sys::is_culib_present() } {
        Ok(())
    } else {
        Err(unavailable(
            ordinal,
            "no CUDA driver (libcuda) on this machine",
        ))
    }
}

impl GpuDevice {
    /// Creates the context, loads the kernels and uploads the tables; `driver` is the time already
    /// spent in `cuInit` (by [`device`]), recorded with the other steps.
    fn load(ordinal: usize, driver: Duration) -> Result<Self> {
        let mut step = Instant::now();
        // One clock read per step boundary, so that the steps add up to the whole load.
        let mut lap = || {
            let now = Instant::now();
            now.duration_since(std::mem::replace(&mut step, now))
        };
        let ctx = CudaContext::new(ordinal).map_err(driver_error("context creation"))?;
        // cudarc by default gives every buffer two events and waits on / records them around every
        // use, so that a buffer can hop between streams safely. clatch never lets one hop: each call
        // allocates, uses and frees its buffers on its own stream (frees are stream-ordered), and the
        // tables below are uploaded on the default stream and synchronised before any other stream
        // exists. The tracking cost ~2 driver calls per kernel argument and most of the host time of
        // a queued image. With it off, cudarc never records a `PinnedHostSlice`'s own event either, so
        // its `as_slice`, `as_mut_slice` and drop return at once even with copies queued: every user of
        // pinned memory records and waits on events of its own (`memory.rs`, `collection/grouped.rs`).
        // SAFETY: the invariant above: no buffer is used on a stream other than the one it was
        // allocated on, except the tables, which are complete before they are shared.
        unsafe { ctx.disable_event_tracking() };
        let context = lap();
        if ptx::STUB {
            return Err(unavailable(
                ordinal,
                "this clatch was built with stub kernels (a documentation build)",
            ));
        }
        let mut kernels = HashMap::new();
        // The fatbin's native code loads without JIT on the GPUs it was built for (and falls back to its
        // PTX elsewhere); CLATCH_FORCE_PTX=1 loads the plain PTX instead, so tests can prove both paths.
        let force_ptx = std::env::var_os("CLATCH_FORCE_PTX").is_some_and(|v| v == "1");
        let (major, minor) = ctx
            .compute_capability()
            .map_err(driver_error("reading the compute capability"))?;
        // A file whose instructions this device lacks (the int8 MMA before 8.0) is not loaded; the
        // matcher then keeps to the popcount kernels.
        let capability = u32::try_from(major * 10 + minor).unwrap_or(0);
        let tensor_cores = tensor_cores_on(capability);
        for file in KERNELS.iter().filter(|f| f.runs_on(capability)) {
            load_module(&ctx, force_ptx, file, &mut kernels)?;
        }
        let kernels_loaded = lap();
        let stream = ctx.default_stream();
        let rotation: Vec<i32> = rotation_table().iter().flatten().copied().collect();
        let rotation = stream
            .clone_htod(&rotation)
            .map_err(driver_error("uploading the rotation table"))?;
        let triplets: Vec<u8> = TRIPLETS.iter().flatten().copied().collect();
        let triplets = stream
            .clone_htod(&triplets)
            .map_err(driver_error("uploading the triplet table"))?;
        let boundaries: Vec<i64> = quadrant_boundaries().iter().flatten().copied().collect();
        let boundaries = stream
            .clone_htod(&boundaries)
            .map_err(driver_error("uploading the direction boundaries"))?;
        stream
            .synchronize()
            .map_err(driver_error("uploading the tables"))?;
        let attribute = |a| {
            ctx.attribute(a)
                .map_err(driver_error("reading device attributes"))
        };
        let pitch_alignment =
            attribute(sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_TEXTURE_PITCH_ALIGNMENT)?
                as usize;
        let multiprocessors =
            attribute(sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_MULTIPROCESSOR_COUNT)? as usize;
        let name = ctx
            .name()
            .map_err(driver_error("reading the device name"))?;
        let set_up = SetUpSteps {
            driver,
            context,
            kernels: kernels_loaded,
            tables: lap(),
        };
        Ok(Self {
            ctx,
            kernels,
            rotation,
            triplets,
            boundaries,
            pitch_alignment,
            multiprocessors,
            #[cfg(feature = "internals")]
            capability,
            tensor_cores,
            match_kernel_override: MatchKernel::from_env(),
            name,
            #[cfg(feature = "internals")]
            force_ptx,
            #[cfg(feature = "internals")]
            bench_kernels: OnceLock::new(),
            lanes: LanePool::default(),
            weights: Mutex::default(),
            set_up,
        })
    }

    /// Forgets the uploaded weight tables (test hooks: a cold start). Work queued with one keeps it
    /// alive until it has run (`Lane::keep_until_passed`).
    #[cfg(feature = "internals")]
    pub(crate) fn clear_weights(&self) {
        self.weights
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clear();
    }

    /// `values` (a descriptor weight table) on the device, uploaded on first use. Like the tables of
    /// [`GpuDevice::load`], the upload runs on the default stream and is complete before the buffer is
    /// shared with any stream, so it never needs event tracking; it is never written afterwards.
    pub(crate) fn weights(&self, values: Vec<i32>) -> Result<Arc<CudaSlice<i32>>> {
        let mut tables = self.weights.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(table) = tables.get(&values) {
            return Ok(table.clone());
        }
        let stream = self.ctx.default_stream();
        let table = Arc::new(super::memory::upload(&stream, &values, "weight upload")?);
        stream
            .synchronize()
            .map_err(driver_error("weight upload"))?;
        // Kept for the process (256 bytes each; a program uses one or two): a table is never freed
        // while a stream may still read it.
        tables.insert(values, table.clone());
        Ok(table)
    }

    /// Loads the bench and diagnostic kernels (once; later calls do nothing), so that
    /// [`GpuDevice::kernel`] finds them.
    #[cfg(feature = "internals")]
    pub(crate) fn load_bench_kernels(&self) -> Result<()> {
        if self.bench_kernels.get().is_some() {
            return Ok(());
        }
        let mut kernels = HashMap::new();
        let usable = BENCH_KERNELS.iter().filter(|f| f.runs_on(self.capability));
        for file in usable {
            load_module(&self.ctx, self.force_ptx, file, &mut kernels)?;
        }
        // A concurrent caller may have won: its table is the same.
        let _ = self.bench_kernels.set(kernels);
        Ok(())
    }

    /// The kNN kernels matching uses for `k` neighbours: the tensor cores where the device has them and
    /// k <= 2, unless `CLATCH_MATCH_KERNEL=popcount` says otherwise; the popcount kernels elsewhere.
    pub(crate) fn match_kernel(&self, k: usize) -> MatchKernel {
        let tensor_ok = self.tensor_cores && k <= matching_tensor::MAX_K;
        match self.match_kernel_override {
            Some(MatchKernel::Popcount) => MatchKernel::Popcount,
            _ if tensor_ok => MatchKernel::Tensor,
            _ => MatchKernel::Popcount,
        }
    }

    /// `kernel` if this device can run it for `k` neighbours, else a typed error.
    pub(crate) fn check_match_kernel(&self, kernel: MatchKernel, k: usize) -> Result<MatchKernel> {
        if kernel == MatchKernel::Tensor && !self.tensor_cores {
            return Err(Error::BackendUnavailable {
                backend: format!("cuda tensor-core matcher on {}", self.name),
                reason: "needs compute capability 8.0 or later".into(),
            });
        }
        if kernel == MatchKernel::Tensor && k > matching_tensor::MAX_K {
            return Err(Error::KTooLargeForBackend {
                k,
                max: matching_tensor::MAX_K,
                backend: "cuda tensor-core matcher".into(),
            });
        }
        Ok(kernel)
    }

    /// Whether the tensor-core kNN kernels are loaded on this device (test hooks).
    #[cfg(feature = "internals")]
    pub fn has_tensor_matcher(&self) -> bool {
        self.tensor_cores
    }

    /// A loaded kernel, by its `extern "C"` name (one listed in `KERNELS`, or with the `internals`
    /// feature in `BENCH_KERNELS` once loaded). Every name the crate asks for is one of its own
    /// constants, so a miss is a bug in clatch.
    pub(crate) fn kernel(&self, kernel: Kernel) -> &CudaFunction {
        #[cfg(feature = "internals")]
        if let Some(f) = self.bench_kernels.get().and_then(|k| k.get(&kernel)) {
            return f;
        }
        self.kernels
            .get(&kernel)
            .unwrap_or_else(|| panic!("kernel {} is not listed in KERNELS", kernel.name()))
    }

    /// The device's name, e.g. "NVIDIA H100 80GB HBM3".
    pub fn name(&self) -> &str {
        &self.name
    }

    /// A new stream owned by the caller (never the default stream).
    pub(crate) fn new_stream(&self) -> Result<Arc<CudaStream>> {
        self.ctx
            .new_stream()
            .map_err(driver_error("stream creation"))
    }

    /// A new event without timing, not yet recorded (waiting on it returns at once until it is).
    pub(crate) fn new_event(&self) -> Result<CudaEvent> {
        self.ctx
            .new_event(None)
            .map_err(driver_error("event creation"))
    }
}

/// Loads one kernel file (its fatbin, or its PTX when `force_ptx`) and its entry points into `kernels`.
fn load_module(
    ctx: &Arc<CudaContext>,
    force_ptx: bool,
    file: &KernelFile,
    kernels: &mut HashMap<Kernel, CudaFunction>,
) -> Result<()> {
    let image = if force_ptx {
        Ptx::from_src(file.ptx)
    } else {
        Ptx::from_binary(file.fatbin.to_vec())
    };
    let module = ctx.load_module(image).map_err(driver_error(file.path))?;
    for kernel in file.entry_points() {
        let name = kernel.name();
        let function = module.load_function(name).map_err(driver_error(name))?;
        matching_tensor::configure(name, &function)?;
        kernels.insert(kernel, function);
    }
    Ok(())
}

#[cfg(feature = "internals")]
/// Times `launch` with CUDA events on `stream`: `warmup` untimed calls, then `repeats` timed ones
/// (milliseconds each).
pub(crate) fn time_launches(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    warmup: usize,
    repeats: usize,
    mut launch: impl FnMut() -> Result<()>,
) -> Result<Vec<f32>> {
    for _ in 0..warmup {
        launch()?;
    }
    let timing = Some(sys::CUevent_flags::CU_EVENT_DEFAULT);
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let start = dev
            .ctx
            .new_event(timing)
            .map_err(driver_error("event creation"))?;
        let end = dev
            .ctx
            .new_event(timing)
            .map_err(driver_error("event creation"))?;
        start.record(stream).map_err(driver_error("event record"))?;
        launch()?;
        end.record(stream).map_err(driver_error("event record"))?;
        times.push(
            start
                .elapsed_ms(&end)
                .map_err(driver_error("timed kernels"))?,
        );
    }
    Ok(times)
}
