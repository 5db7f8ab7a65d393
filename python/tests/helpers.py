"""Helpers of the test suite: the tool's files, images, descriptors and a brute-force matcher."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
ASTRONAUT = REPO / "assets" / "astronaut.png"


def run_extract(cli: Path, image: Path, prefix: Path, flags: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """``clatch extract IMAGE -o PREFIX FLAGS``: the keypoints CSV as columns and the descriptors .npy."""
    subprocess.run(
        [str(cli), "extract", str(image), "-o", str(prefix), *flags],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    csv = Path(f"{prefix}.keypoints.csv")
    header = csv.read_text().splitlines()[0]
    assert header == "x,y,size,angle,response,octave", header
    table = np.loadtxt(csv, delimiter=",", skiprows=1, dtype=np.float64, ndmin=2)
    descriptors = np.load(f"{prefix}.descriptors.npy")
    return table, descriptors


def write_pnm(path: Path, image: np.ndarray) -> Path:
    """A binary PGM (2-D) or PPM (H x W x 3) file of a ``uint8`` image."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    magic = b"P5" if image.ndim == 2 else b"P6"
    h, w = image.shape[:2]
    path.write_bytes(magic + f"\n{w} {h}\n255\n".encode() + image.tobytes())
    return path


def synthetic(height: int, width: int, seed: int, channels: int = 0) -> np.ndarray:
    """A textured ``uint8`` image: random rectangles of random grey (or colour) on noise."""
    rng = np.random.default_rng(seed)
    shape = (height, width, channels) if channels else (height, width)
    image = rng.integers(90, 110, size=shape, dtype=np.int32)
    for _ in range(60):
        y0, x0 = rng.integers(0, height - 8), rng.integers(0, width - 8)
        h, w = rng.integers(6, max(7, height // 4)), rng.integers(6, max(7, width // 4))
        value = rng.integers(0, 256, size=(channels,) if channels else ())
        image[y0 : y0 + h, x0 : x0 + w] = value
    return image.astype(np.uint8)


def random_descriptors(rng: np.random.Generator, n: int, nbytes: int) -> np.ndarray:
    return rng.integers(0, 256, size=(n, nbytes), dtype=np.uint8)


_POPCOUNT = np.array([bin(b).count("1") for b in range(256)], dtype=np.uint16)


def hamming_matrix(query: np.ndarray, train: np.ndarray) -> np.ndarray:
    """All distances, popcount of the XOR byte by byte (the byte order does not matter here)."""
    d = np.zeros((len(query), len(train)), dtype=np.int64)
    for col in range(query.shape[1]):
        d += _POPCOUNT[np.bitwise_xor.outer(query[:, col], train[:, col])]
    return d


def reference_knn(query: np.ndarray, train: np.ndarray, k: int) -> np.ndarray:
    """(N, k, 2) of (train index, distance): the k smallest (distance, index), nearest first."""
    d = hamming_matrix(query, train)
    out = np.zeros((len(query), k, 2), dtype=np.int64)
    for q in range(len(query)):
        order = np.lexsort((np.arange(len(train)), d[q]))[:k]
        out[q, :, 0] = order
        out[q, :, 1] = d[q, order]
    return out


def reference_match(
    query: np.ndarray,
    train: np.ndarray,
    ratio: float | None,
    cross_check: bool,
    max_distance: int | None,
) -> list[tuple[int, int, int]]:
    """The matcher's contract (src/matching/mod.rs), written out over the full distance matrix:
    the best match (lowest index on ties) of each query, kept iff ``float32(d1) < float32(ratio) *
    float32(d2)`` (one float32 product), iff the query is the nearest query (lowest index on ties)
    of its train descriptor, and iff ``d1 <= max_distance``."""
    d = hamming_matrix(query, train)
    nearest_query = np.argmin(d, axis=0)  # first index of the minimum: lowest on ties
    kept = []
    for q in range(len(query)):
        order = np.lexsort((np.arange(len(train)), d[q]))
        t1 = int(order[0])
        d1 = int(d[q, t1])
        if ratio is not None:
            d2 = int(d[q, order[1]])
            if not np.float32(d1) < np.float32(ratio) * np.float32(d2):
                continue
        if cross_check and nearest_query[t1] != q:
            continue
        if max_distance is not None and d1 > max_distance:
            continue
        kept.append((q, t1, d1))
    return kept


def as_tuples(matches: np.ndarray) -> list[tuple[int, int, int]]:
    return [(int(m["query"]), int(m["train"]), int(m["distance"])) for m in matches]


def photo_folder(folder: Path, count: int, size: int = 256, seed: int = 11) -> Path:
    """``count`` overlapping views of one textured scene (``size`` x ``size`` crops at shifted
    offsets) as PGM files ``view0.pgm`` ...: every pair shares most of its pixels, so it has matches."""
    scene = synthetic(size + 160, size + 160, seed)
    # Smooth once so that corners survive the shifts as corners, not as pixel noise.
    scene = ((scene[:-1, :-1].astype(np.uint16) + scene[1:, 1:]) // 2).astype(np.uint8)
    offsets = [(0, 0), (40, 28), (80, 60), (16, 96), (108, 24), (60, 120), (120, 120), (96, 8)]
    for k in range(count):
        dy, dx = offsets[k % len(offsets)]
        write_pnm(folder / f"view{k}.pgm", scene[dy : dy + size, dx : dx + size])
    return folder


def broken_copy(folder: Path, dest: Path) -> tuple[Path, Path]:
    """A copy of a photo folder whose last photo has a header that probes fine but pixels cut short
    (its read fails during extraction): the copy and that photo."""
    dest.mkdir()
    for photo in folder.iterdir():
        (dest / photo.name).write_bytes(photo.read_bytes())
    last = sorted(dest.iterdir())[-1]
    last.write_bytes(last.read_bytes()[:-5000])
    return dest, last
