#!/usr/bin/env bash
# COLMAP 3.8's own CPU SIFT pipeline on a folder of photos with a known PINHOLE K, timing each stage:
# the reference that `clatch colmap` is compared with in EVALUATION.md.
#   eval/scripts/colmap_sift_baseline.sh IMAGES_DIR K_FILE OUT_DIR
# Writes OUT_DIR/database.db, OUT_DIR/sparse/N and OUT_DIR/*.log; prints the stage times and
# model_analyzer's figures. SIFT must run with use_gpu 0 on a machine without a display or GPU.
set -euo pipefail
images=$1 k_file=$2 out=$3
k=($(tr -d '\r' < "$k_file"))  # 9 numbers, row-major; some K.txt files end lines with CRLF
fx=${k[0]} cx=${k[2]} fy=${k[4]} cy=${k[5]}
mkdir -p "$out/sparse"
rm -f "$out/database.db"
stage() { # stage NAME COMMAND...: runs it, logs it, prints its wall and CPU (user + system) time
    local name=$1; shift
    /usr/bin/time -f "%e %U %S" -o "$out/$name.time" "$@" > "$out/$name.log" 2>&1 \
        || { tail -n 20 "$out/$name.log"; exit 1; }
    read -r wall user sys < "$out/$name.time"
    printf '%-10s %.1f s (cpu %.1f s)\n' "$name" "$wall" "$(echo "$user + $sys" | bc)"
}
stage extract colmap feature_extractor --database_path "$out/database.db" --image_path "$images" \
    --ImageReader.camera_model PINHOLE --ImageReader.single_camera 1 \
    --ImageReader.camera_params "$fx,$fy,$cx,$cy" --SiftExtraction.use_gpu 0
stage match colmap exhaustive_matcher --database_path "$out/database.db" --SiftMatching.use_gpu 0
stage map colmap mapper --database_path "$out/database.db" --image_path "$images" --output_path "$out/sparse"
for model in "$out"/sparse/*/; do
    colmap model_analyzer --path "$model" 2>&1 | grep -E "Registered images|Points|Mean reprojection error" | sed 's/^.*\] //'
done
