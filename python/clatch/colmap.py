"""A folder of photos → a COLMAP 3.8 database and match list, as ``clatch colmap`` writes them.

``match_folder(images, database)`` lists the folder, extracts every photo with the structure-from-
motion settings of ``clatch colmap`` (8192 keypoints a photo spread over an 8 x 8 grid, sub-pixel
positions), matches every pair (or the ``pairs`` given) and writes the database (cameras, images, keypoints) and
the match list (``<workspace>/matches.txt``) with the Rust library's one writer
(``clatch::colmap::FolderWriter``), the code the command-line tool runs: with the same options the
files are byte-identical to those of ``clatch colmap --images DIR --database DB --no-colmap``.
``clatch.ray.match_folder`` spreads the same work over a Ray cluster and writes the same bytes.

COLMAP then verifies the matches and reconstructs::

    colmap matches_importer --database_path DB --match_list_path WORKSPACE/matches.txt \\
        --match_type raw --SiftMatching.use_gpu 0
    colmap mapper --database_path DB --image_path DIR --output_path WORKSPACE/sparse
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from ._clatch import (
    Extractor,
    ImageFolder,
    Matcher,
    PinholeCamera,
    _extract_photos,
    _FolderWriter,
)
from ._exceptions import DatabaseError, InvalidInputError

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

#: The grid keypoints are spread over unless ``extractor`` says otherwise (``clatch colmap``'s).
DEFAULT_GRID = 8
#: Keypoints per photo unless ``extractor`` says otherwise (``clatch colmap``'s: COLMAP's own SIFT
#: budget, 8192, instead of the library's general 5000).
DEFAULT_MAX_KEYPOINTS = 8192
#: ``subpixel=``: the extractor's FAST-score peak (default), whole pixels, or Förstner's corner.
SUBPIXEL_METHODS = ("score", "none", "corner")
#: Pairs matched per call in the single-process run (the match list is written as they finish).
_PAIR_CHUNK = 256
#: Photos extracted per call (``progress`` is called after each).
_PHOTO_CHUNK = 32

#: A path: ``str`` or ``pathlib.Path`` (any ``os.PathLike[str]``).
PathArg = Union[str, "os.PathLike[str]"]
#: ``progress(stage, done, total)``: stage ``"extract"`` (photos) then ``"match"`` (pairs).
Progress = Callable[[str, int, int], None]


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
    match_list: Path
    images: int
    keypoints: int
    pairs: int
    #: Putative matches over all pairs.
    matches: int
    #: Pairs with at least one match (the pairs in the match list).
    pairs_with_matches: int
    #: ``clatch.ray`` only: blocks of pairs; blocks and extraction tasks run again because their
    #: actor died; actors lost; descriptor sets the surviving actors fetched from the object store.
    blocks: int = 0
    blocks_rerun: int = 0
    actors_lost: int = 0
    descriptor_fetches: int = 0


def _extractor_options(extractor: Optional[Mapping[str, Any]], subpixel: str) -> Dict[str, Any]:
    """The Extractor keywords of a run: ``clatch colmap``'s grid and budget, then the caller's, then the
    detector's half of ``subpixel``."""
    if subpixel not in SUBPIXEL_METHODS:
        raise _invalid("InvalidConfig", f"subpixel must be one of {SUBPIXEL_METHODS}, got {subpixel!r}")
    options: Dict[str, Any] = {"grid": DEFAULT_GRID, "max_keypoints": DEFAULT_MAX_KEYPOINTS}
    options.update(extractor or {})
    if "subpixel" in options:
        raise _invalid(
            "InvalidConfig", "give the sub-pixel method as subpixel=, not inside extractor="
        )
    options["subpixel"] = "score" if subpixel == "score" else "none"
    return options


def _invalid(kind: str, message: str) -> InvalidInputError:
    error = InvalidInputError(message)
    error.kind = kind
    return error


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


def match_block(
    matcher: Matcher, descriptors: Mapping[int, np.ndarray], pairs: Sequence[Tuple[int, int]]
) -> List[np.ndarray]:
    """Matches of each pair, with only the descriptor sets the pairs name handed to the library."""
    used = sorted({i for pair in pairs for i in pair})
    local = {image: k for k, image in enumerate(used)}
    sets = [descriptors[image] for image in used]
    return list(matcher.match_pairs(sets, [(local[i], local[j]) for i, j in pairs]))


def _chunks(items: Sequence[Any], size: int) -> Iterator[Sequence[Any]]:
    for start in range(0, len(items), size):
        yield items[start : start + size]


class _Plan:
    """Everything checked before any work: the photos, the camera, the pairs, the outputs."""

    def __init__(
        self,
        images: PathArg,
        database: PathArg,
        *,
        workspace: Optional[PathArg],
        pairs: Optional[Sequence[Sequence[Union[int, str]]]],
        camera_k: Any,
        extractor: Optional[Mapping[str, Any]],
        matcher: Optional[Mapping[str, Any]],
        subpixel: str,
        subpixel_radius: int,
        max_pixels: int,
        force: bool,
    ) -> None:
        self.extractor_options = _extractor_options(extractor, subpixel)
        self.matcher_options = dict(matcher or {})
        if not isinstance(subpixel_radius, int) or not 1 <= subpixel_radius <= 16:
            raise _invalid("InvalidConfig", f"subpixel_radius must be in 1..=16, got {subpixel_radius!r}")
        self.corner_radius = subpixel_radius if subpixel == "corner" else None
        self.max_pixels = max_pixels
        self.folder = ImageFolder(images, max_pixels=max_pixels)
        self.camera = None if camera_k is None else self.folder.shared_camera(_k_text(camera_k))
        self.pairs = _pairs(pairs, self.folder.names)
        self.database = Path(database)
        self.workspace = Path(workspace) if workspace is not None else _default_workspace(self.database)
        self.match_list = self.workspace / "matches.txt"
        if self.database.exists() and not force:
            error = DatabaseError(
                f"COLMAP database {self.database} already exists; remove it, choose another path "
                "or pass force=True"
            )
            error.kind = "DatabaseExists"
            raise error
        if self.database.is_dir() or self.match_list.is_dir():
            raise _invalid("OutputPath", f"{self.database} or {self.match_list} is a folder")
        if self.database.resolve() in {p.resolve() for p in self.folder.paths}:
            raise _invalid("OutputClash", f"the database {self.database} is one of the images")

    def open_writer(self) -> "_Staged":
        return _Staged(self)


def _default_workspace(database: Path) -> Path:
    """``out.db`` → ``out-colmap/`` beside it (``clatch colmap``'s default)."""
    return database.with_name(f"{database.stem}-colmap")


def _k_text(camera_k: Any) -> str:
    """A K file's text, or the text of a 3 x 3 array (``repr`` reads back as the same float)."""
    if isinstance(camera_k, (str, os.PathLike)):
        try:
            return Path(camera_k).read_text()
        except (OSError, UnicodeDecodeError) as e:
            raise _invalid("CameraK", f"cannot read the camera matrix {os.fspath(camera_k)}: {e}") from e
    k = np.asarray(camera_k, dtype=np.float64)
    if k.shape != (3, 3):
        raise _invalid("InvalidCamera", f"camera_k must be a K file or a 3 x 3 matrix, got shape {k.shape}")
    return "\n".join(" ".join(repr(float(v)) for v in row) for row in k)


def _pairs(
    pairs: Optional[Sequence[Sequence[Union[int, str]]]], names: Sequence[str]
) -> List[Tuple[int, int]]:
    """Every pair ``(i, j)``, ``i < j``, in order, or the pairs given (indices into the folder's
    photos or their names), checked: in range, two different photos, each pair once."""
    n = len(names)
    if pairs is None:
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    index = {name: i for i, name in enumerate(names)}

    def photo(p: int, value: Any) -> int:
        if isinstance(value, str):
            if value not in index:
                raise _invalid("PairOutOfRange", f"pair {p}: {value!r} is not an image of the folder")
            return index[value]
        if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            if not 0 <= int(value) < n:
                raise _invalid("PairOutOfRange", f"pair {p}: index {int(value)} is not one of {n} photos")
            return int(value)
        raise _invalid("WrongShape", f"pair {p}: {value!r} is neither an image index nor a name")

    out: List[Tuple[int, int]] = []
    seen = set()
    for p, pair in enumerate(pairs):
        if isinstance(pair, str) or len(pair) != 2:
            raise _invalid("WrongShape", f"pair {p} must be two image indices or names, got {pair!r}")
        i, j = photo(p, pair[0]), photo(p, pair[1])
        if i == j:
            raise _invalid("SamePair", f"pair {p}: {names[i]} with itself")
        key = (min(i, j), max(i, j))
        if key in seen:
            raise _invalid("DuplicatePair", f"pair {p}: {names[i]} and {names[j]} are listed twice")
        seen.add(key)
        out.append((i, j))
    return out


class _Staged:
    """The writer over temporary files beside the outputs, renamed into place by ``commit`` only
    when everything was written; removed on any error."""

    def __init__(self, plan: _Plan) -> None:
        self.plan = plan
        plan.workspace.mkdir(parents=True, exist_ok=True)
        self.temps: List[Tuple[Path, Path]] = []
        database = self._temp(plan.database)
        match_list = self._temp(plan.match_list)
        database.unlink()  # the library creates the database file itself and never opens one
        self.writer = _FolderWriter(database, match_list, plan.camera)
        self.keypoint_counts: List[int] = []
        self.pairs_written = 0
        self.matches = 0
        self.pairs_with_matches = 0

    def _temp(self, path: Path) -> Path:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".clatch-tmp", dir=path.parent)
        os.close(fd)
        self.temps.append((Path(name), path))
        return Path(name)

    def add_photo(self, photo: Photo) -> None:
        self.writer.add_photo(photo.name, photo.width, photo.height, photo.focal_35mm, photo.keypoints)
        self.keypoint_counts.append(len(photo.keypoints))

    def add_matches(self, i: int, j: int, matches: np.ndarray) -> None:
        self.writer.add_matches(i, j, matches)
        self.pairs_written += 1
        self.matches += len(matches)
        self.pairs_with_matches += len(matches) > 0

    def commit(self, **ray_counts: int) -> MatchFolderResult:
        self.writer.finish()
        for temp, path in self.temps:
            os.replace(temp, path)
        self.temps = []
        return MatchFolderResult(
            database=self.plan.database,
            match_list=self.plan.match_list,
            images=len(self.keypoint_counts),
            keypoints=sum(self.keypoint_counts),
            pairs=self.pairs_written,
            matches=self.matches,
            pairs_with_matches=self.pairs_with_matches,
            **ray_counts,
        )

    def discard(self) -> None:
        self.writer.close()
        for temp, _ in self.temps:
            for leftover in (temp, temp.with_name(temp.name + "-journal")):
                try:
                    leftover.unlink()
                except FileNotFoundError:
                    pass
        self.temps = []


def match_folder(
    images: PathArg,
    database: PathArg,
    *,
    workspace: Optional[PathArg] = None,
    pairs: Optional[Sequence[Sequence[Union[int, str]]]] = None,
    camera_k: Any = None,
    backend: str = "cpu",
    extractor: Optional[Mapping[str, Any]] = None,
    matcher: Optional[Mapping[str, Any]] = None,
    subpixel: str = "score",
    subpixel_radius: int = 3,
    max_pixels: int = 100_000_000,
    force: bool = False,
    progress: Optional[Progress] = None,
) -> MatchFolderResult:
    """Features and matches of a folder of photos into a new COLMAP 3.8 database and match list.

    - ``images``: the folder (its image files, not its subfolders, in name order: ``ImageFolder``).
    - ``database``: the database to create; an existing file is a ``DatabaseError`` unless
      ``force=True``, which replaces it once the new one is complete.
    - ``workspace``: the folder of the match list ``matches.txt`` (default: the database's name +
      ``-colmap``, beside it), as ``clatch colmap``.
    - ``pairs``: the pairs to match, as ``(i, j)`` indices into the folder's photos or
      ``(name_i, name_j)`` file names, written in that order; default every pair ``i < j``.
    - ``camera_k``: a K file (9 numbers, row-major) or a 3 x 3 matrix shared by every photo; default
      one camera per image size and EXIF focal length (COLMAP's guess without EXIF).
    - ``backend``: ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"auto"``; ``extractor``: ``Extractor``
      keywords on top of ``grid=8``; ``matcher``: ``Matcher`` keywords (ratio 0.8, cross-check).
    - ``subpixel``: ``"score"`` (default), ``"none"`` or ``"corner"`` (over a ``2 subpixel_radius + 1``
      window), ``clatch colmap --subpixel``; descriptors and matches do not depend on it.
    - ``progress(stage, done, total)``: called as photos are extracted and pairs matched.

    Bad input raises ``InvalidInputError`` (no image, a bad pair, a bad setting), an unreadable
    folder or photo ``ImageReadError``, an unwritable output ``DatabaseError``. Nothing is left at
    the output paths when it fails. Matches are written as each chunk of pairs is done, so memory
    holds the descriptors, not every match.
    """
    plan = _Plan(
        images,
        database,
        workspace=workspace,
        pairs=pairs,
        camera_k=camera_k,
        extractor=extractor,
        matcher=matcher,
        subpixel=subpixel,
        subpixel_radius=subpixel_radius,
        max_pixels=max_pixels,
        force=force,
    )
    extract = Extractor(backend, **plan.extractor_options)
    match = Matcher(backend, **plan.matcher_options)
    folder = plan.folder
    total = len(folder)
    staged = plan.open_writer()
    try:
        descriptors: Dict[int, np.ndarray] = {}
        for start in range(0, total, _PHOTO_CHUNK):
            stop = min(total, start + _PHOTO_CHUNK)
            chunk = extract_photos(
                extract,
                folder.paths[start:stop],
                folder.names[start:stop],
                max_pixels=max_pixels,
                corner_radius=plan.corner_radius,
            )
            for k, photo in enumerate(chunk):
                staged.add_photo(photo)
                descriptors[start + k] = photo.descriptors
            if progress is not None:
                progress("extract", stop, total)
        done = 0
        for chunk_pairs in _chunks(plan.pairs, _PAIR_CHUNK):
            for (i, j), found in zip(chunk_pairs, match_block(match, descriptors, chunk_pairs)):
                staged.add_matches(i, j, found)
            done += len(chunk_pairs)
            if progress is not None:
                progress("match", done, len(plan.pairs))
        return staged.commit()
    except BaseException:
        staged.discard()
        raise

