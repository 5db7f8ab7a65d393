#!/usr/bin/env bash
# Extract + match timing of every clatch row again with a binary of known provenance (this branch, built from
# 256bb5f in a target folder of its own), `--no-colmap`, one after the other, and a check that
# its database keypoints and match list equal those of run.sh's run (so the COLMAP figures stand).
#   docs/bench/2026-12-01-sfm/retime.sh CLATCH DATA_DIR WORK_DIR
set -uo pipefail
clatch=$1 data=$2 work=$3
H=$data/strecha_herzjesu_p8 S=$data/sceaux_castle
C=(--pyramid 8:1.2 --level-budget geometric --keypoint-size 40)
for scene in herz sceaux; do
    if [ $scene = herz ]; then images=$H/images k=$H/K.txt; else images=$S k=$S/K.txt; fi
    for cfg in today candidate candidate-max8000 candidate-t10 candidate-nosubpixel; do
        case $cfg in
            today) args=() ;;
            candidate) args=("${C[@]}") ;;
            candidate-max8000) args=("${C[@]}" --max-keypoints 8000) ;;
            candidate-t10) args=("${C[@]}" --threshold 10) ;;
            candidate-nosubpixel) args=("${C[@]}" --subpixel none) ;;
        esac
        name=$scene-clatch-$cfg db=$work/retime-$scene-$cfg.db
        echo "== $name (load $(cut -d' ' -f1-3 /proc/loadavg))"
        /usr/bin/time -f "total: wall %e s user %U s sys %S s" "$clatch" colmap --images "$images" --camera-k "$k" \
            --database "$db" --backend cpu --no-colmap --force "${args[@]}" 2>&1 | grep -E "keypoints|matches|extract|match |total"
        python3 - "$db" "$work/$name.db" <<'PY'
import sqlite3, sys
q = "SELECT image_id, rows, cols, data FROM keypoints ORDER BY image_id"
a, b = (sqlite3.connect(p).execute(q).fetchall() for p in sys.argv[1:])
print("keypoints identical to run.sh's database:", a == b)
PY
        cmp -s "${db%.db}-colmap/matches.txt" "$work/$name-colmap/matches.txt" && echo "match list identical" || echo "match list DIFFERS"
    done
done
