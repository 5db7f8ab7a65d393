#!/usr/bin/env bash
# The matcher before and after on the photos: `clatch colmap --no-colmap` at 8192 keypoints with the
# binary of main before this branch (cd79a8b, scalar POPCNT matcher) and this branch's, one after the
# other; the match lists must be identical (same bits), the CPU times are the report's.
#   docs/bench/2026-12-02-sfm/matcher-before-after.sh OLD_CLATCH NEW_CLATCH DATA_DIR WORK_DIR
set -uo pipefail
old=$1 new=$2 data=$3 work=$4
H=$data/strecha_herzjesu_p8 S=$data/sceaux_castle
for scene in herz sceaux; do
    if [ $scene = herz ]; then images=$H/images k=$H/K.txt; else images=$S k=$S/K.txt; fi
    for which in old new; do
        bin=$old; [ $which = new ] && bin=$new
        echo "== $scene, $which ($bin) ($(date -u +%H:%M:%S), load $(cut -d' ' -f1-3 /proc/loadavg))"
        /usr/bin/time -f "total: wall %e s user %U s sys %S s" "$bin" colmap --images "$images" --camera-k "$k" \
            --database "$work/ba-$scene-$which.db" --backend cpu --no-colmap --force --max-keypoints 8192 2>&1 \
            | grep -E "keypoints|matches|extract|match |total"
    done
    cmp -s "$work/ba-$scene-old-colmap/matches.txt" "$work/ba-$scene-new-colmap/matches.txt" \
        && echo "$scene: match lists identical" || echo "$scene: match lists DIFFER"
done
