"""The GIL is released while the library computes: other Python threads run meanwhile, and two
threads can share one Extractor or Matcher, getting the single-threaded results."""

from __future__ import annotations

import threading
import time

import numpy as np

import clatch
from helpers import ASTRONAUT, as_tuples, random_descriptors


def progress_during(call) -> tuple[int, float]:
    """How many times the main thread advanced a counter while ``call`` ran in another thread, and
    how long the call took."""
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
    inside = sum(1 for t in stamps if window["start"] < t < window["end"])
    return inside, window["end"] - window["start"]


def test_python_runs_while_matching(backend):
    rng = np.random.default_rng(5)
    query, train = random_descriptors(rng, 6000, 64), random_descriptors(rng, 6000, 64)
    matcher = clatch.Matcher(backend)
    inside, seconds = progress_during(lambda: matcher.match(query, train))
    # Holding the GIL would leave the loop a switch interval (5 ms) at most; released, it spins
    # all along (hundreds of thousands of iterations a second).
    assert seconds > 0.01
    assert inside > 1000, f"{inside} loop iterations during a {seconds:.3f} s call"


def test_python_runs_while_extracting(backend):
    photo = np.tile(clatch.imread(ASTRONAUT), (2, 2))
    extractor = clatch.Extractor(backend)
    inside, seconds = progress_during(lambda: extractor.detect_and_describe(photo))
    assert inside > 1000, f"{inside} loop iterations during a {seconds:.3f} s call"


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
