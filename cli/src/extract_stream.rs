//! Extracting many files: decoding on worker threads ahead of the extractor, which takes the decoded
//! images as a stream ([`clatch::Extractor::detect_and_describe_stream`]: on the GPU several images
//! in flight on several streams), results in input order.

use clatch::{AsGrayView, Backend, Extractor, Features};

use crate::error::CliError;
use crate::prefetch::{self, Prefetched};

/// Decoding threads for `backend`, and how many decoded images they may hold ahead of the extractor.
/// The GPU: every core (decoding is then the CPU's only work), as many ahead as there are decoders
/// plus the 8 images the GPU keeps in flight. The CPU backend: half the cores (its extraction uses
/// every core itself), a whole next group of images ahead (it extracts one image per core at once).
fn decoding(backend: Backend) -> (usize, usize) {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    match backend {
        Backend::Cpu => ((cores / 2).max(1), 2 * rayon::current_num_threads().max(1)),
        _ => (cores, cores + 8),
    }
}

/// Decodes items `0..n` with `decode` on worker threads (at most a few ahead of the extractor) and
/// hands each with its features to `each`, in order. Returns the decoders' timings: their summed time,
/// and how long the extractor waited for them (zero when extraction, not decoding, is the bound).
pub fn extract_decoded<T: AsGrayView + Send + Sync>(
    extractor: &Extractor,
    n: usize,
    decode: impl Fn(usize) -> Result<T, CliError> + Sync,
    each: impl FnMut(usize, T, Features) -> Result<(), CliError>,
) -> Result<Prefetched, CliError> {
    let (threads, ahead) = decoding(extractor.backend());
    let (result, stats) = prefetch::ordered(n, threads, ahead, decode, |decoded| {
        extractor.detect_and_describe_stream(decoded, each)
    });
    result?;
    Ok(stats)
}
