#!/usr/bin/env python3
"""Camera-centre and rotation error of a COLMAP model against Strecha-style ground-truth cameras.

    python3 eval/scripts/colmap_eval.py MODEL_DIR GT_DIR

MODEL_DIR is a COLMAP model (sparse/N, binary or text; converted with `colmap model_converter
--output_type TXT` when binary). GT_DIR holds one `NAME.camera` per image (Strecha et al. CVPR 2008
format, as in data/strecha_herzjesu_p8/gt_dense_cameras: K rows, a distortion row, R camera-to-world
rows, the camera centre t in metres, `width height`). The model's camera centres are aligned to the
ground truth's by the least-squares similarity (Umeyama 1991); errors are measured after it. The
relative rotation error (each pair's rotation against the ground truth's) needs no alignment.
Needs numpy only.
"""
import os
import subprocess
import sys
import tempfile

import numpy as np


def quat_to_rot(qw, qx, qy, qz):
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ])


def read_model_images(model_dir):
    """{name: (R camera-to-world, centre)} of the registered images."""
    with tempfile.TemporaryDirectory() as txt:
        if os.path.exists(os.path.join(model_dir, "images.txt")):
            path = os.path.join(model_dir, "images.txt")
        else:
            subprocess.run(["colmap", "model_converter", "--input_path", model_dir,
                            "--output_path", txt, "--output_type", "TXT"],
                           check=True, capture_output=True)
            path = os.path.join(txt, "images.txt")
        lines = [l for l in open(path) if not l.startswith("#")]
    cams = {}
    for line in lines[0::2]:  # every other line is the image's 2D points
        f = line.split()
        if len(f) < 10:
            continue
        r_wc = quat_to_rot(*map(float, f[1:5]))  # world to camera
        t = np.array(list(map(float, f[5:8])))
        cams[f[9]] = (r_wc.T, -r_wc.T @ t)
    return cams


def read_gt(gt_dir):
    gt = {}
    for fname in sorted(os.listdir(gt_dir)):
        if not fname.endswith(".camera"):
            continue
        rows = [list(map(float, l.split())) for l in open(os.path.join(gt_dir, fname)) if l.strip()]
        gt[fname[: -len(".camera")]] = (np.array(rows[4:7]), np.array(rows[7]))
    return gt


def umeyama(src, dst):
    """s, R, t minimising sum |dst - (s R src + t)|^2."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    u, d, vt = np.linalg.svd(b.T @ a / len(src))
    s_fix = np.diag([1, 1, np.sign(np.linalg.det(u @ vt))])
    r = u @ s_fix @ vt
    scale = np.trace(np.diag(d) @ s_fix) / (a * a).sum(1).mean()
    return scale, r, mu_d - scale * r @ mu_s


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    model, gt = read_model_images(sys.argv[1]), read_gt(sys.argv[2])
    names = sorted(set(model) & set(gt))
    if len(names) < 3:
        sys.exit(f"only {len(names)} registered images have ground truth: need 3 to align")
    src = np.array([model[n][1] for n in names])
    dst = np.array([gt[n][1] for n in names])
    s, r, t = umeyama(src, dst)
    centre_err = np.linalg.norm(dst - (s * src @ r.T + t), axis=1)
    rot_err = []
    for n in names:
        rel = gt[n][0].T @ r @ model[n][0]
        rot_err.append(np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))))
    rot_err = np.array(rot_err)
    # Alignment-free: the rotation between every two cameras against the ground truth's.
    rel_err = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            rel = (gt[a][0].T @ gt[b][0]).T @ (model[a][0].T @ model[b][0])
            rel_err.append(np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))))
    rel_err = np.array(rel_err)
    print(f"registered with ground truth: {len(names)} of {len(gt)}")
    print(f"camera centre error: mean {100 * centre_err.mean():.2f} cm, max {100 * centre_err.max():.2f} cm")
    print(f"rotation error: mean {rot_err.mean():.3f} deg, max {rot_err.max():.3f} deg")
    print(f"relative rotation error (every pair, no alignment): mean {rel_err.mean():.3f} deg, "
          f"max {rel_err.max():.3f} deg")
    for n, c, a in zip(names, centre_err, rot_err):
        print(f"  {n}: {100 * c:.2f} cm, {a:.3f} deg")


if __name__ == "__main__":
    main()
