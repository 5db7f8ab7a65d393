"""The Python package's overhead against the Rust call it wraps, in one process and one run.

    pip install ./python && python python/bench/overhead.py [--repeats 21] [--backend cpu]

Two workloads (the goal: at most 5 % over the Rust call):
- matching 10,000 x 10,000 512-bit descriptors (random queries; half the gallery noisy copies of
  half of them, so that about 5000 matches pass the ratio test and cross-check);
- detecting and describing a 1920 x 1080 image (the repository's photo tiled), default settings.

For each, the Python call (``Matcher.match`` / ``Extractor.detect_and_describe`` on numpy arrays:
argument parsing, array checks and conversion, the GIL released and taken back, results handed to
numpy) is timed with ``time.perf_counter`` around the call, and the library's own call
(``Matcher::match_descriptors`` / ``Extractor::detect_and_describe`` on inputs converted
beforehand) is timed in Rust by ``clatch._clatch._rust_*_seconds``, the two interleaved so that
drift in clock speed or load hits both alike. The overhead is the median of the pairs' differences;
"inputs" is the time of the Rust timer's call without the compute (the inputs read and converted,
the GIL released and taken back), a low-noise floor of the overhead.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np

import clatch
from clatch import _clatch

ASTRONAUT = Path(__file__).resolve().parents[2] / "assets" / "astronaut.png"


def photo_1080p() -> np.ndarray:
    tile = clatch.imread(ASTRONAUT)
    reps = (-(-1080 // tile.shape[0]), -(-1920 // tile.shape[1]))
    return np.ascontiguousarray(np.tile(tile, reps)[:1080, :1920])


def measure(python_call, rust_seconds, repeats: int) -> dict:
    """Medians of ``repeats`` interleaved pairs, and the median of the pairs' differences (each pair
    run back to back, in alternating order, so that slow drift of this machine's speed cancels)."""
    python_call()  # warm-up: thread pool, page faults, caches
    rust_seconds(1)
    py, rust = [], []
    for i in range(repeats):
        for which in (0, 1) if i % 2 == 0 else (1, 0):
            if which == 0:
                start = time.perf_counter()
                python_call()
                py.append(time.perf_counter() - start)
            else:
                rust.extend(rust_seconds(1))
    # The wrapper's own work alone: arguments read and converted, the GIL released, no compute.
    wrapper = []
    for _ in range(repeats):
        start = time.perf_counter()
        rust_seconds(0)
        wrapper.append(time.perf_counter() - start)
    rust_med = statistics.median(rust)
    diff = statistics.median(p - r for p, r in zip(py, rust))
    return {
        "python_ms": 1e3 * statistics.median(py),
        "rust_ms": 1e3 * rust_med,
        "overhead_ms": 1e3 * diff,
        "overhead_percent": 100 * diff / rust_med,
        "inputs_only_ms": 1e3 * statistics.median(wrapper),
        "python_min_ms": 1e3 * min(py),
        "rust_min_ms": 1e3 * min(rust),
        "repeats": repeats,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--backend", default="cpu")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    query = rng.integers(0, 256, size=(10_000, 64), dtype=np.uint8)
    # Half the gallery: noisy copies (about 10 % of the bits flipped) of half the queries, shuffled;
    # the rest random. So that about 5000 matches pass the tests and come back through numpy.
    noise = np.packbits(rng.random((5_000, 512)) < 0.1, axis=1)
    train = np.concatenate([query[:5_000] ^ noise, rng.integers(0, 256, size=(5_000, 64), dtype=np.uint8)])
    train = train[rng.permutation(len(train))]
    matcher = clatch.Matcher(args.backend)
    n_matches = len(matcher.match(query, train))
    match = measure(
        lambda: matcher.match(query, train),
        lambda n: _clatch._rust_match_seconds(matcher, query, train, n),
        args.repeats,
    )

    image = photo_1080p()
    extractor = clatch.Extractor(args.backend)
    n_keypoints = len(extractor.detect(image))
    extract = measure(
        lambda: extractor.detect_and_describe(image),
        lambda n: _clatch._rust_extract_seconds(extractor, image, n),
        args.repeats,
    )

    print(f"clatch {clatch.__version__}, backend {matcher.backend}, {platform.python_implementation()} "
          f"{platform.python_version()}, numpy {np.__version__}, medians of {args.repeats}")
    print(f"{'workload':<40}{'Python ms':>11}{'Rust ms':>10}{'overhead':>18}{'inputs':>11}")
    for name, r in [
        (f"match 10k x 10k 512-bit ({n_matches} matches)", match),
        (f"extract 1920x1080 ({n_keypoints} keypoints)", extract),
    ]:
        print(f"{name:<40}{r['python_ms']:>11.2f}{r['rust_ms']:>10.2f}"
              f"{r['overhead_ms']:>9.2f} ms {r['overhead_percent']:>+5.1f} %{r['inputs_only_ms']:>8.2f} ms")
    if args.json:
        args.json.write_text(json.dumps({"match_10k": match, "extract_1080p": extract}, indent=2))


if __name__ == "__main__":
    main()
