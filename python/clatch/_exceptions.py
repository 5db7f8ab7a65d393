"""The exceptions clatch raises.

Every error of the Rust library (``clatch::Error``) is raised as one of these, with the library's
message; ``kind`` names the library's error variant (e.g. ``"ImageTooSmall"``, ``"PairOutOfRange"``)
or, for what the package itself checks, what was wrong (``"WrongDtype"``, ``"WrongType"``, ...).
Every class has a default ``kind`` of its own, so ``kind`` never reads ``"Unknown"``.
"""

from __future__ import annotations

from typing import Any, Optional

__all__ = [
    "ClatchError",
    "InvalidInputError",
    "ArgumentTypeError",
    "BackendUnavailableError",
    "CudaError",
    "DeviceOutOfMemoryError",
    "ImageReadError",
    "DatabaseError",
    "ClusterError",
    "MissingDependencyError",
    "OutOfMemoryError",
]


class ClatchError(Exception):
    """Base class of every clatch exception.

    ``kind`` is the name of the library error it came from (``"Internal"`` or ``"Panic"`` for a bug
    in clatch). ``ClatchError(message, kind=...)`` sets it; without ``kind`` the class's default.
    """

    kind: str = "Internal"

    def __init__(self, *args: Any, kind: Optional[str] = None) -> None:
        super().__init__(*args)
        if kind is not None:
            self.kind = kind


class InvalidInputError(ClatchError, ValueError):
    """Bad input or settings: an image's dtype, shape or size, descriptor widths, keypoints, ``k``,
    a pair index, a configuration value, a backend name."""

    kind = "InvalidInput"


class ArgumentTypeError(ClatchError, TypeError):
    """An argument of the wrong Python type (``k=2.5``, ``backend=None``): a ``TypeError`` too, so
    both ``except TypeError`` and ``except ClatchError`` catch it (``kind == "WrongType"``)."""

    kind = "WrongType"


class BackendUnavailableError(ClatchError, RuntimeError):
    """The backend cannot run here: CUDA not built in (install with the ``cuda`` feature), no
    driver, no such device."""

    kind = "BackendUnavailable"


class CudaError(ClatchError, RuntimeError):
    """A CUDA driver call or kernel launch failed."""

    kind = "Cuda"


class DeviceOutOfMemoryError(CudaError, MemoryError):
    """The GPU ran out of memory; the device stays usable."""

    kind = "DeviceOutOfMemory"


class ImageReadError(ClatchError, OSError):
    """An image file could not be read or decoded (``clatch.imread``)."""

    kind = "Io"


class DatabaseError(ClatchError, OSError):
    """The COLMAP database or match list could not be written: the database already exists
    (``kind == "DatabaseExists"``; pass ``force=True`` to replace it), or SQLite or the file system
    failed (``clatch.colmap``)."""

    kind = "Sqlite"


class ClusterError(ClatchError, RuntimeError):
    """Work spread over a Ray cluster could not finish (``clatch.ray``): actors died more often than
    allowed (``kind == "ActorsDied"``), a task failed with an error that is not clatch's own
    (``"TaskFailed"``, the default), the cluster lacks the resources an actor asks for
    (``"ResourcesUnavailable"``), or the actors did not start in time (``"ActorsNotStarted"``)."""

    kind = "TaskFailed"


class MissingDependencyError(ClatchError, ImportError):
    """An optional package a call needs is not installed: ``cv2`` (``clatch.to_cv2_keypoints``,
    ``clatch.to_cv2_matches``) or ``ray`` (``clatch.ray``); the message says what to install
    (``kind == "MissingDependency"``)."""

    kind = "MissingDependency"


class OutOfMemoryError(ClatchError, MemoryError):
    """The memory an input needs (a copy of an image, a descriptor set) cannot be allocated on this
    machine (``kind == "OutOfMemory"``): raised instead of the process aborting."""

    kind = "OutOfMemory"
