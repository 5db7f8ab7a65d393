"""Type stubs of the native module ``clatch._clatch`` (re-exported by ``clatch``)."""

from __future__ import annotations

import os
from typing import Any, Callable, Literal, Mapping, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "Extractor",
    "Matcher",
    "OpencvLatch",
    "TwoViewGeometry",
    "verify_pair",
    "verify_pairs",
    "imread",
    "to_gray",
    "_reads_in_place",
    "_rust_match_seconds",
    "_rust_extract_seconds",
    "ImageFolder",
    "PinholeCamera",
    "_FolderJob",
    "_FolderPlan",
    "_FolderWriter",
    "_extract_photos",
    "DEFAULT_GRID",
    "DEFAULT_MAX_KEYPOINTS",
    "SUBPIXEL_METHODS",
    "KEYPOINT_DTYPE",
    "MATCH_DTYPE",
    "CUDA_BUILT",
    "MAX_PAIRS",
    "MAX_IMAGE_SIDE",
    "__version__",
]

__version__: str
#: Whether this build has the CUDA backend (installed with the ``cuda`` feature).
CUDA_BUILT: bool
#: The most pairs ``Matcher.all_pairs`` lists (2 GiB as int64); more raise ``InvalidInputError``.
MAX_PAIRS: int
#: The largest image side the library processes (``clatch::MAX_IMAGE_SIDE``), checked from the shape.
MAX_IMAGE_SIDE: int
#: Keypoints: x, y, size, angle, response (float32), octave (int32); the library's ``KeyPoint``.
KEYPOINT_DTYPE: np.dtype
#: Matches: query, train, distance (uint32); the library's ``Match``.
MATCH_DTYPE: np.dtype
#: ``clatch.colmap``: the grid keypoints are spread over unless told otherwise (the library's).
DEFAULT_GRID: int
#: ``clatch.colmap``: keypoints per photo unless told otherwise (the library's, COLMAP's SIFT budget).
DEFAULT_MAX_KEYPOINTS: int
#: ``clatch.colmap``: the names of ``subpixel=``.
SUBPIXEL_METHODS: Tuple[str, ...]

#: An image: ``uint8``, 2-D gray (H x W) or H x W x 3 RGB, or BGR with ``channels="bgr"`` (H x W x 4:
#: alpha ignored).
_Image = npt.NDArray[np.uint8]
#: Descriptors: ``uint8``, shape (N, bits / 8), OpenCV LATCH's byte order.
_Descriptors = npt.NDArray[np.uint8]
#: A structured array of ``KEYPOINT_DTYPE``.
_KeyPoints = np.ndarray
#: A structured array of ``MATCH_DTYPE``.
_Matches = np.ndarray
#: Pairs of set indices: a sequence of ``(a, b)`` or an integer array of shape (P, 2).
_Pairs = Union[Sequence[Tuple[int, int]], npt.NDArray[np.integer]]
_Backend = str
#: The colour order of an H x W x 3 image: RGB, or OpenCV's BGR (``cv2.imread``).
_Channels = Literal["rgb", "bgr"]

@final
class Extractor:
    """Finds FAST keypoints and computes their 512-bit CLATCH descriptors.

    ``backend``: ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"auto"``. Without ``single_scale`` the
    settings start from the library's defaults (8-level pyramid of factor 1.2, 5000 keypoints shared
    among the levels, 40-pixel windows, sub-pixel positions); ``single_scale=True`` starts from the
    full-resolution speed preset (64-pixel windows, whole pixels). Keywords left at ``None`` keep the
    preset's value. The methods release the GIL while they compute (and copy); a gray image whose
    rows are contiguous is read in place meanwhile, so do not write to it from another thread during
    the call. Colour is RGB unless ``channels="bgr"``. Pickles (rebuilt from backend and config).
    """

    def __new__(
        cls,
        backend: _Backend = "cpu",
        *,
        single_scale: bool = False,
        threshold: Optional[int] = None,
        max_keypoints: Optional[int] = None,
        keypoint_size: Optional[float] = None,
        grid: Optional[int] = None,
        level_budget: Optional[Literal["geometric", "global", "area"]] = None,
        ranking: Optional[Literal["fast", "harris"]] = None,
        subpixel: Optional[Literal["score", "none"]] = None,
        pyramid: Union[Tuple[int, float], Literal[False], None] = None,
        bits: Optional[int] = None,
        smoothing: Optional[Literal["none", "binomial3", "binomial5"]] = None,
        weights: Optional[Sequence[int]] = None,
    ) -> Extractor: ...
    @property
    def backend(self) -> str:
        """The backend: ``"cpu"`` or ``"cuda:N"``."""
    @property
    def config(self) -> dict[str, Any]:
        """The settings in effect, as the constructor's keywords."""
    def __reduce__(self) -> Tuple[Any, ...]:
        """Pickling: rebuilt from ``backend`` and ``config``."""
    def detect(self, image: _Image, *, channels: _Channels = "rgb") -> _KeyPoints:
        """FAST keypoints of ``image``, strongest first (``KEYPOINT_DTYPE``)."""
    def detect_and_describe(
        self, image: _Image, *, channels: _Channels = "rgb"
    ) -> Tuple[_KeyPoints, _Descriptors]:
        """Keypoints and their descriptors (row i describes keypoint i)."""
    def detect_and_describe_batch(
        self, images: Sequence[_Image], *, channels: _Channels = "rgb"
    ) -> list[Tuple[_KeyPoints, _Descriptors]]:
        """``detect_and_describe`` of every image, in input order."""
    def describe(
        self, image: _Image, keypoints: _KeyPoints, *, channels: _Channels = "rgb"
    ) -> Tuple[_KeyPoints, _Descriptors, npt.NDArray[np.int64]]:
        """Descriptors of your own keypoints: (described keypoints, descriptors, input index)."""
    def describe_opencv(
        self, latch: OpencvLatch, image: _Image, keypoints: _KeyPoints, *, channels: _Channels = "rgb"
    ) -> Tuple[_KeyPoints, _Descriptors, npt.NDArray[np.int64]]:
        """OpenCV's LATCH descriptors of your keypoints, bit for bit: (described keypoints,
        descriptors of ``latch.bytes`` bytes, input index)."""

@final
class OpencvLatch:
    """OpenCV's LATCH settings (``cv2.xfeatures2d.LATCH_create``), validated; the defaults are
    OpenCV's. ``Extractor.describe_opencv`` describes with them."""

    def __new__(
        cls,
        bytes: int = 32,
        rotation_invariance: bool = True,
        half_ssd_size: int = 3,
        sigma: float = 2.0,
    ) -> OpencvLatch: ...
    @property
    def bytes(self) -> int:
        """Descriptor length in bytes."""
    @property
    def rotation_invariance(self) -> bool:
        """Whether the sampling pattern turns with each keypoint's angle."""
    @property
    def half_ssd_size(self) -> int:
        """Half the side of each compared patch."""
    @property
    def sigma(self) -> float:
        """The Gaussian blur's sigma (0: no blur)."""
    def __reduce__(self) -> Tuple[Any, ...]:
        """Pickling: the same settings."""

@final
class Matcher:
    """Brute-force Hamming matcher (ratio test, cross-check, distance limit; ties to the lowest
    index). The methods release the GIL while they compute. A pair that cannot match (no query, too
    small a gallery) gives no matches in ``match`` as in ``match_pairs``. Pickles."""

    def __new__(
        cls,
        backend: _Backend = "cpu",
        ratio: Optional[float] = 0.8,
        cross_check: bool = True,
        max_distance: Optional[int] = None,
    ) -> Matcher: ...
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
    def __reduce__(self) -> Tuple[Any, ...]:
        """Pickling: the same settings and backend."""
    def match(self, query: _Descriptors, train: _Descriptors) -> _Matches:
        """The best gallery match of every query that passes the tests, in query order."""
    def knn(self, query: _Descriptors, train: _Descriptors, k: int) -> _Matches:
        """The k nearest gallery descriptors of every query: shape (N, k), nearest first."""
    def match_pairs(self, descriptors: Sequence[_Descriptors], pairs: _Pairs) -> list[_Matches]:
        """``match(descriptors[a], descriptors[b])`` of every pair (a, b), in pair order."""
    @staticmethod
    def all_pairs(n: int) -> npt.NDArray[np.int64]:
        """Every pair (i, j), i < j, of n sets in order: shape (n (n - 1) / 2, 2)."""

def imread(path: Union[str, os.PathLike[str]], max_pixels: int = 100_000_000) -> _Image:
    """A PNG, JPEG or PNM file as a 2-D ``uint8`` gray image, read as the command-line tool reads it."""

def to_gray(image: _Image, *, channels: _Channels = "rgb") -> _Image:
    """The gray image the extractor sees (colour with OpenCV's integer weights)."""

_Camera = Optional[Union[Tuple[int, int], Tuple[int, int, Any]]]
_VerifyInput = Union[Tuple[Any, Any, Any], Tuple[Any, Any, Any, _Camera, _Camera]]

@final
class TwoViewGeometry:
    """The two-view geometry of a verified pair, as COLMAP 3.8's ``TwoViewGeometry::Estimate``."""
    @property
    def config(self) -> str:
        """``"degenerate"``, ``"calibrated"``, ``"uncalibrated"``, ``"planar_or_panoramic"``, ``"watermark"``, ..."""
    @property
    def config_code(self) -> int:
        """COLMAP 3.8's integer for ``config``."""
    @property
    def F(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def E(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def H(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def inliers(self) -> npt.NDArray[np.uint32]:
        """Indices into the pair's matches of the inliers, ascending."""
    @property
    def num_inliers(self) -> int: ...
    @property
    def inlier_counts(self) -> dict[str, int]:
        """Inliers of each model: ``{"E": .., "F": .., "H": ..}``."""

def verify_pair(
    keypoints_a: npt.NDArray[Any],
    keypoints_b: npt.NDArray[Any],
    matches: npt.NDArray[Any],
    camera_a: _Camera = None,
    camera_b: _Camera = None,
    *,
    key: int = 0,
    **options: Any,
) -> TwoViewGeometry:
    """The two-view geometry COLMAP 3.8 would find for one pair (``clatch::verify``, GIL released)."""

def verify_pairs(
    pairs: Sequence[_VerifyInput],
    *,
    keys: Optional[Sequence[int]] = None,
    backend: str = "cpu",
    **options: Any,
) -> list[TwoViewGeometry]:
    """``verify_pair`` of many pairs, GIL released, on the CPU's threads or (``backend="cuda"``) a
    batch per launch on the GPU, the same geometries bit for bit; results in order."""

@final
class ImageFolder:
    """The photos of a folder, checked before any work (``clatch.colmap``): the image files directly
    inside ``images``, in name order, each name UTF-8 without whitespace, each header within
    ``max_pixels``, each image large enough to detect on."""

    def __new__(
        cls, images: Union[str, os.PathLike[str]], *, max_pixels: int = 100_000_000
    ) -> ImageFolder: ...
    @property
    def paths(self) -> list[Any]:
        """The image files (``pathlib.Path``), in name order (image ``i`` of every result)."""
    @property
    def names(self) -> list[str]:
        """Their names in the database: the file names."""
    @property
    def sizes(self) -> list[Tuple[int, int]]:
        """Their sizes ``(width, height)``, from the headers."""
    def __len__(self) -> int: ...
    def shared_camera(self, k_text: str) -> PinholeCamera:
        """The camera of the intrinsic matrix ``k_text`` (9 numbers, row-major) for every photo."""

@final
class PinholeCamera:
    """A PINHOLE camera of the database, in COLMAP's pixel convention."""

    @property
    def width(self) -> int:
        """Image width in pixels."""
    @property
    def height(self) -> int:
        """Image height in pixels."""
    @property
    def fx(self) -> float:
        """Focal length along x, in pixels."""
    @property
    def fy(self) -> float:
        """Focal length along y, in pixels."""
    @property
    def cx(self) -> float:
        """Principal point x, in pixels."""
    @property
    def cy(self) -> float:
        """Principal point y, in pixels."""
    @property
    def focal_is_known(self) -> bool:
        """Whether the focal length is known (a given K is)."""

# Not public API: the library's folder run, its stages and its writer, which clatch.colmap and
# clatch.ray call.
_Photo = Tuple[str, int, int, Optional[int], _KeyPoints, _Descriptors]

@final
class _FolderJob:
    def __new__(
        cls,
        images: Union[str, os.PathLike[str]],
        database: Union[str, os.PathLike[str]],
        *,
        extractor: Extractor,
        matcher: Matcher,
        workspace: Optional[Union[str, os.PathLike[str]]] = None,
        pairs: Optional[Sequence[Tuple[Union[int, str], Union[int, str]]]] = None,
        camera_k: Optional[str] = None,
        camera_k_file: Optional[Union[str, os.PathLike[str]]] = None,
        subpixel: str = "score",
        subpixel_radius: int = 3,
        max_pixels: int = 100_000_000,
        force: bool = False,
        verify: bool = True,
        match_list: bool = False,
            guided_matching: bool = True,
    ) -> _FolderJob: ...
    def run(self, progress: Optional[Callable[[str, int, int], None]] = None) -> dict[str, Any]: ...
    def plan(self) -> _FolderPlan: ...
    def extract_photos(
        self, paths: Sequence[Union[str, os.PathLike[str]]], names: Sequence[str]
    ) -> list[_Photo]: ...
    def match_pairs(
        self, descriptors: Mapping[int, _Descriptors], pairs: Sequence[Tuple[int, int]]
    ) -> list[_Matches]: ...

@final
class _FolderPlan:
    @property
    def paths(self) -> list[Any]: ...
    @property
    def names(self) -> list[str]: ...
    @property
    def pairs(self) -> list[Tuple[int, int]]: ...
    def __len__(self) -> int: ...
    def open_writer(self) -> _FolderWriter: ...

@final
class _FolderWriter:
    def __new__(
        cls,
        database: Union[str, os.PathLike[str]],
        match_list: Union[str, os.PathLike[str]],
        camera: Optional[PinholeCamera] = None,
    ) -> _FolderWriter: ...
    def add_photo(
        self,
        name: str,
        width: int,
        height: int,
        focal_35mm: Optional[int],
        keypoints: _KeyPoints,
        descriptors: Optional[_Descriptors] = None,
    ) -> int: ...
    def add_matches(self, i: int, j: int, matches: _Matches) -> None: ...
    @property
    def photos(self) -> int: ...
    def finish(self) -> Optional[dict[str, Any]]: ...
    def close(self) -> None: ...

def _extract_photos(
    extractor: Extractor,
    paths: Sequence[Union[str, os.PathLike[str]]],
    names: Sequence[str],
    max_pixels: int,
    corner_radius: Optional[int] = None,
) -> list[_Photo]: ...

# Not public API: the test suite's and the overhead bench's hooks.
def _reads_in_place(image: _Image) -> bool:
    """Whether ``image`` would be read in place (no copy) by the extractor."""

def _rust_match_seconds(
    matcher: Matcher, query: _Descriptors, train: _Descriptors, repeats: int
) -> list[float]:
    """Seconds of each of ``repeats`` calls of the library's ``Matcher::match_descriptors``."""

def _rust_extract_seconds(extractor: Extractor, image: _Image, repeats: int) -> list[float]:
    """Seconds of each of ``repeats`` calls of the library's ``Extractor::detect_and_describe``."""
