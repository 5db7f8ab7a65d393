#!/usr/bin/env bash
# EVALUATION.md's "guided matching" (2026-12-03): `clatch colmap --verify` without (`--no-guided-matching`)
# and with guided matching (the default) on the three generated repeated-structure scenes and Herz-Jesu, each database and
# model judged by clatch-eval geometry. Run from the repository root:
#   docs/bench/2026-12-03-guided/run.sh DATA OUT
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
[ -e other1/scene.json ] || $eval facade --photo "$photo" --crop 1150,980,220,260 --columns 7 --rows 3 --seed 3 \
    --spread 30 --out other1
H=$data/strecha_herzjesu_p8
run() { # run NAME IMAGES K SCENE: both modes one after the other
    local name=$1 images=$2 k=$3 scene=$4
    for mode in verify guided; do
        local flags=(--verify)
        [ $mode = verify ] && flags+=(--no-guided-matching)
        /usr/bin/time -f "%e %U %S" -o $mode-$name.time $clatch colmap --images "$images" --camera-k "$k" \
            --database $mode-$name.db --backend cpu --force "${flags[@]}" > $mode-$name.out
        $eval geometry --scene "$scene" --database $mode-$name.db --model $mode-$name-colmap/sparse/0 --pairs \
            --json $mode-$name.geometry.json > $mode-$name.geo
    done
}
run facade1 facade1/images facade1/K.txt facade1
run corner1 corner1/images corner1/K.txt corner1
run other1 other1/images other1/K.txt other1
run herz "$H/images" "$H/K.txt" "$H"
