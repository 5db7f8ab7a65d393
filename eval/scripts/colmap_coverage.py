#!/usr/bin/env python3
"""How keypoints spread over each image of a COLMAP database, and how well each image is tied to the
others after COLMAP's geometric verification: what decides whether the mapper can register it.

    python3 eval/scripts/colmap_coverage.py DATABASE [GRID]

Per image: keypoints, cells of a GRID x GRID division (default 8) holding at least one keypoint,
the share of keypoints in the busiest eighth of the cells, and the two largest verified inlier counts
with other images (COLMAP's mapper wants 100 for its initial pair and 15 to register an image, by
default). Needs numpy only.
"""
import sqlite3
import sys

import numpy as np

MAX_IMAGE_ID = 2147483647


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    grid = int(sys.argv[2]) if len(sys.argv) == 3 else 8
    db = sqlite3.connect(sys.argv[1])
    sizes = {c: (w, h) for c, w, h in db.execute("SELECT camera_id, width, height FROM cameras")}
    images = db.execute("SELECT image_id, name, camera_id FROM images ORDER BY image_id").fetchall()
    links = {i: [] for i, _, _ in images}
    for pair, rows in db.execute("SELECT pair_id, rows FROM two_view_geometries WHERE rows > 0"):
        a, b = pair // MAX_IMAGE_ID, pair % MAX_IMAGE_ID
        links[a].append(rows)
        links[b].append(rows)
    print(f"{'image':<16}{'keypoints':>10}{'cells':>8}{'busiest 1/8':>13}  best verified pairs")
    for image_id, name, camera in images:
        rows, cols, data = db.execute(
            "SELECT rows, cols, data FROM keypoints WHERE image_id = ?", (image_id,)).fetchone()
        xy = np.frombuffer(data, np.float32).reshape(rows, cols)[:, :2]
        w, h = sizes[camera]
        cx = np.minimum((xy[:, 0] * grid / w).astype(int), grid - 1)
        cy = np.minimum((xy[:, 1] * grid / h).astype(int), grid - 1)
        counts = np.bincount(cy * grid + cx, minlength=grid * grid)
        busiest = np.sort(counts)[::-1][: max(1, grid * grid // 8)].sum() / max(1, rows)
        best = sorted(links[image_id], reverse=True)[:2]
        print(f"{name:<16}{rows:>10}{(counts > 0).sum():>5}/{grid * grid:<3}{100 * busiest:>11.0f}%  {best}")


if __name__ == "__main__":
    main()
