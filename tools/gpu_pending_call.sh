#!/usr/bin/env bash
# tools/PENDING_GPU.md's seven calls folded into two full device calls (2026-12-02: 30 minutes of device
# time, a fresh start costs one to two of them). Prepare here: bash tools/pack_gpu_suite.sh, and copy the
# JPEG folders with bash tools/pack_gpu_extract.sh --folders-only (or the whole of that script).
# Both calls carry [".gpu/suite.tar.xz", ".gpu/folders"] and run under timeout 600:
#
#   bash tools/gpu_pending_call.sh verify   every GPU suite of the extraction and collection sides
#       (gpu_extract_call.sh tests, gpu_collection_call.sh tests), then issue 13's collection bench with the
#       PyTorch baseline (gpu_collection_call.sh bench, 2 timed runs) and issue 11's pool call
#       (gpu_pool_call.sh). About 9 minutes.
#   bash tools/gpu_pending_call.sh measure  issue 13's extraction bench and real folders
#       (gpu_extract_call.sh bench), then the sanitizers side by side, each bounded by what is left of
#       the call: memcheck, initcheck and synccheck on cuda_extract_stream, cuda_collection, cuda_pool and
#       cuda_faults, racecheck on cuda_collection, cuda_extract_stream and cuda_faults, all with
#       CLATCH_TEST_SCALE=sanitizer. About 9.5 minutes.
#
# Every part's summary lines go to $OUT/summary_all.txt (printed last); the parts' own logs stay in $OUT
# (at most 8 files come back).
cd "$(dirname "$0")/.."
export OUT=${OUT:-/tmp/out}
mkdir -p "$OUT" .gpu/bin
start=$(date +%s)
left() { echo $(( ${CALL_SECONDS:-585} - ($(date +%s) - start) )); }
part() { # title command...
    local title=$1; shift
    echo "##### $title ($(( $(date +%s) - start )) s into the call)" >> "$OUT/summary_all.txt"
    "$@" > /dev/null 2>&1
    cat "$OUT/summary.txt" >> "$OUT/summary_all.txt" 2>/dev/null
    rm -f "$OUT/summary.txt"
}
# The whole suite.tar.xz, or the parts a call carries (.gpu/part-*.tar.xz: suite.tar.xz with the JPEG
# folders is over a call's 64 MiB). The scripts below then find .gpu/bin unpacked.
for tarball in .gpu/suite.tar.xz .gpu/part-*.tar.xz; do
    [ -f "$tarball" ] && tar -xJf "$tarball" -C .gpu/bin
done
touch .gpu/bin/.unpacked
# gpu_extract_call.sh bench reads .gpu/xbin (from extract.tar.xz); the suite holds the same binaries.
[ -e .gpu/xbin ] || ln -s bin .gpu/xbin
case "${1:-verify}" in
verify)
    TEST_LIMIT=120 part "extraction side: every GPU suite" bash tools/gpu_extract_call.sh tests
    part "collection side: tests" bash tools/gpu_collection_call.sh tests
    CLATCH_COLLECTION_REPEATS=2 part "collection bench and PyTorch baseline" bash tools/gpu_collection_call.sh bench
    part "pool (the one GPU as 1, 2 and 4 workers)" bash tools/gpu_pool_call.sh
    ;;
measure)
    part "extraction bench and real folders" bash tools/gpu_extract_call.sh bench
    B=.gpu/bin
    bound=$(( $(left) - 15 ))
    echo "##### sanitizers side by side, each bounded by $bound s" >> "$OUT/summary_all.txt"
    jobs=()
    for tool in memcheck initcheck synccheck; do
        for t in cuda_extract_stream cuda_collection cuda_pool cuda_faults; do jobs+=("$tool $t"); done
    done
    for t in cuda_collection cuda_extract_stream cuda_faults; do jobs+=("racecheck $t"); done
    for job in "${jobs[@]}"; do
        set -- $job
        ( CLATCH_TEST_SCALE=sanitizer timeout "$bound" compute-sanitizer --tool "$1" "$B/$2" \
              > "/tmp/san_$1_$2.txt" 2>&1; echo "rc=$?" > "/tmp/san_$1_$2.rc" ) &
    done
    wait
    for job in "${jobs[@]}"; do
        set -- $job
        f=/tmp/san_$1_$2.txt
        { echo "== $1 $2 (CLATCH_TEST_SCALE=sanitizer) $(cat "/tmp/san_$1_$2.rc")"
          grep -E '^test |^test result|SUMMARY' "$f" | grep -v ' \.\.\. ok$' | tail -20
          grep -qE 'ERROR SUMMARY: 0 errors|RACECHECK SUMMARY: 0 hazards' "$f" || tail -40 "$f"; } >> "$OUT/sanitize.txt"
        echo "$1 $2 $(cat "/tmp/san_$1_$2.rc"): $(grep -E '^test result' "$f" | tail -1 | cut -c1-70) $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' "$f" | tail -1)" >> "$OUT/summary_all.txt"
    done
    ;;
esac
echo "call took $(( $(date +%s) - start )) s" >> "$OUT/summary_all.txt"
cat "$OUT/summary_all.txt"
