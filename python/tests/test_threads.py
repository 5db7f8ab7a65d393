"""The GIL is released while the library computes: other Python threads run meanwhile, and two
threads can share one Extractor or Matcher, getting the single-threaded results."""

from __future__ import annotations

import threading
import time

import numpy as np

import clatch
from helpers import ASTRONAUT, as_tuples, random_descriptors


def longest_stall(call) -> tuple[float, float]:
    """Runs ``call`` in another thread while this one spins; returns the longest time this thread
    could not run during the call, and the call's duration. With the GIL held through the call the
    stall is about the whole call; released, it is at most a few switch intervals (5 ms each)."""
    window = {}

    def worker():
        window["start"] = time.perf_counter()
        call()
        window["end"] = time.perf_counter()

    thread = threading.Thread(target=worker)
    stamps = []
    thread.start()
    while thread.is_alive():
        stamps.append(time.perf_counter())
    thread.join()
    start, end = window["start"], window["end"]
    # Every moment of the call, from its start to its end, and when this thread last ran before it.
    inside = [start] + [t for t in stamps if start < t < end] + [end]
    return max(b - a for a, b in zip(inside, inside[1:])), end - start


def long_enough(make_call, sizes) -> object:
    """The call ``make_call(size)`` gives for the first of ``sizes`` whose call takes at least 0.1 s
    here (the last one otherwise): the library's speed varies with the processor (the matcher's
    AVX-512 path matches 8000 x 8000 in under 50 ms), and a call must be long enough to tell a
    released GIL from a held one."""
    for size in sizes:
        call = make_call(size)
        start = time.perf_counter()
        call()
        if time.perf_counter() - start >= 0.1:
            break
    return call


def test_python_runs_while_matching(backend):
    rng = np.random.default_rng(5)
    matcher = clatch.Matcher(backend)

    def make(n):
        query, train = random_descriptors(rng, n, 64), random_descriptors(rng, n, 64)
        return lambda: matcher.match(query, train)

    call = long_enough(make, [8000, 16000, 32000])
    stall, seconds = min((longest_stall(call) for _ in range(3)), key=lambda r: r[0] / r[1])
    assert seconds > 0.05, "too short a call to tell"
    assert stall < 0.5 * seconds, f"this thread stalled {stall:.3f} s of a {seconds:.3f} s call"


def test_python_runs_while_extracting(backend):
    extractor = clatch.Extractor(backend)

    def make(tiles):
        photo = np.tile(clatch.imread(ASTRONAUT), (tiles, tiles))
        return lambda: extractor.detect_and_describe(photo)

    call = long_enough(make, [3, 5, 8])
    stall, seconds = min((longest_stall(call) for _ in range(3)), key=lambda r: r[0] / r[1])
    assert seconds > 0.05, "too short a call to tell"
    assert stall < 0.5 * seconds, f"this thread stalled {stall:.3f} s of a {seconds:.3f} s call"


def test_threads_share_one_extractor_and_matcher(backend):
    photo = clatch.imread(ASTRONAUT)
    images = [photo, photo[50:, 30:], photo[::-1].copy(), photo[:400, :450]]
    extractor = clatch.Extractor(backend, max_keypoints=1000)
    matcher = clatch.Matcher(backend)
    expected = [extractor.detect_and_describe(i) for i in images]
    expected_matches = [as_tuples(matcher.match(expected[0][1], d)) for _, d in expected]
    results: dict[int, object] = {}
    errors: list[BaseException] = []

    def work(worker: int) -> None:
        try:
            for round_ in range(3):
                i = (worker + round_) % len(images)
                keypoints, descriptors = extractor.detect_and_describe(images[i])
                matches = matcher.match(expected[0][1], descriptors)
                results[(worker, round_)] = (i, keypoints, descriptors, as_tuples(matches))
        except BaseException as e:  # reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(w,)) for w in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
        assert not t.is_alive(), "a worker thread hung"
    assert not errors, errors
    assert len(results) == 12
    for i, keypoints, descriptors, matches in results.values():
        assert np.array_equal(keypoints, expected[i][0])
        assert np.array_equal(descriptors, expected[i][1])
        assert matches == expected_matches[i]
