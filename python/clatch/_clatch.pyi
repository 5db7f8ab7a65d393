"""Type stubs of the native module ``clatch._clatch`` (re-exported by ``clatch``)."""

from __future__ import annotations

import os
from typing import Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
#: Whether this build has the CUDA backend (installed with the ``cuda`` feature).
CUDA_BUILT: bool
#: Keypoints: x, y, size, angle, response (float32), octave (int32); the library's ``KeyPoint``.
KEYPOINT_DTYPE: np.dtype
#: Matches: query, train, distance (uint32); the library's ``Match``.
MATCH_DTYPE: np.dtype

#: An image: ``uint8``, 2-D gray (H x W) or H x W x 3 RGB (H x W x 4: alpha ignored).
Image = npt.NDArray[np.uint8]
#: Descriptors: ``uint8``, shape (N, bits / 8), OpenCV LATCH's byte order.
Descriptors = npt.NDArray[np.uint8]
#: A structured array of ``KEYPOINT_DTYPE``.
KeyPoints = np.ndarray
#: A structured array of ``MATCH_DTYPE``.
Matches = np.ndarray
#: Pairs of set indices: a sequence of ``(a, b)`` or an integer array of shape (P, 2).
Pairs = Union[Sequence[Tuple[int, int]], npt.NDArray[np.integer]]
Backend = str

class Extractor:
    """Finds FAST keypoints and computes their 512-bit CLATCH descriptors.

    ``backend``: ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"auto"``. Without ``single_scale`` the
    settings start from the library's defaults (8-level pyramid of factor 1.2, 5000 keypoints shared
    among the levels, 40-pixel windows, sub-pixel positions); ``single_scale=True`` starts from the
    full-resolution speed preset (64-pixel windows, whole pixels). Keywords left at ``None`` keep the
    preset's value. The methods release the GIL while they compute; a gray image whose rows are
    contiguous is read in place meanwhile, so do not write to it from another thread during the call.
    """

    def __init__(
        self,
        backend: Backend = "cpu",
        *,
        single_scale: bool = False,
        threshold: Optional[int] = None,
        max_keypoints: Optional[int] = None,
        keypoint_size: Optional[float] = None,
        grid: Optional[int] = None,
        level_budget: Optional[Literal["geometric", "global"]] = None,
        ranking: Optional[Literal["fast", "harris"]] = None,
        subpixel: Optional[Literal["score", "none"]] = None,
        pyramid: Union[Tuple[int, float], Literal[False], None] = None,
        bits: Optional[int] = None,
        smoothing: Optional[Literal["none", "binomial3", "binomial5"]] = None,
        weights: Optional[Sequence[int]] = None,
    ) -> None: ...
    @property
    def backend(self) -> str:
        """The backend: ``"cpu"`` or ``"cuda:N"``."""
    @property
    def config(self) -> dict:
        """The settings in effect, as the constructor's keywords."""
    def detect(self, image: Image) -> KeyPoints:
        """FAST keypoints of ``image``, strongest first (``KEYPOINT_DTYPE``)."""
    def detect_and_describe(self, image: Image) -> Tuple[KeyPoints, Descriptors]:
        """Keypoints and their descriptors (row i describes keypoint i)."""
    def detect_and_describe_batch(
        self, images: Sequence[Image]
    ) -> list[Tuple[KeyPoints, Descriptors]]:
        """``detect_and_describe`` of every image, in input order."""
    def describe(
        self, image: Image, keypoints: KeyPoints
    ) -> Tuple[KeyPoints, Descriptors, npt.NDArray[np.int64]]:
        """Descriptors of your own keypoints: (described keypoints, descriptors, input index)."""

class Matcher:
    """Brute-force Hamming matcher (ratio test, cross-check, distance limit; ties to the lowest
    index). The methods release the GIL while they compute."""

    def __init__(
        self,
        backend: Backend = "cpu",
        ratio: Optional[float] = 0.8,
        cross_check: bool = True,
        max_distance: Optional[int] = None,
    ) -> None: ...
    @property
    def backend(self) -> str:
        """The backend: ``"cpu"`` or ``"cuda:N"``."""
    @property
    def ratio(self) -> Optional[float]:
        """Lowe's ratio (``None``: no ratio test)."""
    @property
    def cross_check(self) -> bool:
        """Whether only mutual nearest neighbours are kept."""
    @property
    def max_distance(self) -> Optional[int]:
        """The largest distance kept, in bits (``None``: no limit)."""
    def match(self, query: Descriptors, train: Descriptors) -> Matches:
        """The best gallery match of every query that passes the tests, in query order."""
    def knn(self, query: Descriptors, train: Descriptors, k: int) -> Matches:
        """The k nearest gallery descriptors of every query: shape (N, k), nearest first."""
    def match_pairs(self, descriptors: Sequence[Descriptors], pairs: Pairs) -> list[Matches]:
        """``match(descriptors[a], descriptors[b])`` of every pair (a, b), in pair order."""
    @staticmethod
    def all_pairs(n: int) -> npt.NDArray[np.int64]:
        """Every pair (i, j), i < j, of n sets in order: shape (n (n - 1) / 2, 2)."""

def imread(path: Union[str, os.PathLike[str]], max_pixels: int = 100_000_000) -> Image:
    """A PNG, JPEG or PNM file as a 2-D ``uint8`` gray image, read as the command-line tool reads it."""

def to_gray(image: Image) -> Image:
    """The gray image the extractor sees (RGB with OpenCV's integer weights)."""
