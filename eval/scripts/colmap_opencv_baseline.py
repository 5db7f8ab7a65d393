#!/usr/bin/env python3
"""OpenCV ORB keypoints + OpenCV LATCH descriptors, handed to COLMAP 3.8 exactly as `clatch colmap`
hands its own: the baseline of EVALUATION.md's COLMAP table.

    python3 eval/scripts/colmap_opencv_baseline.py IMAGES_DIR K_FILE OUT_DIR [--features N] [--ratio 0.8]
        [--descriptor latch|orb]

Per image: ORB (nfeatures=N, OpenCV defaults otherwise: 8 levels, scale 1.2, FAST 20), LATCH (OpenCV
defaults: 32 bytes, rotation invariance, half_ssd_size 3) on the gray image, or ORB's own 256-bit
descriptor with `--descriptor orb`. Every pair: brute-force
Hamming 2-NN, ratio test and mutual cross-check (as clatch). Then a COLMAP 3.8 database (made by
`colmap database_creator`; PINHOLE with K, keypoints with +0.5), the match list,
`colmap matches_importer --match_type raw`, `colmap mapper`, `colmap model_analyzer`, each timed
(wall time, and the CPU time of this process, all threads, for extract and match).
Needs opencv-contrib-python-headless and numpy.
"""
import argparse
import os
import sqlite3
import subprocess
import time

import cv2
import numpy as np

MAX_IMAGE_ID = 2147483647


def colmap(*args, log, may_fail=False):
    res = subprocess.run(["colmap", *args], capture_output=True, text=True)
    with open(log, "w") as f:
        f.write(res.stdout + res.stderr)
    if res.returncode != 0 and not may_fail:
        raise SystemExit(f"colmap {args[0]} failed:\n" + "\n".join((res.stdout + res.stderr).splitlines()[-20:]))
    return res.stdout + res.stderr


def mutual_ratio_matches(d1, d2, matcher, ratio):
    """Ratio test on 2-NN of d1 in d2, kept only when d1's match is also d2's nearest in d1."""
    if len(d1) == 0 or len(d2) < 2:
        return np.zeros((0, 2), np.uint32)
    knn = matcher.knnMatch(d1, d2, k=2)
    back = {m[0].queryIdx: m[0].trainIdx for m in matcher.knnMatch(d2, d1, k=1) if m}
    out = [(m[0].queryIdx, m[0].trainIdx) for m in knn
           if len(m) == 2 and m[0].distance < ratio * m[1].distance
           and back.get(m[0].trainIdx) == m[0].queryIdx]
    return np.array(out, np.uint32).reshape(-1, 2)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("images")
    ap.add_argument("k_file")
    ap.add_argument("out")
    ap.add_argument("--features", type=int, default=8000)
    ap.add_argument("--ratio", type=float, default=0.8)
    ap.add_argument("--descriptor", choices=["latch", "orb"], default="latch")
    a = ap.parse_args()
    cv2.setNumThreads(os.cpu_count())
    os.makedirs(os.path.join(a.out, "sparse"), exist_ok=True)
    db_path = os.path.join(a.out, "database.db")
    if os.path.exists(db_path):
        os.remove(db_path)
    fx, _, cx, _, fy, cy, *_ = map(float, open(a.k_file).read().split())
    names = sorted(n for n in os.listdir(a.images) if n.lower().endswith((".jpg", ".jpeg", ".png")))

    t0, c0 = time.perf_counter(), time.process_time()
    orb = cv2.ORB_create(nfeatures=a.features)
    describer = orb if a.descriptor == "orb" else cv2.xfeatures2d.LATCH_create()
    feats = []
    for n in names:
        img = cv2.imread(os.path.join(a.images, n), cv2.IMREAD_GRAYSCALE)
        kps = orb.detect(img, None)
        kps, desc = describer.compute(img, kps)
        feats.append((img.shape, kps, desc if desc is not None else np.zeros((0, 32), np.uint8)))
    t_extract, c_extract = time.perf_counter() - t0, time.process_time() - c0

    t0, c0 = time.perf_counter(), time.process_time()
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    pairs = {}
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            pairs[(i, j)] = mutual_ratio_matches(feats[i][2], feats[j][2], bf, a.ratio)
    t_match, c_match = time.perf_counter() - t0, time.process_time() - c0

    colmap("database_creator", "--database_path", db_path, log=os.path.join(a.out, "creator.log"))
    db = sqlite3.connect(db_path)
    (h, w), _, _ = feats[0]
    params = np.array([fx, fy, cx, cy], np.float64).tobytes()
    db.execute("INSERT INTO cameras VALUES (1, 1, ?, ?, ?, 1)", (w, h, params))
    for i, (n, (_, kps, _)) in enumerate(zip(names, feats)):
        kp = np.array([(k.pt[0] + 0.5, k.pt[1] + 0.5, k.size / 2, np.radians(k.angle)) for k in kps],
                      np.float32).reshape(-1, 4)
        db.execute("INSERT INTO images (image_id, name, camera_id) VALUES (?, ?, 1)", (i + 1, n))
        db.execute("INSERT INTO keypoints VALUES (?, ?, 4, ?)", (i + 1, len(kp), kp.tobytes()))
    db.commit()
    db.close()
    match_list = os.path.join(a.out, "matches.txt")
    with open(match_list, "w") as f:
        for (i, j), m in pairs.items():
            if len(m):
                f.write(f"{names[i]} {names[j]}\n" + "".join(f"{p} {q}\n" for p, q in m) + "\n")

    t0 = time.perf_counter()
    colmap("matches_importer", "--database_path", db_path, "--match_list_path", match_list,
           "--match_type", "raw", "--SiftMatching.use_gpu", "0", log=os.path.join(a.out, "import.log"))
    t_verify = time.perf_counter() - t0
    kp_total = sum(len(f[1]) for f in feats)
    print(f"keypoints {kp_total} ({kp_total / len(names):.0f} per image), "
          f"putative matches {sum(len(m) for m in pairs.values())} over {len(pairs)} pairs")
    print(f"extract {t_extract:.1f} s (cpu {c_extract:.1f} s), match {t_match:.1f} s (cpu {c_match:.1f} s), "
          f"verify {t_verify:.1f} s", flush=True)
    t0 = time.perf_counter()
    # COLMAP 3.8's mapper exits non-zero when it keeps no model: that is a result here, not an error.
    colmap("mapper", "--database_path", db_path, "--image_path", a.images,
           "--output_path", os.path.join(a.out, "sparse"), log=os.path.join(a.out, "mapper.log"),
           may_fail=True)
    print(f"map {time.perf_counter() - t0:.1f} s")
    models = sorted(os.listdir(os.path.join(a.out, "sparse")))
    if not models:
        print("no model: the mapper registered no image")
    for m in models:
        out = colmap("model_analyzer", "--path", os.path.join(a.out, "sparse", m), log=os.path.join(a.out, "analyzer.log"))
        print(f"model {m}: " + ", ".join(l.split("] ")[-1] for l in out.splitlines()
                                         if any(k in l for k in ("Registered images", "Points:", "Mean reprojection"))))


if __name__ == "__main__":
    main()
