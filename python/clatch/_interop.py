"""Keypoints and matches as other tools take them: plain point arrays and OpenCV's records.

A structured array of ``KEYPOINT_DTYPE`` is not a point array: ``keypoints[["x", "y"]]`` is a
structured view that ``cv2.findHomography`` refuses, and ``.view(np.float32).reshape(-1, 2)`` reads
size and angle as every second point. ``points`` gives the (N, 2) ``float32`` array OpenCV wants.
"""

from __future__ import annotations

from typing import Any, List

import numpy as np

from ._clatch import KEYPOINT_DTYPE, MATCH_DTYPE
from ._exceptions import ArgumentTypeError, InvalidInputError, MissingDependencyError

__all__ = ["points", "to_cv2_keypoints", "to_cv2_matches"]


def _records(array: Any, dtype: np.dtype, name: str, what: str) -> np.ndarray:
    """``array`` as a 1-D structured array of ``dtype`` (any strides), or a ClatchError."""
    if not isinstance(array, np.ndarray):
        raise ArgumentTypeError(f"{what} must be a numpy.ndarray of {name}, got {type(array).__name__}")
    if array.dtype != dtype or array.ndim != 1:
        raise InvalidInputError(
            f"{what} must be a 1-D array of dtype {name}, got {array.ndim}-D {array.dtype}",
            kind="WrongDtype",
        )
    return array


def points(keypoints: np.ndarray) -> np.ndarray:
    """The positions of ``keypoints`` (``KEYPOINT_DTYPE``) as a plain C-contiguous ``float32`` array
    of shape (N, 2), one ``(x, y)`` row per keypoint: what ``cv2.findHomography``,
    ``cv2.findFundamentalMat`` and ``cv2.perspectiveTransform`` take. A copy.

    >>> src = clatch.points(kp_a[matches["query"]])
    """
    keypoints = _records(keypoints, KEYPOINT_DTYPE, "clatch.KEYPOINT_DTYPE", "keypoints")
    out = np.empty((len(keypoints), 2), dtype=np.float32)
    out[:, 0] = keypoints["x"]
    out[:, 1] = keypoints["y"]
    return out


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as e:
        raise MissingDependencyError(
            "this needs OpenCV's Python package (cv2), which is not installed: "
            "pip install opencv-python-headless"
        ) from e
    return cv2


def to_cv2_keypoints(keypoints: np.ndarray) -> List[Any]:
    """``keypoints`` (``KEYPOINT_DTYPE``) as a list of ``cv2.KeyPoint`` (x, y, size, angle in
    degrees, response, octave; ``class_id`` -1), in order: for ``cv2.drawKeypoints``,
    ``cv2.drawMatches`` or an OpenCV descriptor's ``compute``. Needs ``cv2``
    (``MissingDependencyError`` without it)."""
    keypoints = _records(keypoints, KEYPOINT_DTYPE, "clatch.KEYPOINT_DTYPE", "keypoints")
    cv2 = _cv2()
    fields = [keypoints[n].tolist() for n in ("x", "y", "size", "angle", "response", "octave")]
    return [cv2.KeyPoint(x, y, s, a, r, o) for x, y, s, a, r, o in zip(*fields)]


def to_cv2_matches(matches: np.ndarray) -> List[Any]:
    """``matches`` (``MATCH_DTYPE``) as a list of ``cv2.DMatch`` (queryIdx, trainIdx, distance), in
    order: for ``cv2.drawMatches``. Needs ``cv2`` (``MissingDependencyError`` without it)."""
    matches = _records(matches, MATCH_DTYPE, "clatch.MATCH_DTYPE", "matches")
    cv2 = _cv2()
    fields = [matches[n].tolist() for n in ("query", "train", "distance")]
    return [cv2.DMatch(q, t, float(d)) for q, t, d in zip(*fields)]
