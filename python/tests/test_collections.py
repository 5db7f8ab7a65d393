"""Batch extraction and pair matching: equal, item by item, to the single calls."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import clatch
from helpers import ASTRONAUT, as_tuples, random_descriptors, synthetic


def test_batch_equals_single_calls(backend):
    photo = clatch.imread(ASTRONAUT)
    images = [
        photo,
        synthetic(200, 260, 11),
        photo[40:300, 100:480],  # a view read in place
        synthetic(180, 150, 12, channels=3),  # RGB
        photo[:, ::-1],  # copied
    ]
    extractor = clatch.Extractor(backend, max_keypoints=800)
    batch = extractor.detect_and_describe_batch(images)
    assert len(batch) == len(images)
    for image, (keypoints, descriptors) in zip(images, batch):
        single_k, single_d = extractor.detect_and_describe(image)
        assert len(single_k) > 0
        assert np.array_equal(keypoints, single_k)
        assert np.array_equal(descriptors, single_d)
    assert extractor.detect_and_describe_batch([]) == []


def test_batch_checks_every_image_first(backend):
    photo = clatch.imread(ASTRONAUT)
    with pytest.raises(clatch.InvalidInputError) as e:
        clatch.Extractor(backend).detect_and_describe_batch([photo, photo[:20, :20]])
    assert e.value.kind == "ImageTooSmall"
    with pytest.raises(clatch.InvalidInputError, match=r"images\[1\]"):
        clatch.Extractor(backend).detect_and_describe_batch([photo, photo.astype(np.int16)])


def test_all_pairs_lists_every_pair_in_order():
    for n in [0, 1, 2, 5, 13]:
        pairs = clatch.Matcher.all_pairs(n)
        assert pairs.shape == (n * (n - 1) // 2, 2)
        assert [tuple(p) for p in pairs.tolist()] == list(itertools.combinations(range(n), 2))


@pytest.mark.parametrize("ratio", [None, 0.8])
def test_match_pairs_equals_single_calls(backend, ratio):
    rng = np.random.default_rng(7)
    base = random_descriptors(rng, 300, 32)
    sets = [
        base,
        np.concatenate([base[100:250] ^ (rng.random((150, 32)) < 0.03).astype(np.uint8) * 0x10, random_descriptors(rng, 90, 32)]),
        random_descriptors(rng, 200, 32),
        base[::3].copy(),
        np.zeros((0, 32), dtype=np.uint8),  # a featureless image
        random_descriptors(rng, 1, 32),  # too small a gallery for the ratio test
    ]
    matcher = clatch.Matcher(backend, ratio=ratio)
    pairs = [(0, 1), (1, 0), (2, 3), (3, 3), (0, 4), (4, 0), (1, 5), (5, 1), (0, 1)]
    as_lists = [list(p) for p in pairs]
    as_arrays = [np.array(p, dtype=np.uint16) for p in pairs]
    for given in [pairs, as_lists, as_arrays, np.array(pairs, dtype=np.int32), clatch.Matcher.all_pairs(len(sets))]:
        results = matcher.match_pairs(sets, given)
        assert len(results) == len(given)
        for (a, b), got in zip(np.asarray(given).reshape(-1, 2).tolist(), results):
            assert got.dtype == clatch.MATCH_DTYPE
            needed = 2 if ratio is not None else 1
            if len(sets[a]) == 0 or len(sets[b]) < needed:
                assert len(got) == 0  # no error for a featureless set, as in Rust
            else:
                assert as_tuples(got) == as_tuples(matcher.match(sets[a], sets[b]))
    assert len(matcher.match_pairs(sets, [(0, 1)])[0]) > 50, "overlapping sets should match"
    assert matcher.match_pairs(sets, []) == []


def test_match_pairs_of_extracted_features(backend):
    photo = clatch.imread(ASTRONAUT)
    crops = [photo[:420, :420], photo[40:460, 30:450], photo[90:, 60:]]
    extractor = clatch.Extractor(backend, max_keypoints=700)
    descriptors = [d for _, d in extractor.detect_and_describe_batch(crops)]
    matcher = clatch.Matcher(backend)
    results = matcher.match_pairs(descriptors, clatch.Matcher.all_pairs(3))
    for (a, b), got in zip(clatch.Matcher.all_pairs(3).tolist(), results):
        assert len(got) > 30
        assert as_tuples(got) == as_tuples(matcher.match(descriptors[a], descriptors[b]))
