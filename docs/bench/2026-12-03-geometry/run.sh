#!/usr/bin/env bash
# The baseline of EVALUATION.md's "baseline, COLMAP's verification" (2026-12-03): clatch colmap and COLMAP's
# CPU SIFT on Herz-Jesu and two generated repeated-structure scenes, every database and model judged by
# clatch-eval geometry. Run from the repository root: docs/bench/2026-12-03-geometry/run.sh DATA OUT
#   DATA: the folder holding strecha_herzjesu_p8 and sceaux_castle (data/README.md); OUT: a work folder.
set -euo pipefail
data=$1 out=$2
repo=$(pwd)
cargo build --release -p clatch-cli -p clatch-eval
clatch=$repo/target/release/clatch eval=$repo/target/release/clatch-eval
mkdir -p "$out" && cd "$out"
photo=$data/sceaux_castle/100_7100.JPG
[ -e facade1/scene.json ] || $eval facade --photo "$photo" --crop 940,1020,250,290 --out facade1
[ -e corner1/scene.json ] || $eval facade --photo "$photo" --crop 940,1020,250,290 --columns 5 --corner --out corner1
H=$data/strecha_herzjesu_p8
run() { # run NAME IMAGES K SCENE
    local name=$1 images=$2 k=$3 scene=$4
    /usr/bin/time -f "%e %U %S" -o clatch_$name.time \
        $clatch colmap --images "$images" --camera-k "$k" --database clatch_$name.db --backend cpu --force > clatch_$name.out
    $eval geometry --scene "$scene" --database clatch_$name.db --model clatch_$name-colmap/sparse/0 --pairs \
        --json clatch_$name.geometry.json
    "$repo"/eval/scripts/colmap_sift_baseline.sh "$images" "$k" sift_$name | tee sift_$name.out
    # K kept fixed, as clatch colmap maps (the script's mapping refines the focal length)
    rm -rf sift_$name/sparse_fixedf && mkdir -p sift_$name/sparse_fixedf
    /usr/bin/time -f "%e %U %S" -o sift_$name.fixedf.time colmap mapper --database_path sift_$name/database.db \
        --image_path "$images" --output_path sift_$name/sparse_fixedf --Mapper.ba_refine_focal_length 0 \
        > sift_$name.fixedf.log 2>&1
    $eval geometry --scene "$scene" --database sift_$name/database.db --model sift_$name/sparse_fixedf/0 --pairs \
        --json sift_$name.geometry.json
}
run herz "$H/images" "$H/K.txt" "$H"
run facade1 facade1/images facade1/K.txt facade1
run corner1 corner1/images corner1/K.txt corner1
