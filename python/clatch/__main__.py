"""``python -m clatch``: the command-line tool's basic use, from the Python package.

    python -m clatch extract photo.jpg -o photo        # photo.keypoints.csv, photo.descriptors.npy
    python -m clatch extract a.jpg b.jpg -o features   # features/a.*, features/b.*
    python -m clatch match a.jpg b.jpg -o matches.csv  # query,train,distance; the count printed
    python -m clatch colmap --images photos/ --database out.db   # as clatch colmap --no-colmap

The files are those ``clatch extract`` writes (the keypoints CSV with the same columns, the
descriptors ``.npy`` in OpenCV LATCH's byte order), with the same numbers for the same settings. A
clatch error is printed as ``error: ...`` with exit status 1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import List, Optional, Sequence

import numpy as np

from . import Extractor, Matcher, imread
from ._exceptions import ClatchError

KEYPOINT_COLUMNS = ("x", "y", "size", "angle", "response", "octave")


def _extractor_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backend", default="auto", help='"cpu", "cuda", "cuda:N" or "auto" (default)')
    parser.add_argument("--max-pixels", type=int, default=100_000_000, help="refuse larger images (header)")
    parser.add_argument("--threshold", type=int, help="FAST threshold, 1..=254 (default 20)")
    parser.add_argument("--max-keypoints", type=int, help="keypoints kept per image (default 5000)")
    parser.add_argument("--grid", type=int, help="spread keypoints over a grid x grid division")
    parser.add_argument("--bits", type=int, help="descriptor width, a multiple of 8 up to 512")
    parser.add_argument("--single-scale", action="store_true", help="full resolution only")


def _extractor(args: argparse.Namespace) -> Extractor:
    keywords = {k: getattr(args, k) for k in ("threshold", "max_keypoints", "grid", "bits") if getattr(args, k) is not None}
    return Extractor(args.backend, single_scale=args.single_scale, **keywords)


def _write_features(prefix: Path, keypoints: np.ndarray, descriptors: np.ndarray) -> None:
    lines = [",".join(KEYPOINT_COLUMNS)]
    for kp in keypoints:
        lines.append(",".join(str(kp[c]) for c in KEYPOINT_COLUMNS))
    Path(f"{prefix}.keypoints.csv").write_text("\n".join(lines) + "\n")
    np.save(f"{prefix}.descriptors.npy", descriptors)


def extract(args: argparse.Namespace) -> int:
    extractor = _extractor(args)
    images = [Path(p) for p in args.images]
    out = Path(args.output)
    if len(images) > 1:
        out.mkdir(parents=True, exist_ok=True)
    for image in images:
        keypoints, descriptors = extractor.detect_and_describe(imread(image, args.max_pixels))
        prefix = out / image.stem if len(images) > 1 else out
        _write_features(prefix, keypoints, descriptors)
        print(f"{image}: {len(keypoints)} keypoints -> {prefix}.keypoints.csv, {prefix}.descriptors.npy")
    return 0


def match(args: argparse.Namespace) -> int:
    extractor = _extractor(args)
    ratio = None if args.ratio <= 0 else args.ratio
    matcher = Matcher(extractor.backend, ratio=ratio, cross_check=not args.no_cross_check, max_distance=args.max_distance)
    (kp_a, desc_a), (kp_b, desc_b) = (extractor.detect_and_describe(imread(p, args.max_pixels)) for p in (args.a, args.b))
    matches = matcher.match(desc_a, desc_b)
    print(f"{len(kp_a)} and {len(kp_b)} keypoints, {len(matches)} matches")
    if args.output:
        rows = ["query,train,distance"] + [f"{m['query']},{m['train']},{m['distance']}" for m in matches]
        Path(args.output).write_text("\n".join(rows) + "\n")
    return 0


def colmap(args: argparse.Namespace) -> int:
    from . import colmap as colmap_module

    extractor = {k: getattr(args, k) for k in ("threshold", "max_keypoints", "grid", "bits") if getattr(args, k) is not None}
    result = colmap_module.match_folder(
        args.images,
        args.database,
        workspace=args.workspace,
        camera_k=args.camera_k,
        backend=args.backend,
        extractor=extractor,
        matcher={"ratio": args.ratio},
        max_pixels=args.max_pixels,
        force=args.force,
        verify=not args.no_verify,
        match_list=args.match_list,
    )
    verified = "" if args.no_verify else f", {result.inliers} verified in {result.pairs_with_inliers} pairs"
    outputs = ", ".join(str(p) for p in (result.database, result.match_list) if p is not None)
    print(
        f"{result.images} photos, {result.keypoints} keypoints, {result.pairs} pairs, {result.matches} matches"
        f"{verified} -> {outputs}"
    )
    return 0


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="python -m clatch", description=__doc__.split("\n\n")[0])
    commands = top.add_subparsers(dest="command", required=True)
    p = commands.add_parser("extract", help="detect and describe images; write keypoints CSV and descriptors .npy")
    p.add_argument("images", nargs="+")
    p.add_argument("-o", "--output", required=True, help="output prefix (with several images: a folder)")
    _extractor_options(p)
    p.set_defaults(run=extract)
    p = commands.add_parser("match", help="match two images; print the count, write the matches as CSV")
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("-o", "--output", help="matches CSV (query,train,distance)")
    p.add_argument("--ratio", type=float, default=0.8, help="Lowe's ratio (0 or less: none)")
    p.add_argument("--no-cross-check", action="store_true")
    p.add_argument("--max-distance", type=int)
    _extractor_options(p)
    p.set_defaults(run=match)
    p = commands.add_parser("colmap", help="a folder of photos -> a COLMAP database, pairs verified")
    p.add_argument("--images", required=True)
    p.add_argument("--database", required=True)
    p.add_argument("--workspace")
    p.add_argument("--camera-k", help="a K file: 9 numbers, row-major")
    p.add_argument("--force", action="store_true", help="replace an existing database")
    verification = p.add_mutually_exclusive_group()
    verification.add_argument("--verify", action="store_true", help="accepted for compatibility: verification is the default")
    verification.add_argument(
        "--no-verify",
        action="store_true",
        help="write the match list for colmap matches_importer instead of verifying (clatch colmap --no-verify)",
    )
    p.add_argument("--match-list", action="store_true", help="write the match list too when verifying (clatch colmap --match-list)")
    p.add_argument("--ratio", type=float, default=0.8)
    _extractor_options(p)
    p.set_defaults(run=colmap)
    return top


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parser().parse_args(argv)
    try:
        status: int = args.run(args)
        return status
    except ClatchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
