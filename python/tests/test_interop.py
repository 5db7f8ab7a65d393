"""Results handed to OpenCV: plain point arrays, cv2 records, the README's snippet with
cv2.findHomography, and OpenCV's own LATCH computed bit for bit."""

from __future__ import annotations

import os
import re
import sys

import numpy as np
import pytest

import clatch
from helpers import ASTRONAUT, REPO


def features(max_keypoints: int = 500):
    photo = clatch.imread(ASTRONAUT)
    return photo, *clatch.Extractor(max_keypoints=max_keypoints).detect_and_describe(photo)


def test_points_are_a_plain_array_of_positions():
    """Finding P4: ``kp[["x", "y"]]`` is a structured view (cv2 refuses it) and
    ``.view(np.float32).reshape(-1, 2)`` reads size and angle as every second point."""
    _, keypoints, _ = features()
    for kp in (keypoints, keypoints[::-3], keypoints[:0]):
        xy = clatch.points(kp)
        assert xy.dtype == np.float32 and xy.shape == (len(kp), 2) and xy.flags.c_contiguous
        assert xy.dtype.names is None
        assert np.array_equal(xy[:, 0], kp["x"]) and np.array_equal(xy[:, 1], kp["y"])
    with pytest.raises(clatch.InvalidInputError):
        clatch.points(np.zeros((3, 2), np.float32))
    with pytest.raises(clatch.ArgumentTypeError):
        clatch.points([(1.0, 2.0)])


def test_cv2_records():
    cv2 = pytest.importorskip("cv2")
    photo, keypoints, descriptors = features()
    cv_keypoints = clatch.to_cv2_keypoints(keypoints)
    assert len(cv_keypoints) == len(keypoints)
    for kp, cv_kp in zip(keypoints[:50], cv_keypoints):
        assert isinstance(cv_kp, cv2.KeyPoint)
        assert cv_kp.pt == (kp["x"], kp["y"])
        assert (cv_kp.size, cv_kp.angle, cv_kp.response, cv_kp.octave) == (kp["size"], kp["angle"], kp["response"], kp["octave"])
    assert np.array_equal(cv2.KeyPoint_convert(cv_keypoints), clatch.points(keypoints))
    matches = clatch.Matcher().match(descriptors, descriptors[::-1].copy())
    cv_matches = clatch.to_cv2_matches(matches)
    assert [(m.queryIdx, m.trainIdx, m.distance) for m in cv_matches] == [
        (int(m["query"]), int(m["train"]), float(m["distance"])) for m in matches
    ]
    # What cv2's own matcher finds, with the same descriptors.
    bf = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(descriptors, descriptors[::-1].copy())
    assert {(m.queryIdx, m.trainIdx) for m in cv_matches} <= {(m.queryIdx, m.trainIdx) for m in bf}
    cv2.drawMatches(photo, cv_keypoints, photo, cv_keypoints[::-1], cv_matches[:20], None)


def test_a_missing_cv2_is_a_typed_error(monkeypatch):
    _, keypoints, _ = features(50)
    monkeypatch.setitem(sys.modules, "cv2", None)  # import cv2 now raises ImportError
    for call in (lambda: clatch.to_cv2_keypoints(keypoints), lambda: clatch.to_cv2_matches(np.zeros(1, clatch.MATCH_DTYPE))):
        with pytest.raises(clatch.MissingDependencyError) as info:
            call()
        assert isinstance(info.value, ImportError) and info.value.kind == "MissingDependency"
        assert "pip install" in str(info.value)


def readme_snippet(path):
    blocks = re.findall(r"```python\n(.*?)```", path.read_text(), re.S)
    return next(b for b in blocks if "findHomography" in b)


def test_the_readme_snippet_runs_with_find_homography(tmp_path, monkeypatch):
    """Finding P4: the README's snippet, as written, on two views related by a known homography."""
    cv2 = pytest.importorskip("cv2")
    gray = clatch.imread(ASTRONAUT)
    colour = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    colour[..., 0] //= 2  # a BGR photo whose channels differ
    truth = np.array([[0.95, 0.08, 12.0], [-0.06, 1.0, 20.0], [0.0, 0.0001, 1.0]])
    warped = cv2.warpPerspective(colour, truth, gray.shape[::-1])
    cv2.imwrite(str(tmp_path / "a.jpg"), cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY), [cv2.IMWRITE_JPEG_QUALITY, 98])
    cv2.imwrite(str(tmp_path / "b.jpg"), warped, [cv2.IMWRITE_JPEG_QUALITY, 98])
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(readme_snippet(REPO / "python" / "README.md"), "README.md", "exec"), scope)
    H, inliers, matches = scope["H"], scope["inliers"], scope["matches"]
    assert H is not None and int(inliers.sum()) > 0.5 * len(matches) > 50
    corners = np.array([[[100.0, 100.0]], [[400.0, 300.0]]], np.float32)
    assert np.abs(cv2.perspectiveTransform(corners, H) - cv2.perspectiveTransform(corners, truth)).max() < 2.0
    assert scope["picture"].shape[1] == 2 * gray.shape[1]


def test_opencv_latch_equals_cv2_bit_for_bit():
    """Finding P10: OpenCV's LATCH (the library's ``OpencvLatch``) from Python, equal to
    ``cv2.xfeatures2d.LATCH_create(...).compute`` on the same keypoints (tests/opencv_latch.rs
    checks the library the same way over many more settings)."""
    cv2 = pytest.importorskip("cv2")
    if not hasattr(cv2, "xfeatures2d"):
        if os.environ.get("CLATCH_REQUIRE_OPENCV"):
            raise AssertionError("CLATCH_REQUIRE_OPENCV is set but cv2 has no xfeatures2d (contrib)")
        pytest.skip("opencv-contrib-python not installed")
    photo = clatch.imread(ASTRONAUT)
    detected = clatch.Extractor(max_keypoints=1500).detect(photo)
    rng = np.random.default_rng(8)
    extra = np.zeros(500, clatch.KEYPOINT_DTYPE)
    extra["x"] = rng.uniform(0, photo.shape[1] - 1, 500).astype(np.float32)
    extra["y"] = rng.uniform(0, photo.shape[0] - 1, 500).astype(np.float32)
    extra["angle"] = rng.uniform(-360, 360, 500).astype(np.float32)
    extra["size"] = 7.0
    keypoints = np.concatenate([detected, extra])
    extractor = clatch.Extractor()
    compared = 0
    for settings in ({}, {"bytes": 64, "rotation_invariance": False, "half_ssd_size": 2, "sigma": 0.0}, {"bytes": 16, "sigma": 1.5}):
        latch = clatch.OpencvLatch(**settings)
        cv_latch = cv2.xfeatures2d.LATCH_create(latch.bytes, latch.rotation_invariance, latch.half_ssd_size, latch.sigma)
        cv_keypoints = clatch.to_cv2_keypoints(keypoints)
        for i, kp in enumerate(cv_keypoints):
            kp.class_id = i  # carries the input index through cv2's border filter
        kept, cv_rows = cv_latch.compute(photo, cv_keypoints)
        cv_index = [kp.class_id for kp in kept]
        described, rows, index = extractor.describe_opencv(latch, photo, keypoints)
        assert rows.dtype == np.uint8 and rows.shape == (len(index), latch.bytes)
        assert np.array_equal(described, keypoints[index])
        ours = dict(zip(index.tolist(), rows))
        theirs = dict(zip(cv_index, cv_rows))
        # We also skip, on purpose, the rare keypoint OpenCV keeps but reads outside the image for.
        assert set(ours) <= set(theirs) and len(ours) >= len(theirs) - 5
        for i, row in ours.items():
            assert np.array_equal(row, theirs[i]), (settings, i)
        compared += len(ours)
    assert compared > 3000
    # The same call takes colour, in either order.
    bgr = np.stack([photo // 2, photo, photo], axis=-1)
    assert np.array_equal(
        extractor.describe_opencv(clatch.OpencvLatch(), bgr, keypoints, channels="bgr")[1],
        extractor.describe_opencv(clatch.OpencvLatch(), clatch.to_gray(bgr[..., ::-1]), keypoints)[1],
    )


@pytest.mark.parametrize(
    "settings,kind",
    [({"bytes": 3}, "InvalidConfig"), ({"bytes": -1}, "InvalidConfig"), ({"half_ssd_size": 25}, "InvalidConfig"), ({"sigma": float("nan")}, "InvalidConfig")],
)
def test_opencv_latch_settings_are_checked(settings, kind):
    with pytest.raises(clatch.InvalidInputError) as info:
        clatch.OpencvLatch(**settings)
    assert info.value.kind == kind
    latch = clatch.OpencvLatch()
    assert (latch.bytes, latch.rotation_invariance, latch.half_ssd_size, latch.sigma) == (32, True, 3, 2.0)
