"""``clatch.verify_pair`` and ``clatch.verify_pairs``: the library's two-view geometry on numpy
arrays, every input form giving the same geometry, and a typed error for every bad input."""

from __future__ import annotations

import numpy as np
import pytest

import clatch

FOCAL, WIDTH, HEIGHT = 500.0, 640, 480
K = np.array([[FOCAL, 0, 320.0], [0, FOCAL, 240.0], [0, 0, 1]])


def shifted_plane(n: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grid of points and the same points 20 px to the left: a homography (a translation)."""
    i = np.arange(n)
    a = np.stack([100.0 + 37.0 * (i % 6), 80.0 + 41.0 * (i // 6)], axis=1).astype(np.float32)
    b = a - np.array([20.0, 0.0], np.float32)
    return a, b, np.stack([i, i], axis=1)


def scene(n: int = 200, outliers: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points at many depths seen by two cameras (K) apart by a rotation and a translation, the
    last ``outliers`` matches wrong."""
    rng = np.random.default_rng(7)
    points = np.stack([rng.uniform(-2, 2, n), rng.uniform(-1.5, 1.5, n), rng.uniform(4, 12, n)], axis=1)
    angle = np.radians(8.0)
    rotation = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    second = points @ rotation.T + np.array([-1.0, 0.1, 0.2])

    def project(p: np.ndarray) -> np.ndarray:
        x = p @ K.T
        return (x[:, :2] / x[:, 2:]).astype(np.float32)

    a, b = project(points), project(second)
    matches = np.stack([np.arange(n), np.arange(n)], axis=1)
    matches[n - outliers :, 1] = (matches[n - outliers :, 1] + 17) % n
    return a, b, matches


def as_keypoints(xy: np.ndarray) -> np.ndarray:
    keypoints = np.zeros(len(xy), clatch.KEYPOINT_DTYPE)
    keypoints["x"], keypoints["y"] = xy[:, 0], xy[:, 1]
    return keypoints


def as_matches(pairs: np.ndarray) -> np.ndarray:
    matches = np.zeros(len(pairs), clatch.MATCH_DTYPE)
    matches["query"], matches["train"] = pairs[:, 0], pairs[:, 1]
    return matches


def same(g: clatch.TwoViewGeometry, h: clatch.TwoViewGeometry) -> bool:
    matrices = all(
        (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
        for x, y in ((g.F, h.F), (g.E, h.E), (g.H, h.H))
    )
    return g.config == h.config and matrices and np.array_equal(g.inliers, h.inliers) and g.inlier_counts == h.inlier_counts


def test_a_translated_plane_is_a_homography():
    a, b, matches = shifted_plane()
    g = clatch.verify_pair(a, b, matches)
    assert (g.config, g.config_code) == ("planar_or_panoramic", 6)
    assert g.num_inliers == 30 and g.inliers.dtype == np.uint32
    assert np.array_equal(g.inliers, np.arange(30))
    assert g.H is not None and g.H.shape == (3, 3) and g.H.dtype == np.float64
    h = g.H / g.H[2, 2]
    assert np.allclose(h, [[1, 0, -20], [0, 1, 0], [0, 0, 1]], atol=1e-6), h
    assert g.E is None and g.inlier_counts["H"] == 30
    assert "planar_or_panoramic" in repr(g)


def sampson_distances(f: np.ndarray, a: np.ndarray, b: np.ndarray, matches: np.ndarray, inliers: np.ndarray) -> np.ndarray:
    """Each inlier's Sampson distance under ``f`` (px), the error COLMAP's threshold bounds."""
    ha = np.c_[a[matches[inliers, 0]], np.ones(len(inliers))]
    hb = np.c_[b[matches[inliers, 1]], np.ones(len(inliers))]
    fa, fb = ha @ f.T, hb @ f
    return np.abs(np.sum(hb * fa, axis=1)) / np.sqrt(fa[:, 0] ** 2 + fa[:, 1] ** 2 + fb[:, 0] ** 2 + fb[:, 1] ** 2)


def test_a_general_scene_is_calibrated_with_k_and_uncalibrated_without():
    a, b, matches = scene()
    camera = (WIDTH, HEIGHT, K)
    calibrated = clatch.verify_pair(a, b, matches, camera, camera)
    assert calibrated.config == "calibrated" and calibrated.E is not None and calibrated.F is not None
    # Every true match; a wrong one only where it happens to lie on its epipolar line.
    inliers = set(calibrated.inliers.tolist())
    assert set(range(160)) <= inliers and len(inliers - set(range(160))) <= 8, sorted(inliers - set(range(160)))
    # E acts on camera coordinates: the true matches satisfy it.
    kinv = np.linalg.inv(K)
    na = np.c_[a[:160], np.ones(160)] @ kinv.T
    nb = np.c_[b[:160], np.ones(160)] @ kinv.T
    residual = np.abs(np.sum(nb * (na @ calibrated.E.T), axis=1)) / np.linalg.norm(calibrated.E)
    assert residual.max() < 1e-3, residual.max()
    plain = clatch.verify_pair(a, b, matches)
    assert plain.config == "uncalibrated" and plain.E is None and plain.F is not None
    assert plain.num_inliers >= 150 and len(set(plain.inliers.tolist()) - set(range(160))) <= 8
    assert plain.inlier_counts["F"] >= plain.num_inliers and plain.inlier_counts["E"] == 0
    assert sampson_distances(plain.F, a, b, matches, plain.inliers).max() <= 4.0


def test_every_input_form_gives_the_same_geometry():
    a, b, matches = scene()
    reference = clatch.verify_pair(a, b, matches)
    assert same(reference, clatch.verify_pair(as_keypoints(a), as_keypoints(b), as_matches(matches)))
    assert same(reference, clatch.verify_pair(a, b, matches.astype(np.uint32)))
    assert same(reference, clatch.verify_pair(np.asfortranarray(a), b[::1], matches.astype(np.uint64)))
    # The sampler's key and seed decide the samples; the same key gives the same geometry.
    assert same(clatch.verify_pair(a, b, matches, key=5), clatch.verify_pair(a, b, matches, key=5))


def test_the_batch_equals_each_pair_alone():
    a, b, matches = scene()
    pa, pb, pm = shifted_plane()
    camera = (WIDTH, HEIGHT, K)
    pairs = [(a, b, matches), (pa, pb, pm), (a, b, matches, camera, camera), (b, a, matches[:, ::-1])]
    keys = [3, 0, 1, 2**63]
    batch = clatch.verify_pairs(pairs, keys=keys, max_error=3.0)
    assert len(batch) == 4
    for pair, key, got in zip(pairs, keys, batch):
        assert same(got, clatch.verify_pair(*pair, key=key, max_error=3.0))
    assert clatch.verify_pairs([]) == []


def test_the_batch_on_the_tested_backend_equals_the_cpus(backend):
    a, b, matches = scene()
    pa, pb, pm = shifted_plane()
    camera = (WIDTH, HEIGHT, K)
    pairs = [(a, b, matches), (pa, pb, pm), (a, b, matches, camera, camera), (a[:5], b[:5], matches[:5])]
    on_cpu = clatch.verify_pairs(pairs, keys=[1, 2, 3, 4])
    got = clatch.verify_pairs(pairs, keys=[1, 2, 3, 4], backend=backend)
    assert len(got) == len(on_cpu) == 4
    assert all(same(g, h) for g, h in zip(got, on_cpu))
    assert got[0].num_inliers > 0


def test_a_bad_or_missing_backend_is_a_typed_error():
    with pytest.raises(clatch.InvalidInputError) as e:
        clatch.verify_pairs([], backend="gpu")
    assert e.value.kind == "InvalidBackend"
    try:
        clatch.Extractor("cuda")
    except clatch.BackendUnavailableError:
        with pytest.raises(clatch.BackendUnavailableError):
            clatch.verify_pairs([], backend="cuda")


def test_options_reach_the_verification():
    a, b, matches = scene()
    assert clatch.verify_pair(a, b, matches, min_num_inliers=1000).config == "degenerate"
    strict = clatch.verify_pair(a, b, matches, max_error=0.001)
    assert strict.num_inliers < clatch.verify_pair(a, b, matches).num_inliers
    filtered = clatch.verify_pair(a, b, matches, neighbour_consistency=True)
    assert filtered.num_inliers >= 100 and not same(filtered, clatch.verify_pair(a, b, matches))


def expect(kind: str, call, *args, **kwargs) -> str:
    with pytest.raises(clatch.InvalidInputError) as e:
        call(*args, **kwargs)
    assert e.value.kind == kind, (e.value.kind, str(e.value))
    return str(e.value)


def test_bad_input_raises_typed_errors():
    a, b, matches = shifted_plane()
    verify = clatch.verify_pair
    assert "float32" in expect("WrongDtype", verify, a.astype(np.float64), b, matches)
    expect("WrongShape", verify, np.zeros((5, 3), np.float32), b, matches)
    expect("NotAnArray", verify, a.tolist(), b, matches)
    expect("WrongDtype", verify, a, b, matches.astype(np.float32))
    expect("WrongShape", verify, a, b, matches[:, :1])
    assert "index -1" in expect("IndexOutOfRange", verify, a, b, np.array([[0, -1]]))
    expect("IndexOutOfRange", verify, a, b, np.array([[2**32, 0]], np.uint64))
    # A match naming a keypoint that is not there, a matched keypoint at NaN.
    assert "keypoint 30" in expect("InvalidInput", verify, a, b, np.array([[0, 30]]))
    nan = a.copy()
    nan[3, 1] = np.nan
    assert "not finite" in expect("InvalidInput", verify, nan, b, matches)
    inf = as_keypoints(a)
    inf["x"][4] = np.inf
    expect("InvalidInput", verify, inf, b, matches)
    # Cameras: both or neither, a pinhole K, a usable one.
    camera = (WIDTH, HEIGHT, K)
    expect("InvalidCamera", verify, a, b, matches, camera)
    expect("InvalidCamera", verify, a, b, matches, camera, (WIDTH,))
    skewed = K.copy()
    skewed[0, 1] = 0.5
    expect("InvalidCamera", verify, a, b, matches, camera, (WIDTH, HEIGHT, skewed))
    expect("InvalidInput", verify, a, b, matches, camera, (WIDTH, HEIGHT, K * [[-1], [1], [1]]))
    expect("InvalidInput", verify, a, b, matches, (-1, HEIGHT), (WIDTH, HEIGHT))
    with pytest.raises(clatch.ArgumentTypeError):
        verify(a, b, matches, "camera", "camera")
    # Options: known names, their types, their ranges.
    assert "max_error" in expect("UnknownOption", verify, a, b, matches, max_eror=3.0)
    with pytest.raises(clatch.ArgumentTypeError):
        verify(a, b, matches, max_error="3")
    with pytest.raises(clatch.ArgumentTypeError):
        verify(a, b, matches, key=1.5)
    expect("InvalidConfig", verify, a, b, matches, confidence=2.0)
    expect("InvalidConfig", verify, a, b, matches, max_error=float("nan"))
    expect("InvalidInput", verify, a, b, matches, seed=-1)
    # The batch names the pair.
    bad = np.array([[0, 99]])
    assert "pair 1" in expect("InvalidInput", clatch.verify_pairs, [(a, b, matches), (a, b, bad)])
    assert "pairs[1]" in expect("WrongDtype", clatch.verify_pairs, [(a, b, matches), (a, b, bad.astype(float))])
    expect("WrongLength", clatch.verify_pairs, [(a, b)])
    expect("WrongLength", clatch.verify_pairs, [(a, b, matches)], keys=[1, 2])
    with pytest.raises(clatch.ArgumentTypeError):
        clatch.verify_pairs(3)
