"""The exceptions clatch raises.

Every error of the Rust library (``clatch::Error``) is raised as one of these, with the library's
message; ``kind`` names the library's error variant (e.g. ``"ImageTooSmall"``, ``"PairOutOfRange"``).
"""

from __future__ import annotations

__all__ = [
    "ClatchError",
    "InvalidInputError",
    "BackendUnavailableError",
    "CudaError",
    "DeviceOutOfMemoryError",
    "ImageReadError",
    "DatabaseError",
    "ClusterError",
]


class ClatchError(Exception):
    """Base class of every clatch exception.

    ``kind`` is the name of the library error it came from (``"Internal"`` or ``"Panic"`` for a bug
    in clatch).
    """

    kind: str = "Unknown"


class InvalidInputError(ClatchError, ValueError):
    """Bad input or settings: an image's dtype, shape or size, descriptor widths, keypoints, ``k``,
    a pair index, a configuration value, a backend name."""


class BackendUnavailableError(ClatchError, RuntimeError):
    """The backend cannot run here: CUDA not built in (install with the ``cuda`` feature), no
    driver, no such device."""


class CudaError(ClatchError, RuntimeError):
    """A CUDA driver call or kernel launch failed."""


class DeviceOutOfMemoryError(CudaError, MemoryError):
    """The GPU ran out of memory; the device stays usable."""


class ImageReadError(ClatchError, OSError):
    """An image file could not be read or decoded (``clatch.imread``)."""


class DatabaseError(ClatchError, OSError):
    """The COLMAP database or match list could not be written: the database already exists
    (``kind == "DatabaseExists"``; pass ``force=True`` to replace it), or SQLite or the file system
    failed (``clatch.colmap``)."""


class ClusterError(ClatchError, RuntimeError):
    """Work spread over a Ray cluster could not finish (``clatch.ray``): actors died more often than
    allowed (``kind == "ActorsDied"``), or a task failed with an error that is not clatch's own
    (``kind == "TaskFailed"``)."""
