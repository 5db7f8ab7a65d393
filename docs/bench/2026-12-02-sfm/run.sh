#!/usr/bin/env bash
# The SfM table for `clatch colmap`'s defaults of 2026-12-02 (8192 keypoints per photo, the
# given K kept fixed by the mapper, the AVX-512 CPU matcher), beside COLMAP SIFT measured in the same run. One job at a time (2 cores).
# Every clatch configuration: `clatch colmap` (extract, match, COLMAP verification and mapper), a
# second `colmap mapper` on the same database, then extract + match again with --no-colmap for the CPU
# time, checking that its keypoints and match list are identical to the mapped run's.
# Run from the repository root:
#   CLATCH=path/to/clatch docs/bench/2026-12-02-sfm/run.sh DATA_DIR WORK_DIR [JOB...]
# JOBs (default: all, in this order): sift-herz sift-sceaux herz-defaults sceaux-defaults herz-5000
# sceaux-5000 herz-none herz-corner. Logs go to docs/bench/2026-12-02-sfm/logs/.
set -uo pipefail
data=$1 work=$2
shift 2
jobs=("$@")
[ ${#jobs[@]} -eq 0 ] && jobs=(sift-herz sift-sceaux herz-defaults sceaux-defaults herz-5000 sceaux-5000 herz-none herz-corner)
logs=docs/bench/2026-12-02-sfm/logs
clatch=${CLATCH:-target/release/clatch}
mkdir -p "$work" "$logs"
H=$data/strecha_herzjesu_p8 S=$data/sceaux_castle
header() { echo "== $* ($(date -u +%H:%M:%S), load $(cut -d' ' -f1-3 /proc/loadavg))"; }
evaluate() { # evaluate SCENE DB MODEL_ROOT [sift]
    local scene=$1 db=$2 root=$3 kind=${4:-}
    for m in "$root"/*/; do
        [ -d "$m" ] || continue
        echo "-- model $m"
        colmap model_analyzer --path "$m" 2>&1 | grep -E "Registered images|Points:|Observations:|Mean track|Mean reprojection" | sed 's/^.*\] //'
        [ "$scene" = herz ] && python3 tools/colmap_eval.py "$m" "$H/gt_dense_cameras" | grep -E "registered|error"
        if [ "$kind" = sift ]; then # SIFT's keypoints are affine shapes: no per-scale table
            python3 tools/colmap_level_errors.py "$db" "$m" | head -n 1
        else
            python3 tools/colmap_level_errors.py "$db" "$m"
        fi
    done
}
remap() { # remap NAME SCENE DB IMAGES KIND [MAPPER_OPTION...]: KIND sift or empty
    local name=$1 scene=$2 db=$3 images=$4 kind=$5 out=$work/$1-remap
    shift 5
    rm -rf "$out"; mkdir -p "$out"
    header "$name: mapper again on the same database $*"
    /usr/bin/time -f "map (repeat): wall %e s user %U s sys %S s" \
        colmap mapper --database_path "$db" --image_path "$images" --output_path "$out" "$@" > "$work/$name-remap.log" 2>&1
    grep -E "Elapsed time|No good initial" "$work/$name-remap.log" | tail -n 2
    evaluate "$scene" "$db" "$out" "$kind"
}
sift() { # sift NAME SCENE IMAGES K
    local name=$1 scene=$2 images=$3 k=$4
    {
        header "$name: COLMAP SIFT (CPU)"
        rm -rf "$work/$name"
        tools/colmap_sift_baseline.sh "$images" "$k" "$work/$name"
        for s in extract match map; do echo "$s: $(cat "$work/$name/$s.time") (wall user sys)"; done
        evaluate "$scene" "$work/$name/database.db" "$work/$name/sparse" sift
        remap "$name" "$scene" "$work/$name/database.db" "$images" sift
    } 2>&1 | tee "$logs/$name.txt"
}
run_clatch() { # run_clatch NAME SCENE IMAGES K ARGS...
    local name=$1 scene=$2 images=$3 k=$4; shift 4
    {
        header "$name: clatch colmap $*"
        rm -rf "$work/$name.db" "$work/$name-colmap"
        /usr/bin/time -f "total (all stages): wall %e s user %U s sys %S s" \
            "$clatch" colmap --images "$images" --camera-k "$k" --database "$work/$name.db" --backend cpu "$@"
        evaluate "$scene" "$work/$name.db" "$work/$name-colmap/sparse"
        # the options `clatch colmap` gives the mapper: a given K is kept (--camera-k)
        remap "$name" "$scene" "$work/$name.db" "$images" "" --Mapper.ba_refine_focal_length 0
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
for job in "${jobs[@]}"; do
    case $job in
        sift-herz) sift herz-sift herz "$H/images" "$H/K.txt" ;;
        sift-sceaux) sift sceaux-sift sceaux "$S" "$S/K.txt" ;;
        herz-defaults) run_clatch herz-clatch-defaults herz "$H/images" "$H/K.txt" ;;
        sceaux-defaults) run_clatch sceaux-clatch-defaults sceaux "$S" "$S/K.txt" ;;
        herz-5000) run_clatch herz-clatch-5000 herz "$H/images" "$H/K.txt" --max-keypoints 5000 ;;
        sceaux-5000) run_clatch sceaux-clatch-5000 sceaux "$S" "$S/K.txt" --max-keypoints 5000 ;;
        herz-none) run_clatch herz-clatch-subpixel-none herz "$H/images" "$H/K.txt" --subpixel none ;;
        herz-corner) run_clatch herz-clatch-subpixel-corner herz "$H/images" "$H/K.txt" --subpixel corner ;;
        *) echo "unknown job $job" >&2; exit 2 ;;
    esac
done
