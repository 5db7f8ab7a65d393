#!/usr/bin/env python3
"""OpenCV's LATCH (on ORB keypoints), ORB and SIFT on the pairs of `clatch-eval`, judged by the same
rule, written in the same format (PREFIX.summary.csv, PREFIX.pr.csv) so that `clatch-eval` merges them.

The rule (EVALUATION.md, eval/src/metrics.rs): a match (a, b) is correct iff
|H(a) - b| <= tolerance; a keypoint of A is in the overlap iff H(a) lies inside B, one of B iff
H^-1(b) lies inside A; matching score = correct / min(overlap A, overlap B); candidates are the 1-NN
matches of A's keypoints that pass the cross-check (if on); at ratio r a candidate is kept iff
float32(d1) < float32(r) * float32(d2); precision = correct kept / kept, recall = correct kept /
correct candidates.

Usage (normally run by `clatch-eval --opencv-python PYTHON`):
    python3 eval/scripts/eval_opencv.py --manifest OUT/pairs.csv --out OUT/opencv [--inlier-px 3]
        [--max-keypoints 5000] [--ratio 0.8 | --no-ratio] [--no-cross-check]
Needs the versions pinned in eval/scripts/requirements.txt.
"""

import argparse
import csv
import sys
from pathlib import Path

import cv2
import numpy as np

TESTED_OPENCV = "4.12.0"
RATIOS = [np.float32((50 + 5 * i) / 100) for i in range(11)]
# The same headers as eval/src/results.rs (a Rust test compares them).
SUMMARY_HEADER = "method,pair,group,param,width_a,height_a,width_b,height_b,keypoints_a,keypoints_b,overlap_a,overlap_b,matches,correct,correct_1nn,precision,matching_score"  # noqa: E501
PR_HEADER = "method,pair,ratio,kept,correct_kept,correct_1nn,precision,recall"


class EvalInputError(Exception):
    """A missing or malformed input file."""


def read_homography(path):
    """Nine numbers (Oxford H1toNp) or OpenCV FileStorage XML; A pixels to B pixels."""
    text = Path(path).read_text()
    if text.lstrip().startswith(("<?xml", "<opencv_storage>")):
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        h = fs.getFirstTopLevelNode().mat()
        fs.release()
    else:
        values = text.split()
        if len(values) != 9:
            raise EvalInputError(f"{path}: expected 9 numbers, found {len(values)}")
        h = np.array([float(v) for v in values]).reshape(3, 3)
    if h is None or h.shape != (3, 3) or not np.all(np.isfinite(h)) or abs(np.linalg.det(h)) < 1e-12:
        raise EvalInputError(f"{path}: not an invertible 3x3 matrix")
    return h.astype(np.float64)


def read_gray(path):
    """8-bit gray as clatch makes it: colour through cvtColor (the same integer weights as clatch's
    luma), 16-bit samples keep their high byte. Not IMREAD_GRAYSCALE: for PNG it lets libpng convert,
    which differs from cvtColor by 1 on about half of graf1.png's pixels, while PPM goes through
    cvtColor, so the same photo would give different figures by file format."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise EvalInputError(f"{path}: cannot read the image")
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise EvalInputError(f"{path}: unsupported image layout {img.shape} {img.dtype}")
    return img


def project(h, pts):
    """h applied to (n, 2) points; rows sent to infinity (|w| < 1e-12) become NaN."""
    if len(pts) == 0:
        return np.zeros((0, 2))
    homogeneous = np.hstack([pts, np.ones((len(pts), 1))]) @ h.T
    w = homogeneous[:, 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = homogeneous[:, :2] / w
    out[np.abs(w[:, 0]) < 1e-12] = np.nan
    return out


def inside(pts, width, height):
    x, y = pts[:, 0], pts[:, 1]
    with np.errstate(invalid="ignore"):
        return (x >= 0) & (x <= width - 1) & (y >= 0) & (y <= height - 1)


def methods(max_keypoints):
    """(label, extract(img) -> (keypoints, descriptors), norm)."""

    def latch(img):
        orb = cv2.ORB_create(nfeatures=max_keypoints)
        latch = cv2.xfeatures2d.LATCH_create(64, True, 3)
        return latch.compute(img, orb.detect(img, None))

    def orb(img):
        return cv2.ORB_create(nfeatures=max_keypoints).detectAndCompute(img, None)

    def sift(img):
        return cv2.SIFT_create(nfeatures=max_keypoints).detectAndCompute(img, None)

    return [
        ("OpenCV LATCH", latch, cv2.NORM_HAMMING),
        ("OpenCV ORB", orb, cv2.NORM_HAMMING),
        ("OpenCV SIFT", sift, cv2.NORM_L2),
    ]


def passes_ratio(d1, d2, ratio):
    return np.float32(d1) < np.float32(ratio) * np.float32(d2)


def evaluate(pair, h, img_a, img_b, method, args):
    label, extract, norm = method
    kps_a, des_a = extract(img_a)
    kps_b, des_b = extract(img_b)
    kps_a, kps_b = list(kps_a or []), list(kps_b or [])
    pts_a = np.array([k.pt for k in kps_a], dtype=np.float64).reshape(-1, 2)
    pts_b = np.array([k.pt for k in kps_b], dtype=np.float64).reshape(-1, 2)
    (ha, wa), (hb, wb) = img_a.shape, img_b.shape
    projected = project(h, pts_a)
    overlap_a = int(inside(projected, wb, hb).sum())
    overlap_b = int(inside(project(np.linalg.inv(h), pts_b), wa, ha).sum())

    candidates = []  # (d1, d2, correct)
    if des_a is not None and des_b is not None and len(kps_a) > 0 and len(kps_b) >= 2:
        matcher = cv2.BFMatcher(norm)
        knn = matcher.knnMatch(des_a, des_b, k=2)
        reverse = matcher.match(des_b, des_a) if args.cross_check else None
        for neighbours in knn:
            if len(neighbours) < 2:
                continue
            best, second = neighbours
            if reverse is not None and reverse[best.trainIdx].trainIdx != best.queryIdx:
                continue
            error = np.hypot(*(projected[best.queryIdx] - pts_b[best.trainIdx]))
            candidates.append((best.distance, second.distance, bool(error <= args.inlier_px)))

    if args.ratio is None:
        configured = candidates
    else:
        configured = [c for c in candidates if passes_ratio(c[0], c[1], args.ratio)]
    correct = sum(c[2] for c in configured)
    correct_1nn = sum(c[2] for c in candidates)
    curve = []
    for r in RATIOS:
        kept = [c for c in candidates if passes_ratio(c[0], c[1], r)]
        curve.append((r, len(kept), sum(c[2] for c in kept)))

    def frac(num, den):
        return f"{num / den:.4f}" if den > 0 else ""

    summary = [
        label, pair["pair"], pair["group"], pair["param"], wa, ha, wb, hb, len(kps_a), len(kps_b),
        overlap_a, overlap_b, len(configured), correct, correct_1nn,
        frac(correct, len(configured)), frac(correct, min(overlap_a, overlap_b)),
    ]
    pr = [
        [label, pair["pair"], f"{float(r):.2f}", kept, correct_kept, correct_1nn,
         frac(correct_kept, kept), frac(correct_kept, correct_1nn)]
        for r, kept, correct_kept in curve
    ]
    return summary, pr


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--manifest", required=True, help="pairs.csv written by clatch-eval")
    parser.add_argument("--out", required=True, help="output prefix: PREFIX.summary.csv, PREFIX.pr.csv")
    parser.add_argument("--inlier-px", type=float, default=3.0)
    parser.add_argument("--max-keypoints", type=int, default=5000)
    parser.add_argument("--ratio", type=float, default=0.8)
    parser.add_argument("--no-ratio", action="store_true")
    parser.add_argument("--no-cross-check", dest="cross_check", action="store_false")
    args = parser.parse_args()
    if args.no_ratio:
        args.ratio = None
    if cv2.__version__ != TESTED_OPENCV:
        print(f"eval_opencv: warning: OpenCV {cv2.__version__}, figures were checked with "
              f"{TESTED_OPENCV}", file=sys.stderr)
    cv2.setRNGSeed(0)

    try:
        with open(args.manifest, newline="") as f:
            pairs = list(csv.DictReader(f))
        if not pairs or set(pairs[0]) != {"pair", "group", "param", "image_a", "image_b", "homography"}:
            raise EvalInputError(f"{args.manifest}: not a clatch-eval manifest")
        summaries, prs = [], []
        for i, pair in enumerate(pairs):
            h = read_homography(pair["homography"])
            img_a, img_b = read_gray(pair["image_a"]), read_gray(pair["image_b"])
            for method in methods(args.max_keypoints):
                summary, pr = evaluate(pair, h, img_a, img_b, method, args)
                summaries.append(summary)
                prs.extend(pr)
            print(f"eval_opencv: {i + 1}/{len(pairs)} {pair['pair']}", file=sys.stderr)
    except (EvalInputError, OSError) as e:
        sys.exit(f"eval_opencv: error: {e}")

    for suffix, header, rows in [(".summary.csv", SUMMARY_HEADER, summaries), (".pr.csv", PR_HEADER, prs)]:
        with open(args.out + suffix, "w", newline="") as f:
            f.write(header + "\n")
            csv.writer(f, lineterminator="\n").writerows(rows)


if __name__ == "__main__":
    main()
