#!/usr/bin/env python3
"""OpenCV's LATCH descriptors for the comparison test (tests/opencv_latch.rs).

Usage: latch_reference.py JOBS
JOBS is a text file, one job per line, paths relative to its folder:
    IMAGE KEYPOINTS OUT BYTES ROTATION HALF_SSD_SIZE SIGMA
IMAGE is an 8-bit grey PGM; KEYPOINTS holds little-endian float32 triples (x, y, angle in degrees).
Each job writes OUT.idx (int32: the input index of every keypoint cv2 kept, in its output order) and
OUT.desc (uint8: one row of BYTES per kept keypoint, cv2's own layout), computed by
cv2.xfeatures2d.LATCH_create(BYTES, ROTATION == 1, HALF_SSD_SIZE, SIGMA).compute.
The first line printed is the cv2 version.
"""
import os
import sys

import cv2
import numpy as np


def run_job(folder, fields):
    image_path, keypoints_path, out, nbytes, rotation, half_ssd, sigma = fields
    image = cv2.imread(os.path.join(folder, image_path), cv2.IMREAD_UNCHANGED)
    if image is None or image.ndim != 2 or image.dtype != np.uint8:
        raise SystemExit(f"{image_path}: not an 8-bit grey image")
    triples = np.fromfile(os.path.join(folder, keypoints_path), dtype="<f4").reshape(-1, 3)
    # float(np.float32) is exact, so cv2 stores the very same float32 values. The class id carries
    # the input index through LATCH's border filter, which drops keypoints.
    keypoints = [
        cv2.KeyPoint(float(x), float(y), 7.0, float(angle), 0.0, 0, i)
        for i, (x, y, angle) in enumerate(triples)
    ]
    latch = cv2.xfeatures2d.LATCH_create(int(nbytes), rotation == "1", int(half_ssd), float(sigma))
    kept, descriptors = latch.compute(image, keypoints)
    if descriptors is None:
        descriptors = np.zeros((0, int(nbytes)), dtype=np.uint8)
    np.asarray([kp.class_id for kp in kept], dtype="<i4").tofile(os.path.join(folder, out + ".idx"))
    np.ascontiguousarray(descriptors, dtype=np.uint8).tofile(os.path.join(folder, out + ".desc"))


def main():
    jobs = sys.argv[1]
    folder = os.path.dirname(os.path.abspath(jobs))
    print(cv2.__version__, flush=True)
    with open(jobs) as f:
        for line in f:
            if line.strip():
                run_job(folder, line.split())


if __name__ == "__main__":
    main()
