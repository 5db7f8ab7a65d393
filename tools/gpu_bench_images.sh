#!/usr/bin/env bash
# Builds, here, the photographs the device-time and CLI-equality runs carry in .gpu/img (git-ignored):
# Herz-Jesu image 0000 upscaled to 5616x3744 (bicubic; the size of issue 9's device-time goal) and Sceaux
# 100_7100 in gray. Needs ../shared/data and python3 with OpenCV (cv2).
#     bash tools/gpu_bench_images.sh [DATA]     (default ../shared/data)
set -euo pipefail
cd "$(dirname "$0")/.."
data=${1:-../shared/data}
mkdir -p .gpu/img
python3 - "$data" <<'PY'
import sys, cv2
data = sys.argv[1]
im = cv2.imread(f"{data}/strecha_herzjesu_p8/images/0000.jpg", cv2.IMREAD_GRAYSCALE)
cv2.imwrite(".gpu/img/herzjesu0_5616x3744.png", cv2.resize(im, (5616, 3744), interpolation=cv2.INTER_CUBIC))
cv2.imwrite(".gpu/img/sceaux7100.png", cv2.imread(f"{data}/sceaux_castle/100_7100.JPG", cv2.IMREAD_GRAYSCALE))
PY
ls -la .gpu/img
