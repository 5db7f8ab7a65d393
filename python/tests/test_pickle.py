"""Extractors, matchers and OpenCV LATCH settings pickle: rebuilt from their settings on the same
backend, for ``copy``, ``multiprocessing`` and Ray."""

from __future__ import annotations

import copy
import multiprocessing
import pickle

import numpy as np

import clatch
from helpers import ASTRONAUT


def extract_and_match(extractor, matcher, image):
    """Runs in a spawned process: what the pickled objects compute there."""
    keypoints, descriptors = extractor.detect_and_describe(image)
    return extractor.backend, extractor.config, keypoints, descriptors, matcher.match(descriptors, descriptors[::-1].copy())


def test_round_trip_through_pickle(backend):
    """Finding P12: ``Extractor`` and ``Matcher`` could not be pickled."""
    extractor = clatch.Extractor(backend, max_keypoints=700, grid=4, bits=256, pyramid=(3, 1.5), smoothing="binomial3")
    matcher = clatch.Matcher(backend, ratio=None, cross_check=False, max_distance=90)
    latch = clatch.OpencvLatch(16, False, 2, 0.0)
    photo = clatch.imread(ASTRONAUT)
    keypoints, descriptors = extractor.detect_and_describe(photo)
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        e, m, l = pickle.loads(pickle.dumps((extractor, matcher, latch), protocol=protocol))
        assert type(e) is clatch.Extractor and type(m) is clatch.Matcher
        assert (e.backend, e.config) == (extractor.backend, extractor.config)
        assert repr(m) == repr(matcher) and repr(l) == repr(latch)
    k, d = e.detect_and_describe(photo)
    assert np.array_equal(k, keypoints) and np.array_equal(d, descriptors)
    assert np.array_equal(m.match(d, d[::-1].copy()), matcher.match(d, d[::-1].copy()))
    assert copy.deepcopy(extractor).config == extractor.config and repr(copy.copy(matcher)) == repr(matcher)


def test_round_trip_through_a_spawned_process(backend):
    extractor = clatch.Extractor(backend, max_keypoints=300)
    matcher = clatch.Matcher(backend, ratio=0.9)
    photo = clatch.imread(ASTRONAUT)
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        got = pool.apply(extract_and_match, (extractor, matcher, photo))
    expected = extract_and_match(extractor, matcher, photo)
    assert got[:2] == expected[:2]
    for a, b in zip(got[2:], expected[2:]):
        assert np.array_equal(a, b)
