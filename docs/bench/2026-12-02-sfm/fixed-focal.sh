#!/usr/bin/env bash
# Diagnostic of the rotation error on Herz-Jesu: `colmap mapper` again on run.sh's databases with the
# given K held fixed (--Mapper.ba_refine_focal_length 0; PINHOLE has no extra parameters and the
# principal point is not refined by default), SIFT's included; prints the refined K of each model.
#   docs/bench/2026-12-02-sfm/fixed-focal.sh DATA_DIR WORK_DIR NAME...   (NAME: herz-sift, herz-clatch-defaults, ...)
set -uo pipefail
data=$1 work=$2; shift 2
H=$data/strecha_herzjesu_p8
for name in "$@"; do
    db=$work/$name.db; [ -f "$db" ] || db=$work/$name/database.db
    out=$work/$name-fixedf; rm -rf "$out"; mkdir -p "$out"
    echo "== $name: mapper, focal length fixed ($(date -u +%H:%M:%S), load $(cut -d' ' -f1-3 /proc/loadavg))"
    colmap mapper --database_path "$db" --image_path "$H/images" --output_path "$out" \
        --Mapper.ba_refine_focal_length 0 > "$out.log" 2>&1
    for m in "$out"/*/; do
        colmap model_analyzer --path "$m" 2>&1 | grep -E "Registered images|Points:|Mean reprojection" | sed 's/^.*\] //'
        python3 tools/colmap_eval.py "$m" "$H/gt_dense_cameras" | grep -E "error"
        colmap model_converter --input_path "$m" --output_path "$out" --output_type TXT > /dev/null 2>&1
        echo "camera: $(grep -v '^#' "$out/cameras.txt")"
    done
    # the refined K of the default mapping (run.sh's model), for comparison
    for m in "$work/$name-colmap/sparse/0" "$work/$name/sparse/0"; do
        [ -d "$m" ] || continue
        t=$work/$name-txt; mkdir -p "$t"
        colmap model_converter --input_path "$m" --output_path "$t" --output_type TXT > /dev/null 2>&1
        echo "camera of the default mapping (focal refined): $(grep -v '^#' "$t/cameras.txt")"
    done
done
