#!/usr/bin/env bash
# One device call for the new defaults (issue 9) and racecheck (issue 10): the GPU suite, ncu device time of
# the default extraction (and of NMS tile variants, when .gpu/variants.tar.xz holds them), CPU-vs-GPU byte
# equality of whole CLI runs with the new defaults, racecheck on every binary in parallel. Prepare here:
#     bash tools/gpu_bench_images.sh && bash tools/pack_gpu_suite.sh
# then with the device tool: run `bash tools/gpu_defaults_call.sh`, carry [".gpu"], timeout 600.
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
bash tools/gpu_suite.sh tests > /dev/null 2>&1
mv "$OUT/summary.txt" "$OUT/summary_tests.txt"
B=.gpu/bin
mkdir -p .gpu/variants && { [ -f .gpu/variants.tar.xz ] && tar -xJf .gpu/variants.tar.xz -C .gpu/variants; }
IMG=.gpu/img/herzjesu0_5616x3744.png
ncu_sum() { python3 tools/ncu_sum.py /tmp/ncu.csv; }
{
for run in "$B/clatch|--threshold 10 --max-keypoints 20000" \
           "$B/clatch|--max-keypoints 20000" \
           "$B/clatch|" \
           ".gpu/variants/clatch_ty16|--threshold 10 --max-keypoints 20000 --pyramid 8:1.2 --level-budget geometric --keypoint-size 40" \
           ".gpu/variants/clatch_ty32|--threshold 10 --max-keypoints 20000 --pyramid 8:1.2 --level-budget geometric --keypoint-size 40"; do
  bin=${run%%|*}; cfg=${run#*|}
  echo "== ncu $bin extract $cfg"
  timeout 120 ncu --clock-control none --cache-control none --metrics gpu__time_duration.sum --csv \
     $bin extract --backend cuda $IMG $cfg -o /tmp/n > /tmp/ncu.csv 2>&1; echo "rc $?"
  grep -E "keypoints  " /tmp/ncu.csv | head -1
  ncu_sum
done
} > "$OUT/ncu.txt" 2>&1
{
for img in .gpu/img/sceaux7100.png $IMG; do
  for be in cpu cuda; do $B/clatch extract --backend $be $img -o /tmp/x_$be > /tmp/x_$be.log 2>&1; echo "extract $img $be rc $? $(grep -E 'keypoints  ' /tmp/x_$be.log)"; done
  for s in keypoints.csv descriptors.npy; do cmp /tmp/x_cpu.$s /tmp/x_cuda.$s && echo "  $s identical"; done
done
for be in cpu cuda; do $B/clatch extract --backend $be .gpu/img/sceaux7100.png --smoothing binomial5 -o /tmp/y_$be > /tmp/y_$be.log 2>&1; echo "extract sceaux --smoothing binomial5 $be rc $? $(grep -E 'keypoints  ' /tmp/y_$be.log)"; done
for s in keypoints.csv descriptors.npy; do cmp /tmp/y_cpu.$s /tmp/y_cuda.$s && echo "  $s identical"; done
for be in cpu cuda; do echo "== demo $be"; $B/clatch demo --backend $be -o /tmp/d_$be.png 2>&1 | grep -E "keypoints|matches|inliers"; done
} > "$OUT/cli_equal.txt" 2>&1
SAN_TIMEOUT=300 bash tools/gpu_suite.sh racecheck-parallel > /dev/null 2>&1
for f in "$OUT"/racecheck_*.txt; do echo "##### $f"; tail -60 "$f"; done > "$OUT/racecheck_logs.txt" 2>&1
rm -f "$OUT"/racecheck_cuda_*.txt
cat "$OUT/summary_tests.txt"; grep -E "device time|^==" "$OUT/ncu.txt"; cat "$OUT/cli_equal.txt"; cat "$OUT/summary.txt"
