#!/usr/bin/env python3
"""What `--subpixel score` would give if it refined only level-0 keypoints (the coarser levels' positions
left on their whole level pixel, mapped to level 0), without changing the CLI: two databases of the same
run (same keypoints, descriptors and matches), one with `--subpixel score` and one with `--subpixel none`,
merged: level-0 rows (the smallest scale) from the first, the rest from the second. Then COLMAP's
verification, mapper and model analyzer again, on the same match list.

    python3 level0_subpixel.py SCORE_DB NONE_DB MATCH_LIST IMAGES OUT_DIR
"""
import os
import shutil
import sqlite3
import subprocess
import sys

import numpy as np


def main():
    score_db, none_db, match_list, images, out = sys.argv[1:]
    os.makedirs(os.path.join(out, "sparse"), exist_ok=True)
    db_path = os.path.join(out, "database.db")
    shutil.copy(none_db, db_path)
    score = {i: np.frombuffer(d, np.float32).reshape(r, c)
             for i, r, c, d in sqlite3.connect(score_db).execute("SELECT image_id, rows, cols, data FROM keypoints")}
    db = sqlite3.connect(db_path)
    changed = 0
    for i, r, c, d in list(db.execute("SELECT image_id, rows, cols, data FROM keypoints")):
        kp = np.frombuffer(d, np.float32).reshape(r, c).copy()
        s = score[i]
        assert s.shape == kp.shape and np.array_equal(s[:, 2], kp[:, 2]), "not the same keypoints"
        assert np.all(np.abs(s[:, :2] - kp[:, :2]) <= 0.5 + 1e-4), "not the same keypoints"
        level0 = kp[:, 2] == kp[:, 2].min()
        kp[level0, :2] = s[level0, :2]
        changed += int(level0.sum())
        db.execute("UPDATE keypoints SET data = ? WHERE image_id = ?", (kp.tobytes(), i))
    db.execute("DELETE FROM matches")
    db.execute("DELETE FROM two_view_geometries")
    db.commit()
    db.close()
    print(f"level-0 keypoints with score sub-pixel positions: {changed}")
    subprocess.run(["colmap", "matches_importer", "--database_path", db_path, "--match_list_path", match_list,
                    "--match_type", "raw", "--SiftMatching.use_gpu", "0"], check=True, capture_output=True)
    subprocess.run(["colmap", "mapper", "--database_path", db_path, "--image_path", images,
                    "--output_path", os.path.join(out, "sparse")], check=True, capture_output=True)


if __name__ == "__main__":
    main()
