#!/usr/bin/env python3
"""Reprojection error of a COLMAP model's observations, grouped by the keypoint's scale in the database.

    python3 eval/scripts/colmap_level_errors.py DATABASE MODEL_DIR

`clatch colmap` writes each keypoint's scale as size / 2, with size = keypoint size x factor^level on a
pyramid, so the distinct scales are the pyramid levels (OpenCV ORB's sizes likewise). Per scale: the
observations in the model, their mean and median reprojection error (PINHOLE cameras only), and the
share of that scale among the image keypoints. The mean here is per observation; `colmap
model_analyzer`'s mean is per 3-D point first, so the two differ a little. Needs numpy and `colmap`
(for `model_converter` when the model is binary).
"""
import os
import sqlite3
import subprocess
import sys
import tempfile
from collections import defaultdict

import numpy as np


def quat_to_rot(qw, qx, qy, qz):
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ])


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    db_path, model = sys.argv[1:]
    db = sqlite3.connect(db_path)
    scales = {}
    for image_id, rows, cols, data in db.execute("SELECT image_id, rows, cols, data FROM keypoints"):
        kp = np.frombuffer(data, np.float32).reshape(rows, cols)
        scales[image_id] = np.round(kp[:, 2], 2) if cols >= 3 else np.zeros(rows, np.float32)
    names = dict(db.execute("SELECT name, image_id FROM images"))
    with tempfile.TemporaryDirectory() as txt:
        subprocess.run(["colmap", "model_converter", "--input_path", model, "--output_path", txt,
                        "--output_type", "TXT"], check=True, capture_output=True)
        cams = {}
        for line in open(os.path.join(txt, "cameras.txt")):
            if line.startswith("#"):
                continue
            f = line.split()
            if f[1] != "PINHOLE":
                sys.exit(f"camera model {f[1]}: only PINHOLE is handled")
            cams[int(f[0])] = list(map(float, f[4:8]))
        pts = {}
        for line in open(os.path.join(txt, "points3D.txt")):
            if line.startswith("#"):
                continue
            f = line.split()
            pts[int(f[0])] = np.array(list(map(float, f[1:4])))
        lines = [l for l in open(os.path.join(txt, "images.txt")) if not l.startswith("#")]
    errors = defaultdict(list)
    per_point = defaultdict(list)
    for head, obs in zip(lines[0::2], lines[1::2]):
        f = head.split()
        r = quat_to_rot(*map(float, f[1:5]))
        t = np.array(list(map(float, f[5:8])))
        fx, fy, cx, cy = cams[int(f[8])]
        image_scales = scales[names[f[9]]]
        o = obs.split()
        for idx in range(len(o) // 3):
            pid = int(o[3 * idx + 2])
            if pid < 0:
                continue
            x, y = float(o[3 * idx]), float(o[3 * idx + 1])
            pc = r @ pts[pid] + t
            u, v = fx * pc[0] / pc[2] + cx, fy * pc[1] / pc[2] + cy
            e = np.hypot(u - x, v - y)
            errors[float(image_scales[idx])].append(e)
            per_point[pid].append(e)
    all_scales = np.concatenate(list(scales.values()))
    total = sum(len(e) for e in errors.values())
    everything = np.concatenate([np.array(e) for e in errors.values()])
    point_mean = np.mean([np.mean(e) for e in per_point.values()])
    print(f"observations {total}, mean {everything.mean():.3f} px, median {np.median(everything):.3f} px; "
          f"mean of the points' means {point_mean:.3f} px (model_analyzer's figure)")
    print("scale  keypoints%  observations  obs%  mean px  median px")
    for s in sorted(errors):
        e = np.array(errors[s])
        print(f"{s:6.2f}  {100 * np.mean(all_scales == s):9.1f}  {len(e):12d}  {100 * len(e) / total:4.1f}"
              f"  {e.mean():7.3f}  {np.median(e):9.3f}")


if __name__ == "__main__":
    main()
