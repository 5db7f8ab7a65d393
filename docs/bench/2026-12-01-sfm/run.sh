#!/usr/bin/env bash
# The SfM table for the candidate defaults: every method on both scenes, one after the other
# (never two at once: the machine has 2 cores), each followed by a second `colmap mapper` run on the
# same database (the mapper is randomised). Run from the repository root:
#   docs/bench/2026-12-01-sfm/run.sh DATA_DIR WORK_DIR
# DATA_DIR holds strecha_herzjesu_p8 and sceaux_castle; WORK_DIR gets the databases and models (large:
# keep it out of the repository). Small text logs go to docs/bench/2026-12-01-sfm/logs/.
set -uo pipefail
data=$1 work=$2
logs=docs/bench/2026-12-01-sfm/logs
clatch=${CLATCH:-target/release/clatch}
mkdir -p "$work" "$logs"
H=$data/strecha_herzjesu_p8 S=$data/sceaux_castle
candidate=(--pyramid 8:1.2 --level-budget geometric --keypoint-size 40)

header() { echo "== $* ($(date -u +%H:%M:%S), load $(cut -d' ' -f1-3 /proc/loadavg))"; }

# evaluate NAME SCENE DB MODEL_ROOT: ground-truth errors (Herz-Jesu) and per-scale errors of every model
evaluate() {
    local name=$1 scene=$2 db=$3 root=$4
    for m in "$root"/*/; do
        [ -d "$m" ] || continue
        echo "-- model $m"
        colmap model_analyzer --path "$m" 2>&1 | grep -E "Registered images|Points:|Observations:|Mean track|Mean reprojection" | sed 's/^.*\] //'
        [ "$scene" = herz ] && python3 tools/colmap_eval.py "$m" "$H/gt_dense_cameras" | grep -E "registered|error"
        if [ "${name#*-}" = sift ]; then # SIFT's keypoints are affine (6 columns, no scale): the overall line only
            python3 tools/colmap_level_errors.py "$db" "$m" | head -n 1
        else
            python3 tools/colmap_level_errors.py "$db" "$m"
        fi
    done
}

# remap NAME SCENE DB IMAGES: a second mapper run on the same database, timed, then evaluated
remap() {
    local name=$1 scene=$2 db=$3 images=$4 out=$work/$1-remap
    rm -rf "$out"; mkdir -p "$out"
    header "$name: mapper again on the same database"
    /usr/bin/time -f "map (repeat): wall %e s user %U s sys %S s" \
        colmap mapper --database_path "$db" --image_path "$images" --output_path "$out" > "$work/$name-remap.log" 2>&1
    grep -E "Elapsed time|No good initial" "$work/$name-remap.log" | tail -n 2
    evaluate "$name" "$scene" "$db" "$out"
}

sift() { # sift NAME SCENE IMAGES K
    local name=$1 scene=$2 images=$3 k=$4
    {
        header "$name: COLMAP SIFT (CPU)"
        rm -rf "$work/$name"
        tools/colmap_sift_baseline.sh "$images" "$k" "$work/$name"
        for s in extract match map; do echo "$s: $(cat "$work/$name/$s.time") (wall user sys)"; done
        evaluate "$name" "$scene" "$work/$name/database.db" "$work/$name/sparse"
        remap "$name" "$scene" "$work/$name/database.db" "$images"
    } 2>&1 | tee "$logs/$name.txt"
}

opencv() { # opencv NAME SCENE IMAGES K ARGS...
    local name=$1 scene=$2 images=$3 k=$4; shift 4
    {
        header "$name: OpenCV ORB $*"
        rm -rf "$work/$name"
        /usr/bin/time -f "total (extract, match, verify, map, analyze): wall %e s user %U s sys %S s" \
            python3 tools/colmap_opencv_baseline.py "$images" "$k" "$work/$name" "$@"
        evaluate "$name" "$scene" "$work/$name/database.db" "$work/$name/sparse"
        remap "$name" "$scene" "$work/$name/database.db" "$images"
    } 2>&1 | tee "$logs/$name.txt"
}

run_clatch() { # run_clatch NAME SCENE IMAGES K ARGS...
    local name=$1 scene=$2 images=$3 k=$4; shift 4
    {
        header "$name: clatch colmap $*"
        rm -rf "$work/$name.db" "$work/$name-colmap"
        /usr/bin/time -f "total (all stages): wall %e s user %U s sys %S s" \
            "$clatch" colmap --images "$images" --camera-k "$k" --database "$work/$name.db" --backend cpu "$@"
        evaluate "$name" "$scene" "$work/$name.db" "$work/$name-colmap/sparse"
        remap "$name" "$scene" "$work/$name.db" "$images"
    } 2>&1 | tee "$logs/$name.txt"
}

for scene in herz sceaux; do
    if [ $scene = herz ]; then images=$H/images k=$H/K.txt; else images=$S k=$S/K.txt; fi
    run_clatch "$scene-clatch-today" $scene "$images" "$k"
    run_clatch "$scene-clatch-candidate" $scene "$images" "$k" "${candidate[@]}"
    run_clatch "$scene-clatch-candidate-max8000" $scene "$images" "$k" "${candidate[@]}" --max-keypoints 8000
    run_clatch "$scene-clatch-candidate-t10" $scene "$images" "$k" "${candidate[@]}" --threshold 10
    run_clatch "$scene-clatch-candidate-nosubpixel" $scene "$images" "$k" "${candidate[@]}" --subpixel none
    opencv "$scene-orb-latch-5000" $scene "$images" "$k" --features 5000
    opencv "$scene-orb-orb-5000" $scene "$images" "$k" --features 5000 --descriptor orb
    opencv "$scene-orb-latch-8000" $scene "$images" "$k" --features 8000
    sift "$scene-sift" $scene "$images" "$k"
done
