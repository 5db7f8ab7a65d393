#!/usr/bin/env python3
"""Large homography pairs for clatch-eval --data, written as Oxford-layout sequence folders
(img1.pgm ... img6.pgm, H1to2p ... H1to6p; image 1 against the others).

Two kinds (EVALUATION.md, "Keypoint budgets on large images"):

  upscale  An Oxford sequence resized by FACTOR (bicubic): every homography becomes
           S H S^-1, S mapping a pixel centre u to FACTOR * u + (FACTOR - 1) / 2 (the
           half-pixel convention of cv2.resize; pixel centres at integers, as clatch-eval).
  warp     A photo (resized by SCALE first, area interpolation) as image 1 and five fixed
           views of it as images 2-6: rotations, zooms and a perspective tilt about the centre
           (bilinear, black outside, the same size), the homography written exactly.
  near     The same with five views at nearly the photo's own scale (zoom 0.95-1.1, rotations
           up to 20 degrees, tilts up to 0.2): the case where full resolution matters most.

Images are written as 8-bit gray PGM (colour converted by cv2.cvtColor, as the OpenCV script
does), so clatch and OpenCV read the same pixels. Deterministic for one OpenCV build.

  python3 eval/scripts/make_large_pairs.py upscale DATA/oxford_graf 2 OUT/graf_x2
  python3 eval/scripts/make_large_pairs.py warp PHOTO.jpg 0.5 OUT/herzjesu_half
  python3 eval/scripts/make_large_pairs.py near PHOTO.jpg 1 OUT/herzjesu_near

Needs numpy and opencv-python (eval/scripts/requirements.txt).
"""

import math
import os
import sys

import cv2
import numpy as np


def read_gray(path):
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        sys.exit(f"make_large_pairs: cannot read {path}")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img


def write_homography(path, h):
    h = h / h[2, 2]
    with open(path, "w") as f:
        for row in h:
            f.write(" ".join(f"{v:.10e}" for v in row) + "\n")


def read_homography(path):
    with open(path) as f:
        return np.array([[float(v) for v in line.split()] for line in f if line.strip()])


def resize_matrix(factor):
    """Pixel centre u of the original to its place in the image resized by `factor`."""
    t = (factor - 1.0) / 2.0
    return np.array([[factor, 0.0, t], [0.0, factor, t], [0.0, 0.0, 1.0]])


def image_path(seq, k):
    for ext in ("ppm", "pgm", "png", "jpg"):
        p = os.path.join(seq, f"img{k}.{ext}")
        if os.path.exists(p):
            return p
    return None


def upscale(seq, factor, out):
    os.makedirs(out, exist_ok=True)
    s = resize_matrix(factor)
    k = 1
    while (p := image_path(seq, k)) is not None:
        img = read_gray(p)
        big = cv2.resize(img, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC)
        cv2.imwrite(os.path.join(out, f"img{k}.pgm"), big)
        if k > 1:
            h = read_homography(os.path.join(seq, f"H1to{k}p"))
            write_homography(os.path.join(out, f"H1to{k}p"), s @ h @ np.linalg.inv(s))
        k += 1


# The views of `warp`: (rotation in degrees, zoom, perspective tilt: w runs from 1 - tilt to
# 1 + tilt across the width).
VIEWS = [(10.0, 1.0, 0.0), (0.0, 0.8, 0.0), (30.0, 1.25, 0.0), (15.0, 0.9, 0.15), (45.0, 0.6, 0.0)]
# The views of `near`.
VIEWS_NEAR = [(5.0, 1.0, 0.0), (10.0, 1.0, 0.1), (0.0, 1.1, 0.0), (20.0, 0.95, 0.05), (0.0, 1.0, 0.2)]


def view_homography(w, h, degrees, zoom, tilt):
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    a = math.radians(degrees)
    centre = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
    turn = np.array(
        [
            [zoom * math.cos(a), -zoom * math.sin(a), 0.0],
            [zoom * math.sin(a), zoom * math.cos(a), 0.0],
            [0.0, 0.0, 1.0],
        ]
    )
    # w = 1 + tilt * x / cx on the centred coordinates: 1 - tilt at the left edge, 1 + tilt at the right.
    persp = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [tilt / cx, 0.0, 1.0]])
    back = np.array([[1.0, 0.0, cx], [0.0, 1.0, cy], [0.0, 0.0, 1.0]])
    return back @ persp @ turn @ centre


def warp(photo, scale, out, views=VIEWS):
    os.makedirs(out, exist_ok=True)
    img = read_gray(photo)
    if scale != 1.0:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    h, w = img.shape
    cv2.imwrite(os.path.join(out, "img1.pgm"), img)
    for k, (degrees, zoom, tilt) in enumerate(views, start=2):
        hom = view_homography(w, h, degrees, zoom, tilt)
        view = cv2.warpPerspective(
            img, hom, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
        )
        cv2.imwrite(os.path.join(out, f"img{k}.pgm"), view)
        write_homography(os.path.join(out, f"H1to{k}p"), hom)


def main(argv):
    if len(argv) != 5 or argv[1] not in ("upscale", "warp", "near"):
        sys.exit(__doc__)
    kind, source, factor, out = argv[1], argv[2], float(argv[3]), argv[4]
    if kind == "upscale":
        upscale(source, factor, out)
    else:
        warp(source, factor, out, VIEWS if kind == "warp" else VIEWS_NEAR)


if __name__ == "__main__":
    main(sys.argv)
