"""Matching against a brute-force numpy reference of the contract in src/matching/mod.rs: Hamming
distances, k nearest by (distance, index), the ratio test as one float32 product, the cross-check
with the lowest query index on ties, the distance limit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import clatch
from helpers import ASTRONAUT, as_tuples, random_descriptors, reference_knn, reference_match

CONFIGS = list(itertools.product([None, 0.8, 1.0, 0.5], [True, False], [None, 3, 200]))


def tie_heavy(rng: np.random.Generator, n: int, nbytes: int) -> np.ndarray:
    """Descriptors drawn from a small pool with few bits set, so that equal distances are common."""
    pool = (rng.random((12, nbytes * 8)) < 0.1).astype(np.uint8)
    rows = pool[rng.integers(0, len(pool), size=n)]
    flips = rng.random(rows.shape) < 0.02
    return np.packbits(rows ^ flips, axis=1, bitorder="big")


@pytest.mark.parametrize("nbytes", [1, 2, 8, 9, 64])
@pytest.mark.parametrize("ratio,cross_check,max_distance", CONFIGS)
def test_match_equals_the_reference(backend, nbytes, ratio, cross_check, max_distance):
    rng = np.random.default_rng(nbytes * 1000 + len(str((ratio, cross_check, max_distance))))
    matcher = clatch.Matcher(backend, ratio=ratio, cross_check=cross_check, max_distance=max_distance)
    for query, train in [
        (random_descriptors(rng, 150, nbytes), random_descriptors(rng, 170, nbytes)),
        (tie_heavy(rng, 200, nbytes), tie_heavy(rng, 160, nbytes)),
    ]:
        got = matcher.match(query, train)
        assert got.dtype == clatch.MATCH_DTYPE
        assert as_tuples(got) == reference_match(query, train, ratio, cross_check, max_distance)


def test_ties_are_broken_towards_the_lowest_index(backend):
    # Every gallery descriptor is equally far from every query: train 0 wins, query 0 wins it.
    query = np.zeros((4, 8), dtype=np.uint8)
    train = np.full((5, 8), 0xFF, dtype=np.uint8)
    no_ratio = clatch.Matcher(backend, ratio=None, cross_check=False)
    assert as_tuples(no_ratio.match(query, train)) == [(q, 0, 64) for q in range(4)]
    assert as_tuples(clatch.Matcher(backend, ratio=None).match(query, train)) == [(0, 0, 64)]
    # d1 == d2 never passes the ratio test, even with ratio 1.
    assert len(clatch.Matcher(backend, ratio=1.0, cross_check=False).match(query, train)) == 0


def test_ratio_is_one_float32_product(backend):
    # d1 = 4, d2 = 5: 4 < 0.8 * 5 is false in float32 (0.8f * 5 == 4.0), as the contract says.
    query = np.zeros((1, 1), dtype=np.uint8)
    train = np.array([[0b1111_0000], [0b1111_1000]], dtype=np.uint8)
    assert np.float32(0.8) * np.float32(5) == np.float32(4)
    assert len(clatch.Matcher(backend, ratio=0.8).match(query, train)) == 0
    assert as_tuples(clatch.Matcher(backend, ratio=0.81).match(query, train)) == [(0, 0, 4)]


@pytest.mark.parametrize("nbytes,k", [(1, 1), (4, 3), (64, 2), (64, 8)])
def test_knn_equals_the_reference(backend, nbytes, k):
    rng = np.random.default_rng(k * 100 + nbytes)
    for query, train in [
        (random_descriptors(rng, 90, nbytes), random_descriptors(rng, 120, nbytes)),
        (tie_heavy(rng, 90, nbytes), tie_heavy(rng, 40, nbytes)),
    ]:
        knn = clatch.Matcher(backend).knn(query, train, k)
        assert knn.shape == (len(query), k) and knn.dtype == clatch.MATCH_DTYPE
        ref = reference_knn(query, train, k)
        assert np.array_equal(knn["query"], np.repeat(np.arange(len(query)), k).reshape(-1, k))
        assert np.array_equal(knn["train"], ref[:, :, 0])
        assert np.array_equal(knn["distance"], ref[:, :, 1])


def test_real_features_match_as_the_reference(backend):
    photo = clatch.imread(ASTRONAUT)
    extractor = clatch.Extractor(backend, max_keypoints=600)
    _, a = extractor.detect_and_describe(photo[:400, :400])
    _, b = extractor.detect_and_describe(photo[30:430, 20:420])
    got = as_tuples(clatch.Matcher(backend).match(a, b))
    assert len(got) > 50, "a shifted crop should match well"
    assert got == reference_match(a, b, 0.8, True, None)


@pytest.mark.parametrize(
    "view",
    [
        lambda a: a[::2],  # every other row: rows apart, each contiguous
        lambda a: a[::-1],  # mirrored rows
        np.asfortranarray,  # column-major: bytes of a row apart
        lambda a: a[:, :16],  # the first half of each row: a narrower width
    ],
    ids=["row-step", "mirrored", "fortran", "first-bytes"],
)
def test_descriptor_arrays_of_any_strides(backend, view):
    # Descriptors are read row by row in OpenCV's byte order whatever the array's memory layout.
    rng = np.random.default_rng(9)
    query, train = view(random_descriptors(rng, 120, 32)), view(random_descriptors(rng, 140, 32))
    got = as_tuples(clatch.Matcher(backend, ratio=None).match(query, train))
    assert got == reference_match(np.ascontiguousarray(query), np.ascontiguousarray(train), None, True, None)
    assert len(got) > 0


def test_narrow_descriptors_are_the_first_bytes(backend):
    # bits = 8n uses the first 8n triplets, which OpenCV's byte order puts in the first n bytes.
    photo = clatch.imread(ASTRONAUT)
    _, full = clatch.Extractor(backend, max_keypoints=300).detect_and_describe(photo)
    for bits in (8, 128, 264):
        _, narrow = clatch.Extractor(backend, max_keypoints=300, bits=bits).detect_and_describe(photo)
        assert narrow.shape == (len(full), bits // 8)
        assert np.array_equal(narrow, full[:, : bits // 8])


def test_matches_go_into_opencv(backend):
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(3)
    query, train = random_descriptors(rng, 200, 64), random_descriptors(rng, 300, 64)
    knn = clatch.Matcher(backend).knn(query, train, 2)
    cv = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(query, train, k=2)
    assert np.array_equal(knn["distance"], np.array([[m.distance for m in pair] for pair in cv]))
    unique = knn["distance"][:, 0] < knn["distance"][:, 1]
    assert unique.sum() > 100
    cv_nearest = np.array([pair[0].trainIdx for pair in cv])
    assert np.array_equal(knn["train"][unique, 0], cv_nearest[unique])
