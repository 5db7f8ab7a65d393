"""Hostile input: arrays of every dtype, shape, stride and size (0-d, empty, huge by broadcast,
Fortran order, negative strides, zero strides) and paths of every kind, through every call that takes
them. Each call returns or raises a ClatchError subclass: nothing else escapes, nothing crashes.
Over 10^5 cases a run, in a few seconds (most are refused from the dtype or shape alone)."""

from __future__ import annotations

import itertools
import os
import time
from pathlib import Path

import numpy as np
import pytest

import clatch
import clatch.colmap

DTYPES = [
    np.uint8, np.int8, np.uint16, np.int16, np.int32, np.uint32, np.int64, np.uint64, np.float16,
    np.float32, np.float64, np.complex64, np.bool_, object, "U3", "S2", "V4", "M8[s]", "m8[ms]",
    ">u2", clatch.KEYPOINT_DTYPE, clatch.MATCH_DTYPE, [("a", np.uint8), ("b", np.uint8)],
]
SHAPES = [
    (), (0,), (1,), (7,), (64,), (0, 0), (0, 64), (64, 0), (1, 1), (2, 3), (63, 64), (64, 63), (64, 64),
    (65, 70), (3, 64), (64, 1), (1, 64), (5, 2), (64, 64, 3), (64, 1, 3), (66, 64, 4), (70, 65, 1), (70, 65, 2), (70, 65, 3), (70, 65, 4), (70, 65, 5),
    (0, 65, 3), (64, 0, 4), (2, 70, 65, 3), (1, 1, 1, 1, 1), (10, 32), (10, 64), (10, 65), (3, 8),
]
HUGE = [(1, 10**9), (10**9, 1), (40_000, 40_000), (32_768, 64), (64, 32_768, 3), (10**6, 10**6, 4), (2**40, 2**20)]


def variants(array: np.ndarray):
    """The array in several memory layouts."""
    yield array
    if array.ndim >= 1:
        yield array[::-1]
    if array.ndim >= 2:
        yield np.asfortranarray(array)
        yield array.swapaxes(0, 1)
        yield array[:, ::-1]
        yield np.broadcast_to(array[:1], array.shape)
    if array.ndim >= 3:
        yield array[..., ::-1]


def arrays():
    for dtype, shape in itertools.product(DTYPES, SHAPES):
        try:
            base = np.zeros(shape, dtype=dtype)
        except (TypeError, ValueError):
            continue
        if base.dtype == np.uint8 and base.size:
            base[...] = np.arange(base.size, dtype=np.uint64).reshape(shape).astype(np.uint8)
        yield from variants(base)
        if base.ndim:
            readonly = base.copy()
            readonly.flags.writeable = False
            yield readonly
    for shape in HUGE:
        yield np.broadcast_to(np.uint8(1), shape)
    yield from [None, 3, 2.5, "image", b"\x00" * 64, [[0] * 64] * 64, memoryview(b"abc"), {"x": 1}, np.uint8(7)]


def paths(tmp_path: Path):
    (tmp_path / "empty.png").write_bytes(b"")
    (tmp_path / "garbage.jpg").write_bytes(os.urandom(2000))
    (tmp_path / "png-header-only.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 30)
    (tmp_path / "huge.pgm").write_bytes(b"P5\n100000 100000\n255\n")
    (tmp_path / "negative.pgm").write_bytes(b"P5\n-3 5\n255\n")
    (tmp_path / "deep.pgm").write_bytes(b"P5\n2 2\n70000\n" + b"\x00" * 8)
    (tmp_path / "dir.png").mkdir()
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    (tmp_path / "dangling.png").symlink_to(tmp_path / "nowhere.png")
    yield from [tmp_path / name for name in os.listdir(tmp_path)]
    yield from [tmp_path, tmp_path / "missing.png", "", ".", "/", "/dev/null", "/proc/self/status", "a\x00b.png",
                "x" * 5000, str(tmp_path / "empty.png").encode(), "é🙂.png", 3, None, 2.5, ["a.png"]]


def check(call, *args, **kwargs) -> bool:
    """Runs one case: True if it returned, False if it raised a ClatchError; anything else fails."""
    try:
        call(*args, **kwargs)
        return True
    except clatch.ClatchError:
        return False
    except BaseException as e:  # what the test is for: reported with the case
        raise AssertionError(f"{getattr(call, '__name__', call)}{args!r:.300} {kwargs} raised {type(e).__name__}: {e}") from e


def test_hostile_input_raises_only_clatch_errors(tmp_path):
    start = time.perf_counter()
    extractor = clatch.Extractor(single_scale=True, max_keypoints=5)
    matcher = clatch.Matcher()
    good_desc = np.zeros((4, 32), np.uint8)
    good_image = np.zeros((64, 64), np.uint8)
    good_kp = np.zeros(1, clatch.KEYPOINT_DTYPE)
    good_xy = np.arange(40, dtype=np.float32).reshape(20, 2)
    good_m = np.zeros(1, clatch.MATCH_DTYPE)
    latch = clatch.OpencvLatch()
    cases = returned = 0
    for a in arrays():
        calls = [
            (clatch.to_gray, (a,), {}),
            (clatch.to_gray, (a,), {"channels": "bgr"}),
            (clatch._clatch._reads_in_place, (a,), {}),
            (extractor.detect, (a,), {}),
            (extractor.detect_and_describe, (a,), {"channels": "bgr"}),
            (extractor.detect_and_describe_batch, ([good_image, a],), {}),
            (extractor.describe, (a, good_kp), {}),
            (extractor.describe, (good_image, a), {}),
            (extractor.describe_opencv, (latch, good_image, a), {}),
            (matcher.match, (a, good_desc), {}),
            (matcher.match, (good_desc, a), {}),
            (matcher.knn, (a, good_desc, 1), {}),
            (matcher.knn, (good_desc, a, 2), {}),
            (matcher.match_pairs, ([a], [(0, 0)]), {}),
            (extractor.detect, (a,), {"channels": "bgr"}),
            (extractor.describe_opencv, (latch, a, good_kp), {}),
            (clatch.to_cv2_keypoints, (a,), {}),
            (matcher.match_pairs, ([good_desc, a], [(0, 1), (1, 0)]), {}),
            (matcher.match_pairs, ([good_desc, good_desc], a), {}),
            (clatch.points, (a,), {}),
            (clatch.to_cv2_matches, (a,), {}),
            (clatch.verify_pair, (a, good_xy, good_m), {}),
            (clatch.verify_pair, (good_xy, a, good_m), {}),
            (clatch.verify_pair, (good_xy, good_xy, a), {}),
            (clatch.verify_pairs, ([(good_xy, good_xy, good_m), (good_kp, a, good_m)],), {}),
        ]
        for call, args, kwargs in calls:
            returned += check(call, *args, **kwargs)
            cases += 1
    for p in paths(tmp_path):
        for call in (clatch.imread, lambda q: clatch.imread(q, max_pixels=10), clatch.colmap.ImageFolder):
            returned += check(call, p)
            cases += 1
    for value in (-(2**70), -1, 0, 1, 2**31, 2**64, 2.0, "3", None, True):
        for call in (lambda v: matcher.knn(good_desc, good_desc, v), clatch.Matcher.all_pairs,
                     lambda v: clatch.Extractor(threshold=v), lambda v: clatch.Extractor(grid=v),
                     lambda v: clatch.Extractor(bits=v), lambda v: clatch.Matcher(max_distance=v),
                     lambda v: clatch.Matcher(ratio=v), lambda v: clatch.OpencvLatch(bytes=v),
                     lambda v: clatch.Extractor(pyramid=(v, 1.2)), lambda v: clatch.Extractor(backend=v),
                     lambda v: clatch.verify_pair(good_xy, good_xy, good_m, max_error=v),
                     lambda v: clatch.verify_pair(good_xy, good_xy, good_m, min_num_trials=v),
                     lambda v: clatch.verify_pair(good_xy, good_xy, good_m, seed=v, key=v),
                     lambda v: clatch.verify_pair(good_xy, good_xy, good_m, neighbour_consistency=v),
                     lambda v: clatch.verify_pair(good_xy, good_xy, good_m, (v, v), (v, v, np.eye(3))),
                     lambda v: clatch.verify_pair(good_xy, good_xy, np.array([[v, 0]], dtype=object)),
                     lambda v: clatch.verify_pairs([(good_xy, good_xy, good_m)], keys=[v]),
                     lambda v: clatch.verify_pairs(v)):
            returned += check(call, value)
            cases += 1
    seconds = time.perf_counter() - start
    print(f"\n{cases} hostile cases, {returned} returned, {cases - returned} refused with a ClatchError, {seconds:.1f} s")
    assert cases >= 100_000
    assert 0 < returned < cases
