//! Tensor-core kNN: `kernels/matching_tensor.cu`, reproducing [`crate::matching::cpu::knn`] exactly for
//! k = 1 and 2, ties included, on GPUs of compute capability 8.0 and later.
//!
//! Exactness strategy: descriptors are expanded on the device to one signed byte per bit (+1 for 0, -1
//! for 1); an int8 dot product of two rows of B bytes is B - 2 * Hamming distance, computed by the
//! tensor cores in int32, so the distance is recovered exactly. Lists are kept and merged by
//! (distance, index) as in the CPU reference. The cross-check's reverse 1-NN comes out of the same dot
//! products (the `mutual` kernels), folded into the same buffer of (distance, query) keys the popcount
//! kernels fill, so the filter and compaction of `matching.rs` serve both.

use std::sync::Arc;

use cudarc::driver::{CudaFunction, CudaSlice, CudaStream, LaunchConfig, PushKernelArg, sys};

use super::device::GpuDevice;
use super::error::driver_error;
use super::header::{
    CLATCH_EXPAND_THREADS, CLATCH_MATCH_ROW_PAD, CLATCH_TENSOR_QUERIES, CLATCH_TENSOR_STAGES,
    CLATCH_TENSOR_TILE, CLATCH_TENSOR_WARPS,
};
use super::kernels::{self, Kernel};
use super::memory::alloc_zeros;
use crate::error::Result;
use crate::matching::Match;

/// Which kNN kernels a matching call runs on the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatchKernel {
    /// The paper-style popcount kernels of `kernels/matching.cu`: every GPU, every k up to 8.
    Popcount,
    /// int8 tensor-core MMA (`kernels/matching_tensor.cu`): compute capability 8.0 and later, k <= 2.
    Tensor,
}

impl MatchKernel {
    /// The kernel family `CLATCH_MATCH_KERNEL` (`popcount` or `tensor`) asks for, if set.
    pub(crate) fn from_env() -> Option<Self> {
        match std::env::var("CLATCH_MATCH_KERNEL").ok()?.as_str() {
            "popcount" => Some(Self::Popcount),
            "tensor" => Some(Self::Tensor),
            _ => None,
        }
    }
}

/// Largest k the tensor kernels keep.
pub(crate) const MAX_K: usize = 2;
/// Row widths (bits) the tensor kernels are compiled for; narrower rows are padded up to one.
const BITS: [usize; 4] = [64, 128, 256, 512];

const THREADS: u32 = CLATCH_TENSOR_WARPS * 32;
const BLOCK_QUERIES: usize = CLATCH_TENSOR_QUERIES as usize;
const TILE: usize = CLATCH_TENSOR_TILE as usize;
const ROW_PAD: usize = CLATCH_MATCH_ROW_PAD as usize;
/// Fewest tiles in a gallery segment, so the copy pipeline has something to overlap.
const MIN_SEGMENT_TILES: usize = 4;
/// Most gallery segments (grid y).
const MAX_SEGMENTS: usize = 65_535;

/// Bits per row the kernels see: `words` rounded up to a power of two (zero bits are +1 on both sides:
/// the same constant in every dot product, so distances are unchanged).
pub(crate) fn padded_bits(words: usize) -> usize {
    words.next_power_of_two() * 64
}

/// Shared memory of one block of the kernels for `bits`-wide rows: the gallery stages.
pub(crate) fn shared_bytes(bits: usize) -> usize {
    CLATCH_TENSOR_STAGES as usize * TILE * bits
}

fn slot(bits: usize) -> usize {
    BITS.iter()
        .position(|&b| b == bits)
        .expect("padded widths are 64..512")
}

/// The kNN kernel for `bits`-wide rows and k (1 or 2) neighbours, with the reverse 1-NN if `mutual`.
fn knn_kernel(bits: usize, k: usize, mutual: bool) -> Kernel {
    kernels::TENSOR_KNN[4 * slot(bits) + 2 * mutual as usize + (k - 1)]
}

/// Lets the kNN kernels use the shared memory they need (over the default 48 KiB); called once per
/// loaded function.
pub(crate) fn configure(name: &str, function: &CudaFunction) -> Result<()> {
    let Some(bits) = BITS
        .iter()
        .find(|&&b| name.contains(&format!("_b{b}")) && name.starts_with("clatch_knn_tensor"))
    else {
        return Ok(());
    };
    function
        .set_attribute(
            sys::CUfunction_attribute::CU_FUNC_ATTRIBUTE_MAX_DYNAMIC_SHARED_SIZE_BYTES,
            shared_bytes(*bits) as i32,
        )
        .map_err(driver_error("allowing the tensor kNN its shared memory"))
}

/// How one pass is cut into blocks: 256 queries per block (x), the gallery in segments (y).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Geometry {
    pub(crate) query_blocks: usize,
    /// Gallery rows per segment, a multiple of TILE.
    pub(crate) segment: usize,
    pub(crate) segments: usize,
}

impl Geometry {
    /// One block is resident per multiprocessor. Cuts the gallery into the fewest segments that give
    /// every multiprocessor work and keep the last wave at least 90% full (segments of at least
    /// `MIN_SEGMENT_TILES` tiles), or the best fill found. `segment_tiles` forces the cut (tests).
    pub(crate) fn new(sms: usize, nq: usize, nt: usize, segment_tiles: Option<usize>) -> Self {
        let query_blocks = nq.div_ceil(BLOCK_QUERIES).max(1);
        let tiles = nt.div_ceil(TILE).max(1);
        let cut = |segment_tiles: usize| {
            let segment_tiles = segment_tiles
                .max(tiles.div_ceil(MAX_SEGMENTS))
                .clamp(1, tiles);
            Self {
                query_blocks,
                segment: segment_tiles * TILE,
                segments: tiles.div_ceil(segment_tiles),
            }
        };
        if let Some(t) = segment_tiles {
            return cut(t);
        }
        let sms = sms.max(1);
        let fill = |g: &Self| {
            let blocks = g.query_blocks * g.segments;
            blocks as f64 / (blocks.div_ceil(sms) * sms) as f64
        };
        let most = tiles.div_ceil(MIN_SEGMENT_TILES).max(1);
        let mut best = cut(tiles);
        for segments in 1..=most.min(4 * sms) {
            let g = cut(tiles.div_ceil(segments));
            if query_blocks * g.segments >= sms && fill(&g) >= 0.9 {
                return g;
            }
            if fill(&g) > fill(&best) + 1e-9 && query_blocks * g.segments <= 4 * sms {
                best = g;
            }
        }
        best
    }
}

/// One tensor-core kNN on the device: the sign-expanded sets, the geometry of each pass and the
/// per-segment lists.
pub(crate) struct TensorKnn {
    kernel: Kernel,
    bits: usize,
    words: u32,
    nq: u32,
    nt: u32,
    k: u32,
    geometry: Geometry,
    query_signs: CudaSlice<u8>,
    train_signs: CudaSlice<u8>,
    partial: CudaSlice<u64>,
}

impl TensorKnn {
    /// Plans `nq` queries against `nt` gallery rows of `words` 64-bit words, `k` (1 or 2) neighbours,
    /// with the reverse 1-NN when `mutual`.
    pub(crate) fn new(
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        (nq, nt, words): (usize, usize, usize),
        k: usize,
        mutual: bool,
        segment_tiles: Option<usize>,
    ) -> Result<Self> {
        super::invariant((1..=MAX_K).contains(&k), "tensor kNN", || {
            format!("k = {k}")
        })?;
        let bits = padded_bits(words);
        let geometry = Geometry::new(dev.multiprocessors, nq, nt, segment_tiles);
        let rows = |n: usize| n.div_ceil(ROW_PAD).max(1) * ROW_PAD;
        let partial_len = if geometry.segments > 1 {
            geometry.segments.saturating_mul(nq).saturating_mul(k)
        } else {
            1
        };
        Ok(Self {
            kernel: knn_kernel(bits, k, mutual),
            bits,
            words: words as u32,
            nq: nq as u32,
            nt: nt as u32,
            k: k as u32,
            geometry,
            query_signs: alloc_zeros(stream, rows(nq) * bits, "expanded query descriptors")?,
            train_signs: alloc_zeros(stream, rows(nt) * bits, "expanded gallery descriptors")?,
            partial: alloc_zeros(stream, partial_len, "kNN segment lists")?,
        })
    }

    /// Queues the expansion of both sets and the kNN (and the merge of its segment lists into `out`);
    /// the mutual kernels also fold the reverse 1-NN into `reverse` (zeroed by the caller).
    pub(crate) fn launch(
        &mut self,
        dev: &GpuDevice,
        stream: &Arc<CudaStream>,
        (query, train): (&CudaSlice<u64>, &CudaSlice<u64>),
        out: &mut CudaSlice<Match>,
        reverse: &mut CudaSlice<u64>,
    ) -> Result<()> {
        let bits = self.bits;
        expand(dev, stream, query, self.words, bits, &mut self.query_signs)?;
        expand(dev, stream, train, self.words, bits, &mut self.train_signs)?;

        let g = self.geometry;
        let kernel = self.kernel;
        let segment = g.segment as u32;
        let mut launch = stream.launch_builder(dev.kernel(kernel));
        launch
            .arg(&self.query_signs)
            .arg(&self.nq)
            .arg(&self.train_signs)
            .arg(&self.nt)
            .arg(&segment)
            .arg(&self.k)
            .arg(&mut *out)
            .arg(&mut self.partial)
            .arg(&mut *reverse);
        // SAFETY: the arguments match clatch_knn_tensor_*'s signature. Both sign buffers hold whole
        // ROW_PAD-row blocks of `bits` bytes (every query block and tile the kernel reads is in
        // bounds), `out` holds nq * k matches, `partial` segments * nq * k keys when there is more
        // than one segment, and `reverse` nt keys for the mutual kernels (the only ones that touch it).
        unsafe { launch.launch(config(g, bits)) }.map_err(driver_error(kernel.name()))?;
        if g.segments > 1 {
            super::matching::launch_merge(
                dev,
                stream,
                &self.partial,
                (self.nq, g.segments as u32, self.k),
                out,
            )?;
        }

        Ok(())
    }
}

fn config(g: Geometry, bits: usize) -> LaunchConfig {
    LaunchConfig {
        grid_dim: (g.query_blocks as u32, g.segments as u32, 1),
        block_dim: (THREADS, 1, 1),
        shared_mem_bytes: shared_bytes(bits) as u32,
    }
}

/// Queues the expansion of a padded bit buffer (rows of `words` words) into `signs` (rows of `bits`
/// signed bytes).
pub(crate) fn expand(
    dev: &GpuDevice,
    stream: &Arc<CudaStream>,
    bits_buffer: &CudaSlice<u64>,
    words: u32,
    bits: usize,
    signs: &mut CudaSlice<u8>,
) -> Result<()> {
    let rows = (signs.len() / bits) as u32;
    super::invariant(
        bits_buffer.len() >= rows as usize * words as usize,
        "expanding descriptors to signs",
        || format!("{} words for {rows} rows of {words}", bits_buffer.len()),
    )?;
    let row_bytes = bits as u32;
    let units = signs.len() / 8;
    let blocks = units.div_ceil(CLATCH_EXPAND_THREADS as usize).min(1 << 16) as u32;
    let mut launch = stream.launch_builder(dev.kernel(kernels::EXPAND_SIGNS));
    launch
        .arg(bits_buffer)
        .arg(&rows)
        .arg(&words)
        .arg(&row_bytes)
        .arg(&mut *signs);
    // SAFETY: `bits_buffer` holds rows * words words and `signs` rows * bits bytes (rows * bits / 8
    // eight-byte units, each written once).
    unsafe {
        launch.launch(LaunchConfig {
            grid_dim: (blocks.max(1), 1, 1),
            block_dim: (CLATCH_EXPAND_THREADS, 1, 1),
            shared_mem_bytes: 0,
        })
    }
    .map_err(driver_error("clatch_expand_signs"))?;
    Ok(())
}

#[cfg(feature = "internals")]
pub mod hooks;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_names_follow_width_and_k() {
        for words in 1..=8 {
            let bits = padded_bits(words);
            assert!(bits >= words * 64 && bits.is_power_of_two());
            for k in 1..=2 {
                let plain = format!("clatch_knn_tensor_b{bits}_k{k}");
                let mutual = format!("clatch_knn_tensor_mutual_b{bits}_k{k}");
                assert_eq!(knn_kernel(bits, k, false).name(), plain);
                assert_eq!(knn_kernel(bits, k, true).name(), mutual);
            }
        }
    }

    #[test]
    fn geometry_covers_the_gallery_with_whole_tiles() {
        for sms in [1, 7, 132] {
            for nq in [1, 255, 256, 1000, 16_384, 65_536] {
                for nt in [1, 63, 64, 65, 1000, 16_384, 65_536] {
                    let g = Geometry::new(sms, nq, nt, None);
                    assert_eq!(g.segment % TILE, 0);
                    assert!(g.segments * g.segment >= nt, "{sms} {nq} {nt}: {g:?}");
                    assert!(
                        (g.segments - 1) * g.segment < nt,
                        "every segment non-empty: {g:?}"
                    );
                    assert_eq!(g.query_blocks, nq.div_ceil(BLOCK_QUERIES));
                }
            }
        }
        // 64k x 64k on 132 SMs: 256 query blocks already fill two waves to 97%.
        assert_eq!(Geometry::new(132, 65_536, 65_536, None).segments, 1);
        // 16k x 16k: 64 query blocks; 4 segments give 256 blocks.
        assert_eq!(Geometry::new(132, 16_384, 16_384, None).segments, 4);
    }

    #[test]
    fn shared_memory_fits_a_hopper_or_ampere_block() {
        assert!(shared_bytes(512) <= 163 * 1024);
    }
}
