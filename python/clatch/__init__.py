"""clatch: FAST keypoints, CLATCH binary descriptors and Hamming matching on numpy arrays.

The classes mirror the Rust library: ``Extractor`` (``detect``, ``detect_and_describe``,
``detect_and_describe_batch``, ``describe``) and ``Matcher`` (``match``, ``knn``, ``match_pairs``,
``all_pairs``). Images are ``uint8`` arrays (2-D gray or H x W x 3 RGB); keypoints come back as
structured arrays of ``KEYPOINT_DTYPE``, descriptors as ``uint8`` arrays of shape (N, bits / 8) in
OpenCV LATCH's byte order, matches as structured arrays of ``MATCH_DTYPE``. Every error is a
``ClatchError`` (an argument of the wrong Python type raises ``ArgumentTypeError``, a ``ClatchError``
that is also a ``TypeError``). Colour images are RGB unless ``channels="bgr"`` (``cv2.imread``).
``points``, ``to_cv2_keypoints`` and ``to_cv2_matches`` hand results to OpenCV;
``OpencvLatch`` with ``Extractor.describe_opencv`` computes OpenCV's own LATCH bit for bit.
``verify_pair`` (and ``verify_pairs``, many at once) gives the two-view geometry COLMAP 3.8 would find
for a pair's matches (``TwoViewGeometry``: F, E, H, the inliers).
Extractors and matchers pickle (rebuilt from their settings on the same backend).
``clatch.colmap.match_folder`` turns a folder of photos into a COLMAP database
(as ``clatch colmap``); ``clatch.ray.match_folder`` does the same over a Ray cluster (``import
clatch.ray``; Ray is needed only then).
"""

from __future__ import annotations

from ._clatch import (
    CUDA_BUILT,
    KEYPOINT_DTYPE,
    MATCH_DTYPE,
    MAX_IMAGE_SIDE,
    MAX_PAIRS,
    Extractor,
    Matcher,
    OpencvLatch,
    TwoViewGeometry,
    __version__,
    imread,
    to_gray,
    verify_pair,
    verify_pairs,
)
from ._exceptions import (
    ArgumentTypeError,
    BackendUnavailableError,
    ClatchError,
    ClusterError,
    CudaError,
    DatabaseError,
    DeviceOutOfMemoryError,
    ImageReadError,
    InvalidInputError,
    MissingDependencyError,
    OutOfMemoryError,
)
from ._interop import points, to_cv2_keypoints, to_cv2_matches
from . import colmap

__all__ = [
    "CUDA_BUILT",
    "KEYPOINT_DTYPE",
    "MATCH_DTYPE",
    "MAX_IMAGE_SIDE",
    "MAX_PAIRS",
    "ArgumentTypeError",
    "BackendUnavailableError",
    "ClatchError",
    "ClusterError",
    "CudaError",
    "DatabaseError",
    "DeviceOutOfMemoryError",
    "Extractor",
    "ImageReadError",
    "InvalidInputError",
    "Matcher",
    "MissingDependencyError",
    "OpencvLatch",
    "OutOfMemoryError",
    "TwoViewGeometry",
    "__version__",
    "imread",
    "points",
    "to_cv2_keypoints",
    "to_cv2_matches",
    "to_gray",
    "verify_pair",
    "verify_pairs",
]
