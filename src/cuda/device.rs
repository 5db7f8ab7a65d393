//! One loaded device: context, kernels and the constant tables, created once per ordinal.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::{CudaContext, CudaFunction, CudaSlice, CudaStream, DriverError, sys};
use cudarc::nvrtc::Ptx;

use super::ptx;
use super::tensor_knn::{self, MatchKernel};
use crate::angle::{quadrant_boundaries, rotation_table};
use crate::describe::triplets::TRIPLETS;
use crate::error::{Error, Result};

/// Every kernel entry point, by the file that defines it (its portable PTX and its fatbin). Add a
/// kernel here and fetch it with [`GpuDevice::kernel`].
const KERNELS: &[(&str, &str, &[u8], &[&str])] = &[
    (
        "kernels/describe.cu",
        ptx::DESCRIBE_PTX,
        ptx::DESCRIBE_FATBIN,
        &[
            "clatch_describe",
            "clatch_describe_binary",
            "clatch_build_quads",
        ],
    ),
    (
        "kernels/describe_opencv.cu",
        ptx::DESCRIBE_OPENCV_PTX,
        ptx::DESCRIBE_OPENCV_FATBIN,
        &["clatch_describe_opencv"],
    ),
    (
        "kernels/detect.cu",
        ptx::DETECT_PTX,
        ptx::DETECT_FATBIN,
        &[
            "clatch_detect_nms",
            "clatch_scan_reduce",
            "clatch_scan_partials",
            "clatch_scan_apply",
            "clatch_detect_scatter",
            "clatch_detect_orient",
            "clatch_debug_read_texture",
        ],
    ),
    (
        "kernels/pyramid.cu",
        ptx::PYRAMID_PTX,
        ptx::PYRAMID_FATBIN,
        &["clatch_downscale"],
    ),
    (
        "kernels/match.cu",
        ptx::MATCH_PTX,
        ptx::MATCH_FATBIN,
        super::matching::KERNELS,
    ),
    (
        "kernels/match_variants.cu",
        ptx::MATCH_VARIANTS_PTX,
        ptx::MATCH_VARIANTS_FATBIN,
        super::matching::VARIANT_KERNELS,
    ),
];

/// Kernels for compute capability 8.0 and later (int8 MMA), loaded only there.
const TENSOR_KERNELS: (&str, &str, &[u8], &[&str]) = (
    "kernels/match_tensor.cu",
    ptx::MATCH_TENSOR_PTX,
    ptx::MATCH_TENSOR_FATBIN,
    tensor_knn::KERNELS,
);

/// A CUDA device with clatch's kernels loaded and its tables uploaded.
#[derive(Debug)]
pub struct GpuDevice {
    pub(crate) ctx: Arc<CudaContext>,
    kernels: HashMap<&'static str, CudaFunction>,
    pub(crate) rotation: CudaSlice<i32>,
    pub(crate) triplets: CudaSlice<u8>,
    /// `angle::quadrant_boundaries()`, flattened `(x, y)` pairs: the detector's orientation bins.
    pub(crate) boundaries: CudaSlice<i64>,
    pub(crate) pitch_alignment: usize,
    pub(crate) multiprocessors: usize,
    /// Whether the tensor-core kNN kernels are loaded (compute capability 8.0 and later).
    tensor_cores: bool,
    /// The kNN kernels asked for with `CLATCH_MATCH_KERNEL`, if any.
    match_kernel_override: Option<MatchKernel>,
    name: String,
}

/// Maps a driver error to ours, naming the operation.
pub(crate) fn driver_error(operation: &str) -> impl Fn(DriverError) -> Error + '_ {
    move |e| {
        let message = e
            .error_string()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|_| format!("{e:?}"));
        if e.0 == sys::cudaError_enum::CUDA_ERROR_OUT_OF_MEMORY {
            Error::DeviceOutOfMemory {
                operation: operation.to_string(),
                bytes: 0,
            }
        } else {
            Error::Cuda {
                operation: operation.to_string(),
                message,
            }
        }
    }
}

fn unavailable(ordinal: usize, reason: impl Into<String>) -> Error {
    Error::BackendUnavailable {
        backend: format!("cuda:{ordinal}"),
        reason: reason.into(),
    }
}

/// The loaded device `ordinal`, created on first use and shared afterwards.
pub fn device(ordinal: usize) -> Result<Arc<GpuDevice>> {
    static DEVICES: OnceLock<Mutex<HashMap<usize, Arc<GpuDevice>>>> = OnceLock::new();
    let mut devices = DEVICES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(dev) = devices.get(&ordinal) {
        return Ok(dev.clone());
    }
    // cudarc panics if libcuda cannot be loaded: ask first.
    // SAFETY: only tries to open the driver library.
    if !unsafe { sys::is_culib_present() } {
        return Err(unavailable(
            ordinal,
            "no CUDA driver (libcuda) on this machine",
        ));
    }
    let count = CudaContext::device_count()
        .map_err(|e| unavailable(ordinal, format!("no CUDA device ({e:?})")))?;
    if ordinal >= count.max(0) as usize {
        return Err(unavailable(
            ordinal,
            format!("no CUDA device {ordinal} ({count} present)"),
        ));
    }
    let dev = Arc::new(GpuDevice::load(ordinal)?);
    devices.insert(ordinal, dev.clone());
    Ok(dev)
}

impl GpuDevice {
    fn load(ordinal: usize) -> Result<Self> {
        let ctx = CudaContext::new(ordinal).map_err(driver_error("context creation"))?;
        // cudarc by default gives every buffer two events and waits on / records them around every
        // use, so that a buffer can hop between streams safely. clatch never lets one hop: each call
        // allocates, uses and frees its buffers on its own stream (frees are stream-ordered), and the
        // tables below are uploaded on the default stream and synchronised before any other stream
        // exists; pinned staging buffers keep their own events. The tracking cost ~2 driver calls per
        // kernel argument and most of the host time of a queued image.
        // SAFETY: the invariant above: no buffer is used on a stream other than the one it was
        // allocated on, except the tables, which are complete before they are shared.
        unsafe { ctx.disable_event_tracking() };
        let mut kernels = HashMap::new();
        // The fatbin's native code loads without JIT on the GPUs it was built for (and falls back to its
        // PTX elsewhere); CLATCH_FORCE_PTX=1 loads the plain PTX instead, so tests can prove both paths.
        let force_ptx = std::env::var_os("CLATCH_FORCE_PTX").is_some_and(|v| v == "1");
        let (major, _) = ctx
            .compute_capability()
            .map_err(driver_error("reading the compute capability"))?;
        let tensor_cores = major >= 8;
        let files = KERNELS
            .iter()
            .chain(tensor_cores.then_some(&TENSOR_KERNELS));
        for &(file, source, fatbin, names) in files {
            let image = if force_ptx {
                Ptx::from_src(source)
            } else {
                Ptx::from_binary(fatbin.to_vec())
            };
            let module = ctx.load_module(image).map_err(driver_error(file))?;
            for &name in names {
                let function = module.load_function(name).map_err(driver_error(name))?;
                tensor_knn::configure(name, &function)?;
                kernels.insert(name, function);
            }
        }
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
        Ok(Self {
            ctx,
            kernels,
            rotation,
            triplets,
            boundaries,
            pitch_alignment,
            multiprocessors,
            tensor_cores,
            match_kernel_override: MatchKernel::from_env(),
            name,
        })
    }

    /// The kNN kernels matching uses for `k` neighbours: the tensor cores where the device has them and
    /// k <= 2, unless `CLATCH_MATCH_KERNEL=popcount` says otherwise; the popcount kernels elsewhere.
    pub(crate) fn match_kernel(&self, k: usize) -> MatchKernel {
        let tensor_ok = self.tensor_cores && k <= tensor_knn::MAX_K;
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
        if kernel == MatchKernel::Tensor && k > tensor_knn::MAX_K {
            return Err(Error::KTooLargeForBackend {
                k,
                max: tensor_knn::MAX_K,
                backend: "cuda tensor-core matcher".into(),
            });
        }
        Ok(kernel)
    }

    /// Whether the tensor-core kNN kernels are loaded on this device.
    pub fn has_tensor_matcher(&self) -> bool {
        self.tensor_cores
    }

    /// A loaded kernel, by its `extern "C"` name (one listed in `KERNELS`).
    pub(crate) fn kernel(&self, name: &'static str) -> &CudaFunction {
        self.kernels
            .get(name)
            .unwrap_or_else(|| panic!("kernel {name} is not listed in KERNELS"))
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
}

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
