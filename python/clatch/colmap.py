"""A folder of photos → a COLMAP 3.8 database, as ``clatch colmap`` writes it.

``match_folder(images, database)`` lists the folder, extracts every photo with the structure-from-
motion settings of ``clatch colmap`` (8192 keypoints a photo spread over an 8 x 8 grid, sub-pixel
positions), matches and verifies every pair (or the ``pairs`` given) and writes the database
(cameras, images, keypoints, matches and two-view geometries, as after COLMAP's own matcher): it runs
the Rust library's one folder run (``clatch::colmap::FolderJob``), the code the command-line tool
runs, so with the same options the files are byte-identical to those of
``clatch colmap --images DIR --database DB --no-colmap``. ``clatch.ray.match_folder`` spreads the
same work over a Ray cluster and writes the same bytes.

COLMAP then reconstructs::

    colmap mapper --database_path DB --image_path DIR --output_path WORKSPACE/sparse

With ``verify=False`` the database holds no matches: the match list (``<workspace>/matches.txt``)
goes to COLMAP's own verification first::

    colmap matches_importer --database_path DB --match_list_path WORKSPACE/matches.txt \\
        --match_type raw --SiftMatching.use_gpu 0
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from ._clatch import (
    DEFAULT_GRID,
    DEFAULT_MAX_KEYPOINTS,
    SUBPIXEL_METHODS,
    Extractor,
    ImageFolder,
    Matcher,
    PinholeCamera,
    _extract_photos,
    _FolderJob,
    _FolderWriter,
)
from ._exceptions import InvalidInputError

__all__ = [
    "DEFAULT_GRID",
    "DEFAULT_MAX_KEYPOINTS",
    "SUBPIXEL_METHODS",
    "ImageFolder",
    "MatchFolderResult",
    "Photo",
    "PinholeCamera",
    "extract_photos",
    "match_folder",
]

# From the Rust library (``clatch::colmap``), as ``clatch colmap`` uses them: DEFAULT_GRID, the grid
# keypoints are spread over unless ``extractor`` says otherwise; DEFAULT_MAX_KEYPOINTS, keypoints per
# photo unless ``extractor`` says otherwise (COLMAP's own SIFT budget, 8192, instead of the library's
# general 5000); SUBPIXEL_METHODS, the names of ``subpixel=``: the extractor's FAST-score peak
# (default), whole pixels, or Förstner's corner.

#: A path: ``str`` or ``pathlib.Path`` (any ``os.PathLike[str]``).
PathArg = Union[str, "os.PathLike[str]"]
#: ``progress(stage, done, total)``: stage ``"extract"`` (photos) then ``"match"`` (pairs).
Progress = Callable[[str, int, int], None]
#: A photo of a pair: its index in the folder's name order or its file name.
PhotoArg = Union[int, str]


class Photo(NamedTuple):
    """One photo's share of the database, and its descriptors (row i describes keypoint i)."""

    name: str
    width: int
    height: int
    #: EXIF ``FocalLengthIn35mmFilm``, if the file has it.
    focal_35mm: Optional[int]
    #: ``KEYPOINT_DTYPE``, positions refined as ``subpixel`` says.
    keypoints: np.ndarray
    #: ``uint8``, (N, bits / 8), OpenCV LATCH's byte order.
    descriptors: np.ndarray


@dataclass(frozen=True)
class MatchFolderResult:
    """What ``match_folder`` wrote."""

    database: Path
    #: ``None`` when no match list was written (verified, without ``match_list=True``).
    match_list: Optional[Path]
    images: int
    keypoints: int
    pairs: int
    #: Putative matches over all pairs.
    matches: int
    #: Pairs with at least one match (the pairs in the match list).
    pairs_with_matches: int
    #: Verified (the default): pairs whose two-view geometry was written, those of them with inliers,
    #: and the inlier matches over all pairs; 0 with ``verify=False``.
    pairs_verified: int = 0
    pairs_with_inliers: int = 0
    inliers: int = 0
    #: ``clatch.ray`` only: blocks of pairs; blocks and extraction tasks run again because their
    #: actor died; actors lost; descriptor sets the surviving actors fetched from the object store.
    blocks: int = 0
    blocks_rerun: int = 0
    actors_lost: int = 0
    descriptor_fetches: int = 0
    #: Wall time of each stage in seconds: ``set_up`` (the backend's), ``extraction``, ``decoding``
    #: (summed over the decoding threads), ``matching``, ``verification`` (each without writing),
    #: ``writing``; stages
    #: that ran on Ray's actors are 0.
    stage_seconds: Mapping[str, float] = field(default_factory=dict)


def _result(report: Mapping[str, Any], **ray_counts: int) -> MatchFolderResult:
    """The result of the library's report (``_FolderJob.run``, ``_FolderWriter.finish``)."""
    fields: dict[str, Any] = {**report, **ray_counts}
    fields["database"] = Path(fields["database"])
    if fields["match_list"] is not None:
        fields["match_list"] = Path(fields["match_list"])
    return MatchFolderResult(**fields)


def _invalid(kind: str, message: str) -> InvalidInputError:
    return InvalidInputError(message, kind=kind)


def _extractor_options(extractor: Optional[Mapping[str, Any]]) -> dict[str, Any]:
    """The Extractor keywords of a run: ``clatch colmap``'s grid and budget, then the caller's (the
    sub-pixel method is ``subpixel=``'s, which the library applies)."""
    options = {"grid": DEFAULT_GRID, "max_keypoints": DEFAULT_MAX_KEYPOINTS}
    options.update(extractor or {})
    if "subpixel" in options:
        raise _invalid("InvalidConfig", "give the sub-pixel method as subpixel=, not inside extractor=")
    return options


def _k_input(camera_k: Any) -> Tuple[Optional[str], Optional[str]]:
    """The text of K and the file it was read from: a K file's, or a 3 x 3 array's (``repr`` reads
    back as the same float)."""
    if camera_k is None:
        return None, None
    if isinstance(camera_k, (str, os.PathLike)):
        try:
            return Path(camera_k).read_text(), os.fspath(camera_k)
        except (OSError, UnicodeDecodeError) as e:
            raise _invalid("CameraK", f"cannot read the camera matrix {os.fspath(camera_k)}: {e}") from e
    k = np.asarray(camera_k, dtype=np.float64)
    if k.shape != (3, 3):
        raise _invalid("InvalidCamera", f"camera_k must be a K file or a 3 x 3 matrix, got shape {k.shape}")
    return "\n".join(" ".join(repr(float(v)) for v in row) for row in k), None


def _pair_args(pairs: Optional[Sequence[Sequence[PhotoArg]]]) -> Optional[List[Tuple[PhotoArg, PhotoArg]]]:
    """Each pair as two photo indices or names; the library checks them against the folder."""
    if pairs is None:
        return None

    def photo(p: int, value: Any) -> PhotoArg:
        if isinstance(value, str):
            return value
        if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            if value < 0:
                raise _invalid("PairOutOfRange", f"pair {p}: index {int(value)} is not a photo index")
            return int(value)
        raise _invalid("WrongShape", f"pair {p}: {value!r} is neither an image index nor a name")

    out = []
    for p, pair in enumerate(pairs):
        if isinstance(pair, str) or len(pair) != 2:
            raise _invalid("WrongShape", f"pair {p} must be two image indices or names, got {pair!r}")
        out.append((photo(p, pair[0]), photo(p, pair[1])))
    return out


def _job(
    images: PathArg,
    database: PathArg,
    *,
    backend: str = "cpu",
    pairs: Optional[Sequence[Sequence[PhotoArg]]] = None,
    camera_k: Any = None,
    extractor: Optional[Mapping[str, Any]] = None,
    matcher: Optional[Mapping[str, Any]] = None,
    **settings: Any,
) -> _FolderJob:
    """The Rust library's job (``clatch::colmap::FolderJob``) of ``match_folder``'s keywords, its
    extractor and matcher on ``backend``; ``settings``: ``workspace``, ``subpixel``,
    ``subpixel_radius``, ``max_pixels`` and ``force``, as they are."""
    k_text, k_file = _k_input(camera_k)
    return _FolderJob(
        images,
        database,
        extractor=Extractor(backend, **_extractor_options(extractor)),
        matcher=Matcher(backend, **dict(matcher or {})),
        pairs=_pair_args(pairs),
        camera_k=k_text,
        camera_k_file=k_file,
        **settings,
    )


def extract_photos(
    extractor: Extractor,
    paths: Sequence[PathArg],
    names: Sequence[str],
    *,
    max_pixels: int = 100_000_000,
    corner_radius: Optional[int] = None,
) -> List[Photo]:
    """Reads, detects and describes each photo (``clatch::colmap::extract_photos``); with
    ``corner_radius``, keypoint positions are refined to Förstner's least-squares corner over a
    ``2 r + 1`` window (``subpixel="corner"``). Photos come back in order."""
    raw = _extract_photos(extractor, [os.fspath(p) for p in paths], list(names), max_pixels, corner_radius)
    return [Photo(*photo) for photo in raw]


def match_folder(
    images: PathArg,
    database: PathArg,
    *,
    workspace: Optional[PathArg] = None,
    pairs: Optional[Sequence[Sequence[PhotoArg]]] = None,
    camera_k: Any = None,
    backend: str = "cpu",
    extractor: Optional[Mapping[str, Any]] = None,
    matcher: Optional[Mapping[str, Any]] = None,
    subpixel: str = "score",
    subpixel_radius: int = 3,
    max_pixels: int = 100_000_000,
    force: bool = False,
    verify: bool = True,
    match_list: bool = False,
    progress: Optional[Progress] = None,
) -> MatchFolderResult:
    """Features, matches and verified geometries of a folder of photos into a new COLMAP 3.8 database.

    - ``images``: the folder (its image files, not its subfolders, in name order: ``ImageFolder``).
    - ``database``: the database to create; an existing file is a ``DatabaseError`` unless
      ``force=True``, which replaces it once the new one is complete.
    - ``workspace``: the folder of the match list ``matches.txt``, if one is written (default: the
      database's name + ``-colmap``, beside it), as ``clatch colmap``.
    - ``pairs``: the pairs to match, as ``(i, j)`` indices into the folder's photos or
      ``(name_i, name_j)`` file names, written in that order; default every pair ``i < j``.
    - ``camera_k``: a K file (9 numbers, row-major) or a 3 x 3 matrix shared by every photo; default
      one camera per image size and EXIF focal length (COLMAP's guess without EXIF).
    - ``backend``: ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"auto"``; ``extractor``: ``Extractor``
      keywords on top of ``grid=8``; ``matcher``: ``Matcher`` keywords (ratio 0.8, cross-check).
    - ``subpixel``: ``"score"`` (default), ``"none"`` or ``"corner"`` (over a ``2 subpixel_radius + 1``
      window), ``clatch colmap --subpixel``; descriptors and matches do not depend on it.
    - ``verify`` (default ``True``): verify every pair in clatch (``clatch::verify``, on the CPU,
      COLMAP 3.8's rules with the neighbour-consistency filter) and write the matches and two-view
      geometries into the database, as COLMAP's own matcher would: ``colmap mapper`` then runs
      straight on it. ``False``: the match list alone, for ``colmap matches_importer``
      (``clatch colmap --no-verify``).
    - ``match_list``: write the match list even though the pairs are verified
      (``clatch colmap --match-list``); it is always written with ``verify=False``.
    - ``progress(stage, done, total)``: called as each stage starts (``done = 0``), as photos are
      extracted and as pairs are matched; an exception it raises stops the run.

    The run is the Rust library's (``clatch::colmap::FolderJob::run``), the one ``clatch colmap``
    runs. Bad input raises ``InvalidInputError`` (no image, a bad pair, a bad setting, an output that
    is an input), an unreadable folder or photo ``ImageReadError``, an unwritable output
    ``DatabaseError``; all of them before any work but the photos whose pixels cannot be decoded.
    Nothing is left at the output paths when it fails. Matches are written as each group of pairs is
    done, so memory holds the descriptors, not every match.
    """
    job = _job(
        images,
        database,
        backend=backend,
        workspace=workspace,
        pairs=pairs,
        camera_k=camera_k,
        extractor=extractor,
        matcher=matcher,
        subpixel=subpixel,
        subpixel_radius=subpixel_radius,
        max_pixels=max_pixels,
        force=force,
        verify=verify,
        match_list=match_list,
    )
    return _result(job.run(progress))
