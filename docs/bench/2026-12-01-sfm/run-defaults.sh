#!/usr/bin/env bash
# The "defaults (main ee81601)" rows: `clatch colmap` with no detector flags (the library's new defaults:
# 8-level 1.2 pyramid, ORB's level shares, 40-pixel windows, Subpixel::Score on every level) and with
# --max-keypoints 8000, both scenes, each mapped twice (as run.sh), then extract + match again with
# --no-colmap (as retime.sh) for the CPU time, checking that the keypoints and match list are identical.
# One job at a time. Run from the repository root:
#   CLATCH=path/to/clatch docs/bench/2026-12-01-sfm/run-defaults.sh DATA_DIR WORK_DIR
set -uo pipefail
data=$1 work=$2
logs=docs/bench/2026-12-01-sfm/logs
clatch=${CLATCH:-target/release/clatch}
mkdir -p "$work" "$logs"
H=$data/strecha_herzjesu_p8 S=$data/sceaux_castle
header() { echo "== $* ($(date -u +%H:%M:%S), load $(cut -d' ' -f1-3 /proc/loadavg))"; }
evaluate() {
    local name=$1 scene=$2 db=$3 root=$4
    for m in "$root"/*/; do
        [ -d "$m" ] || continue
        echo "-- model $m"
        colmap model_analyzer --path "$m" 2>&1 | grep -E "Registered images|Points:|Observations:|Mean track|Mean reprojection" | sed 's/^.*\] //'
        [ "$scene" = herz ] && python3 tools/colmap_eval.py "$m" "$H/gt_dense_cameras" | grep -E "registered|error"
        python3 tools/colmap_level_errors.py "$db" "$m"
    done
}
remap() {
    local name=$1 scene=$2 db=$3 images=$4 out=$work/$1-remap
    rm -rf "$out"; mkdir -p "$out"
    header "$name: mapper again on the same database"
    /usr/bin/time -f "map (repeat): wall %e s user %U s sys %S s" \
        colmap mapper --database_path "$db" --image_path "$images" --output_path "$out" > "$work/$name-remap.log" 2>&1
    grep -E "Elapsed time|No good initial" "$work/$name-remap.log" | tail -n 2
    evaluate "$name" "$scene" "$db" "$out"
}
run_clatch() {
    local name=$1 scene=$2 images=$3 k=$4; shift 4
    {
        header "$name: clatch colmap $*"
        rm -rf "$work/$name.db" "$work/$name-colmap"
        /usr/bin/time -f "total (all stages): wall %e s user %U s sys %S s" \
            "$clatch" colmap --images "$images" --camera-k "$k" --database "$work/$name.db" --backend cpu "$@"
        evaluate "$name" "$scene" "$work/$name.db" "$work/$name-colmap/sparse"
        remap "$name" "$scene" "$work/$name.db" "$images"
        header "$name: extract + match again, --no-colmap"
        db=$work/retime-$name.db
        /usr/bin/time -f "total: wall %e s user %U s sys %S s" "$clatch" colmap --images "$images" --camera-k "$k" \
            --database "$db" --backend cpu --no-colmap --force "$@" 2>&1 | grep -E "keypoints|matches|extract|match |total"
        python3 - "$db" "$work/$name.db" <<'PY'
import sqlite3, sys
q = "SELECT image_id, rows, cols, data FROM keypoints ORDER BY image_id"
a, b = (sqlite3.connect(p).execute(q).fetchall() for p in sys.argv[1:])
print("keypoints identical to the mapped run's database:", a == b)
PY
        cmp -s "${db%.db}-colmap/matches.txt" "$work/$name-colmap/matches.txt" && echo "match list identical" || echo "match list DIFFERS"
    } 2>&1 | tee "$logs/$name.txt"
}
for scene in herz sceaux; do
    if [ $scene = herz ]; then images=$H/images k=$H/K.txt; else images=$S k=$S/K.txt; fi
    run_clatch "$scene-clatch-defaults-ee81601" $scene "$images" "$k"
    run_clatch "$scene-clatch-defaults-ee81601-max8000" $scene "$images" "$k" --max-keypoints 8000
done
