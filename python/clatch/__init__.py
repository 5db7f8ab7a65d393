"""clatch: FAST keypoints, CLATCH binary descriptors and Hamming matching on numpy arrays.

The classes mirror the Rust library: ``Extractor`` (``detect``, ``detect_and_describe``,
``detect_and_describe_batch``, ``describe``) and ``Matcher`` (``match``, ``knn``, ``match_pairs``,
``all_pairs``). Images are ``uint8`` arrays (2-D gray or H x W x 3 RGB); keypoints come back as
structured arrays of ``KEYPOINT_DTYPE``, descriptors as ``uint8`` arrays of shape (N, bits / 8) in
OpenCV LATCH's byte order, matches as structured arrays of ``MATCH_DTYPE``. Every error is a
``ClatchError``. ``clatch.colmap.match_folder`` turns a folder of photos into a COLMAP database
(as ``clatch colmap``); ``clatch.ray.match_folder`` does the same over a Ray cluster (``import
clatch.ray``; Ray is needed only then).
"""

from __future__ import annotations

from ._clatch import (
    CUDA_BUILT,
    KEYPOINT_DTYPE,
    MATCH_DTYPE,
    Extractor,
    Matcher,
    __version__,
    imread,
    to_gray,
)
from ._exceptions import (
    BackendUnavailableError,
    ClatchError,
    ClusterError,
    CudaError,
    DatabaseError,
    DeviceOutOfMemoryError,
    ImageReadError,
    InvalidInputError,
)
from . import colmap

__all__ = [
    "CUDA_BUILT",
    "KEYPOINT_DTYPE",
    "MATCH_DTYPE",
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
    "__version__",
    "imread",
    "to_gray",
]
