"""Bad input raises a ClatchError subclass with the library's message and its variant as ``kind``;
nothing crashes, hangs or panics."""

from __future__ import annotations

import numpy as np
import pytest

import clatch
from helpers import ASTRONAUT, random_descriptors


@pytest.fixture(scope="module")
def photo():
    return clatch.imread(ASTRONAUT)


def raises(exc, kind, call):
    with pytest.raises(exc) as info:
        call()
    assert isinstance(info.value, clatch.ClatchError)
    assert info.value.kind == kind, f"{info.value.kind}: {info.value}"
    assert str(info.value), "the message is the library's Display text, never empty"
    return info.value


def test_the_hierarchy():
    assert issubclass(clatch.InvalidInputError, ValueError)
    assert issubclass(clatch.InvalidInputError, clatch.ClatchError)
    assert issubclass(clatch.BackendUnavailableError, RuntimeError)
    assert issubclass(clatch.DeviceOutOfMemoryError, clatch.CudaError)
    assert issubclass(clatch.ImageReadError, OSError)
    assert issubclass(clatch.ClatchError, Exception)


@pytest.mark.parametrize(
    "image,kind",
    [
        (np.zeros((100, 100), dtype=np.float32), "WrongDtype"),
        (np.zeros((100, 100), dtype=np.int16), "WrongDtype"),
        (np.zeros((100, 100), dtype=bool), "WrongDtype"),
        (np.zeros(10_000, dtype=np.uint8), "WrongShape"),
        (np.zeros((100, 100, 2), dtype=np.uint8), "WrongShape"),
        (np.zeros((2, 100, 100, 3), dtype=np.uint8), "WrongShape"),
        (np.zeros((63, 200), dtype=np.uint8), "ImageTooSmall"),
        (np.zeros((200, 63, 3), dtype=np.uint8), "ImageTooSmall"),
        (np.zeros((0, 200), dtype=np.uint8), "EmptyImage"),
        (np.zeros((40_000, 64), dtype=np.uint8), "ImageTooLarge"),
        ([[0] * 100] * 100, "NotAnArray"),
    ],
)
def test_bad_images(backend, image, kind):
    extractor = clatch.Extractor(backend)
    for call in (extractor.detect, extractor.detect_and_describe, clatch.to_gray):
        if call is clatch.to_gray and kind == "ImageTooSmall":
            continue  # converting a small image is fine; only extraction needs a window
        raises(clatch.InvalidInputError, kind, lambda: call(image))


def test_sizes_are_numpy_shapes(backend):
    """Image sizes are said as numpy shapes, (H, W), never the library's W x H."""
    extractor = clatch.Extractor(backend)
    e = raises(clatch.InvalidInputError, "ImageTooSmall", lambda: extractor.detect(np.zeros((63, 200), np.uint8)))
    assert "shape (63, 200)" in str(e) and "200x63" not in str(e)
    e = raises(clatch.InvalidInputError, "ImageTooLarge", lambda: extractor.detect(np.zeros((40_000, 64), np.uint8)))
    assert "shape (40000, 64)" in str(e)
    e = raises(clatch.InvalidInputError, "EmptyImage", lambda: extractor.detect(np.zeros((0, 70, 3), np.uint8)))
    assert "shape (0, 70, 3)" in str(e)


@pytest.mark.parametrize("name", ["gpu", "CPU", "cuda:", "cuda:x", "cuda:-1", "", "cpu "])
def test_bad_backend_strings(name):
    raises(clatch.InvalidInputError, "InvalidBackend", lambda: clatch.Extractor(name))
    raises(clatch.InvalidInputError, "InvalidBackend", lambda: clatch.Matcher(name))


@pytest.mark.skipif(clatch.CUDA_BUILT, reason="this build has CUDA")
def test_cuda_without_the_feature():
    for make in (clatch.Extractor, clatch.Matcher):
        e = raises(clatch.BackendUnavailableError, "BackendUnavailable", lambda: make("cuda:0"))
        assert "--features cuda" in str(e)


@pytest.mark.parametrize(
    "keywords",
    [
        {"threshold": 0},
        {"threshold": 255},
        {"threshold": 300},
        {"threshold": -1},
        {"max_keypoints": 0},
        {"grid": 0},
        {"grid": 65},
        {"keypoint_size": float("nan")},
        {"keypoint_size": 0.0},
        {"pyramid": (0, 1.2)},
        {"pyramid": (3, 2.5)},
        {"pyramid": (3, 1.0)},
        {"pyramid": "x"},
        {"pyramid": True},
        {"level_budget": "ORB"},
        {"ranking": "sift"},
        {"subpixel": "quadratic"},
        {"smoothing": "gauss"},
        {"bits": 100},
        {"bits": 0},
        {"bits": 520},
        {"weights": [1] * 63},
        {"weights": [0] * 64},
        {"weights": [1 << 30] * 64},
        {"weights": [-1] * 64},
    ],
)
def test_bad_extractor_settings(backend, keywords):
    with pytest.raises(clatch.InvalidInputError) as info:
        clatch.Extractor(backend, **keywords)
    assert info.value.kind in {"InvalidConfig", "InvalidDescriptorWidth", "WeightsLength", "WeightsAllZero", "WeightsOverflow"}


@pytest.mark.parametrize(
    "keywords,kind",
    [
        ({"threshold": 0}, "InvalidConfig"),
        ({"bits": 100}, "InvalidDescriptorWidth"),
        ({"weights": [1] * 63}, "WeightsLength"),
        ({"weights": [0] * 64}, "WeightsAllZero"),
        ({"weights": [1 << 30] * 64}, "WeightsOverflow"),
    ],
)
def test_settings_errors_carry_the_library_error_kind(backend, keywords, kind):
    raises(clatch.InvalidInputError, kind, lambda: clatch.Extractor(backend, **keywords))


def test_option_and_backend_names_are_the_library_s(backend):
    e = raises(clatch.InvalidInputError, "InvalidConfig", lambda: clatch.Extractor(backend, smoothing="gauss"))
    assert str(e) == 'smoothing must be one of "none", "binomial3", "binomial5", got "gauss"'
    e = raises(clatch.InvalidInputError, "InvalidConfig", lambda: clatch.Extractor(backend, level_budget="orb"))
    assert str(e) == 'level_budget must be one of "global", "geometric", "area", got "orb"'
    e = raises(clatch.InvalidInputError, "InvalidBackend", lambda: clatch.Matcher("gpu"))
    assert str(e) == 'backend must be one of "auto", "cpu", "cuda", "cuda:N", got "gpu"'
    chosen = {"level_budget": "global", "ranking": "harris", "subpixel": "none", "smoothing": "binomial5"}
    config = clatch.Extractor(backend, **chosen).config
    assert {k: config[k] for k in chosen} == chosen


@pytest.mark.parametrize("keywords", [{"ratio": 0.0}, {"ratio": 1.5}, {"ratio": float("nan")}, {"ratio": -0.5}, {"max_distance": -1}])
def test_bad_matcher_settings(backend, keywords):
    raises(clatch.InvalidInputError, "InvalidConfig", lambda: clatch.Matcher(backend, **keywords))


def test_bad_descriptors(backend):
    rng = np.random.default_rng(1)
    d64, d32 = random_descriptors(rng, 10, 64), random_descriptors(rng, 10, 32)
    m = clatch.Matcher(backend)
    raises(clatch.InvalidInputError, "DescriptorWidthMismatch", lambda: m.match(d64, d32))
    raises(clatch.InvalidInputError, "DescriptorWidthMismatch", lambda: m.knn(d32, d64, 2))
    raises(clatch.InvalidInputError, "InvalidDescriptorWidth", lambda: m.match(random_descriptors(rng, 3, 65), d64))
    raises(clatch.InvalidInputError, "InvalidDescriptorWidth", lambda: m.match(np.zeros((3, 0), np.uint8), d64))
    raises(clatch.InvalidInputError, "WrongDtype", lambda: m.match(d64.astype(np.int32), d64))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match(d64[0], d64))
    raises(clatch.InvalidInputError, "NotAnArray", lambda: m.match(d64.tolist(), d64))
    raises(clatch.InvalidInputError, "InvalidK", lambda: m.knn(d64, d64[:0], 1))
    raises(clatch.InvalidInputError, "InvalidK", lambda: m.knn(d64, d64, 0))
    raises(clatch.InvalidInputError, "InvalidK", lambda: m.knn(d64, d64, -3))
    raises(clatch.InvalidInputError, "InvalidK", lambda: m.knn(d64, d64, 11))
    assert len(m.match(d64[:0], d64)) == 0  # no queries: no matches, no error


def test_bad_pairs(backend):
    rng = np.random.default_rng(2)
    sets = [random_descriptors(rng, 20, 16) for _ in range(3)]
    m = clatch.Matcher(backend)
    e = raises(clatch.InvalidInputError, "PairOutOfRange", lambda: m.match_pairs(sets, [(0, 1), (1, 3)]))
    assert "pair 1" in str(e) and "3 sets" in str(e)
    raises(clatch.InvalidInputError, "PairOutOfRange", lambda: m.match_pairs(sets, [(0, -1)]))
    raises(clatch.InvalidInputError, "PairOutOfRange", lambda: m.match_pairs(sets, np.array([[0, 7]])))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match_pairs(sets, np.array([0, 1])))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match_pairs(sets, np.array([[0.0, 1.0]])))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match_pairs(sets, [(0, 1, 2)]))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match_pairs(sets, [[0]]))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match_pairs(sets, "01"))
    raises(clatch.InvalidInputError, "WrongShape", lambda: m.match_pairs(sets, 3))
    mixed = [sets[0], random_descriptors(rng, 20, 32)]
    raises(clatch.InvalidInputError, "DescriptorWidthMismatch", lambda: m.match_pairs(mixed, [(0, 0)]))
    raises(clatch.InvalidInputError, "InvalidInput", lambda: clatch.Matcher.all_pairs(-1))


def test_bad_keypoints(backend, photo):
    extractor = clatch.Extractor(backend)
    raises(clatch.InvalidInputError, "WrongDtype", lambda: extractor.describe(photo, np.zeros((3, 2), np.float32)))
    keypoints = np.zeros(2, dtype=clatch.KEYPOINT_DTYPE)
    keypoints["x"], keypoints["y"], keypoints["size"] = [100.0, np.nan], [100.0, 50.0], 64.0
    raises(clatch.InvalidInputError, "InvalidKeyPoint", lambda: extractor.describe(photo, keypoints))


def test_unreadable_files(tmp_path):
    e = raises(clatch.ImageReadError, "Io", lambda: clatch.imread(tmp_path / "missing.png"))
    assert "missing.png" in str(e)
    (tmp_path / "garbage.png").write_bytes(b"not an image at all")
    with pytest.raises(clatch.ImageReadError):
        clatch.imread(tmp_path / "garbage.png")
    with pytest.raises(clatch.ImageReadError):
        clatch.imread(tmp_path)  # a folder
    with pytest.raises(clatch.ImageReadError):
        clatch.imread(ASTRONAUT, max_pixels=1000)


def test_errors_leave_the_objects_usable(backend, photo):
    extractor, matcher = clatch.Extractor(backend, max_keypoints=100), clatch.Matcher(backend)
    with pytest.raises(clatch.ClatchError):
        extractor.detect(photo[:10, :10])
    _, d = extractor.detect_and_describe(photo)
    with pytest.raises(clatch.ClatchError):
        matcher.match(d, d[:, :8])
    assert len(matcher.match(d, d)) == len(d)


def test_all_pairs_refuses_a_list_too_large_to_hold():
    """``all_pairs(10**6)`` listed 5 * 10^11 pairs (24 GB, then the kernel's OOM kill).
    Now every n whose list would pass ``MAX_PAIRS`` is refused before anything is allocated."""
    for n in (10**6, 10**12, 2**62, 16_385):
        e = raises(clatch.InvalidInputError, "TooManyPairs", lambda: clatch.Matcher.all_pairs(n))
        assert str(n) in str(e) and "match_pairs" in str(e)
    assert clatch.MAX_PAIRS == 2**27 and 16_384 * 16_383 // 2 <= clatch.MAX_PAIRS < 16_385 * 16_384 // 2
    pairs = clatch.Matcher.all_pairs(1000)
    assert pairs.shape == (499_500, 2) and pairs.dtype == np.int64
    assert pairs[0].tolist() == [0, 1] and pairs[-1].tolist() == [998, 999]
    assert clatch.Matcher.all_pairs(0).shape == clatch.Matcher.all_pairs(1).shape == (0, 2)


@pytest.mark.parametrize("ratio", [0.8, None])
def test_one_rule_for_a_pair_that_cannot_match(backend, ratio):
    """An empty descriptor set (a blank frame) raised EmptyGallery in ``match`` but gave
    no matches in ``match_pairs``. One rule now, the library's ``MatchConfig::can_match``: a pair
    with no query, or fewer gallery descriptors than the rules look at (none; one with the ratio
    test), gives no matches, in both calls."""
    rng = np.random.default_rng(4)
    d = random_descriptors(rng, 30, 32)
    m = clatch.Matcher(backend, ratio=ratio)
    sets = {"blank": d[:0], "one": d[:1], "two": d[:2], "many": d}
    for qname, query in sets.items():
        for tname, train in sets.items():
            single = m.match(query, train)
            [batch] = m.match_pairs([query, train], [(0, 1)])
            assert single.dtype == clatch.MATCH_DTYPE
            assert np.array_equal(single, batch), (qname, tname)
            if qname == "blank" or tname == "blank" or (tname == "one" and ratio is not None):
                assert len(single) == 0
    # A width mismatch is a mistake, not data: it raises whatever the sizes.
    raises(clatch.InvalidInputError, "DescriptorWidthMismatch", lambda: m.match(d[:0], d[:0, :16]))


def test_knn_names_the_k_it_was_given(backend):
    """``knn(k=-1)`` said "k = 0 is invalid"."""
    d = random_descriptors(np.random.default_rng(5), 10, 32)
    m = clatch.Matcher(backend)
    for k in (-1, -(2**40), 0, 11):
        e = raises(clatch.InvalidInputError, "InvalidK", lambda: m.knn(d, d, k))
        assert f"k = {k} is invalid" in str(e)
    e = raises(clatch.InvalidInputError, "InvalidK", lambda: m.knn(d, d[:0], 2))
    assert "k = 2" in str(e) and "gallery of 0" in str(e)


def test_range_errors_say_the_range(backend):
    """A setting out of range said only "(out of range)"; now the library's range."""
    for keywords, words in [
        ({"threshold": 300}, "threshold = 300 (must be in 1..=254)"),
        ({"threshold": -1}, "threshold = -1 (must be in 1..=254)"),
        ({"grid": 0}, "grid = 0 (must be in 1..=64)"),
        ({"grid": 100000}, "grid = 100000 (must be in 1..=64)"),
        ({"max_keypoints": -5}, "max_keypoints = -5 (must be at least 1)"),
        ({"pyramid": (-1, 1.2)}, "pyramid.levels = -1 (must be in 1..=32)"),
        ({"pyramid": (100, 1.2)}, "pyramid.levels = 100 (must be in 1..=32)"),
        ({"bits": -8}, "bits = -8 (must be a multiple of 8 between 8 and 512)"),
        ({"weights": [-1] * 64}, "weights = -1 (each must be in 0..=4294967295)"),
    ]:
        e = raises(clatch.InvalidInputError, "InvalidConfig", lambda: clatch.Extractor(backend, **keywords))
        assert words in str(e), str(e)
        assert "(out of range)" not in str(e)


def test_every_error_class_has_a_kind_of_its_own():
    """``ClusterError.kind`` read "Unknown"."""
    classes = [getattr(clatch, n) for n in clatch.__all__ if n.endswith("Error")]
    assert len(classes) >= 10
    for cls in classes:
        assert issubclass(cls, clatch.ClatchError)
        error = cls("message")
        assert error.kind and error.kind != "Unknown", cls.__name__
        assert cls("message", kind="Special").kind == "Special"
    assert clatch.ClusterError("x").kind == "TaskFailed"


@pytest.mark.parametrize(
    "call",
    [
        lambda m, e, d, i: m.knn(d, d, k=2.5),
        lambda m, e, d, i: m.knn(d, d, "2"),
        lambda m, e, d, i: clatch.Matcher(backend=None),
        lambda m, e, d, i: clatch.Extractor(None),
        lambda m, e, d, i: clatch.Extractor(threshold=2.5),
        lambda m, e, d, i: clatch.Extractor(single_scale="yes"),
        lambda m, e, d, i: clatch.Extractor(level_budget=3),
        lambda m, e, d, i: clatch.Extractor(weights=3),
        lambda m, e, d, i: clatch.Matcher(ratio="0.8"),
        lambda m, e, d, i: clatch.Matcher(cross_check=None),
        lambda m, e, d, i: clatch.Matcher(max_distance=1.5),
        lambda m, e, d, i: clatch.Matcher.all_pairs(2.0),
        lambda m, e, d, i: m.match_pairs(5, [(0, 1)]),
        lambda m, e, d, i: e.detect_and_describe_batch(5),
        lambda m, e, d, i: e.detect(i, channels=1),
        lambda m, e, d, i: clatch.imread(None),
        lambda m, e, d, i: clatch.imread(ASTRONAUT, max_pixels="many"),
        lambda m, e, d, i: clatch.OpencvLatch(bytes=32.0),
        lambda m, e, d, i: e.describe_opencv("latch", i, np.zeros(0, clatch.KEYPOINT_DTYPE)),
    ],
)
def test_type_mistakes_are_clatch_errors_and_type_errors(backend, call):
    """``k=2.5`` or ``backend=None`` raised a plain TypeError, though every error is a
    ClatchError. Now an ArgumentTypeError, which is both, naming the argument."""
    m, e = clatch.Matcher(backend), clatch.Extractor(backend)
    d = random_descriptors(np.random.default_rng(6), 10, 32)
    image = np.zeros((100, 100), np.uint8)
    with pytest.raises(TypeError) as info:
        call(m, e, d, image)
    assert isinstance(info.value, clatch.ClatchError) and isinstance(info.value, clatch.ArgumentTypeError)
    assert info.value.kind == "WrongType"
    assert " must be " in str(info.value)
    with pytest.raises(clatch.ClatchError):
        call(m, e, d, image)
