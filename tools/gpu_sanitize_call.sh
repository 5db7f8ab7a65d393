#!/usr/bin/env bash
# One device call: the GPU test suite, then every GPU test binary, whole, under memcheck, initcheck and
# synccheck (one sequence per tool, side by side) and racecheck (the binaries named in RACE_BINS, all at
# once, CLATCH_TEST_SCALE=sanitizer). Prepare here: bash tools/pack_gpu_suite.sh; run with carry [".gpu"].
# Files back: summary_tests.txt, suite.txt, sanitize_summary.txt, sanitize_logs.txt, racecheck_logs.txt.
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
bash tools/gpu_suite.sh tests > /dev/null 2>&1
mv "$OUT/summary.txt" "$OUT/summary_tests.txt"
for tool in memcheck initcheck synccheck; do
    OUT=$OUT/$tool SAN_TIMEOUT=${SAN_TIMEOUT:-200} bash tools/gpu_suite.sh sanitize-all $tool > /dev/null 2>&1 &
done
# shellcheck disable=SC2086
OUT=$OUT/racecheck SAN_TIMEOUT=${RACE_TIMEOUT:-300} bash tools/gpu_suite.sh racecheck-parallel ${RACE_BINS:-} > /dev/null 2>&1 &
wait
cat "$OUT"/{memcheck,initcheck,synccheck,racecheck}/summary.txt > "$OUT/sanitize_summary.txt"
cat "$OUT"/{memcheck,initcheck,synccheck,racecheck}/sanitize.txt > "$OUT/sanitize_logs.txt"
for f in "$OUT"/racecheck/racecheck_*.txt; do echo "##### $f"; tail -60 "$f"; done > "$OUT/racecheck_logs.txt"
rm -rf "$OUT"/{memcheck,initcheck,synccheck,racecheck}
cat "$OUT/summary_tests.txt" "$OUT/sanitize_summary.txt"
