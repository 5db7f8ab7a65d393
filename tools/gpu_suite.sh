#!/usr/bin/env bash
# The GPU suite on the device machine (see tools/pack_gpu_suite.sh, which builds what it runs): every
# GPU test binary, the library's unit tests, the sanitizers, the bench-only kernels, the stream example
# and the command-line tool on the GPU. Logs go to $OUT: suite.txt (tests), sanitize.txt (summaries),
# tools.txt (example, benches, CLI). The last lines printed are the summary.
#     bash tools/gpu_suite.sh [tests|sanitize|all]     (default all; each part fits one 10-minute call)
#     bash tools/gpu_suite.sh soak [SECONDS]            (tests/cuda_soak.rs for SECONDS, default 570)
#     bash tools/gpu_suite.sh sanitize-all [TOOL...]    (every GPU test binary, whole, under each tool;
#                                                       default memcheck racecheck initcheck synccheck;
#                                                       SAN_TIMEOUT=S bounds each binary's run, default 590;
#                                                       racecheck runs with CLATCH_TEST_SCALE=sanitizer)
#     bash tools/gpu_suite.sh racecheck-parallel [BIN...]
#                                                      (every GPU test binary but the soak, or the BINs named,
#                                                       whole, under racecheck with CLATCH_TEST_SCALE=sanitizer,
#                                                       all at once; SAN_TIMEOUT=S bounds each, default 300;
#                                                       full logs' tails in $OUT/racecheck_BIN.txt)
# CLATCH_TEST_SCALE=sanitizer (tests/common/scale.rs) shrinks the GPU tests' workload (fewer trials,
# smaller images and sets, fewer launches; every kernel and path still compared with the CPU) so that
# racecheck, which tracks every shared-memory access, gets through a whole binary in a few minutes.
# memcheck, initcheck and synccheck run the full workload. Under any sanitizer, cuda_faults reports but
# does not judge the device's free memory after its failed calls (the sanitizer's allocations move it).
set -uo pipefail
cd "$(dirname "$0")/.."
O=${OUT:-/tmp/out}; mkdir -p "$O" .gpu/bin
# Unpacked once per pack: parts run side by side (tools/gpu_sanitize_call.sh) must not rewrite running binaries.
[ .gpu/bin/.unpacked -nt .gpu/suite.tar.xz ] || { tar -xJf .gpu/suite.tar.xz -C .gpu/bin && touch .gpu/bin/.unpacked; }
B=.gpu/bin
part=${1:-all}
summary=()
if [ "$part" = tests ] || [ "$part" = all ]; then
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,memory.total --format=csv > "$O/suite.txt" 2>&1
SUITES="cuda_describe cuda_describe_opencv cuda_detect cuda_match cuda_collection cuda_pyramid cuda_faults cuda_async cuda_extract_stream cuda_pool cuda_soak"
for t in clatch_unit backend $SUITES; do
    echo "== $t" >> "$O/suite.txt"
    start=$(date +%s)
    timeout 400 "$B/$t" >> "$O/suite.txt" 2>&1; rc=$?
    line=$(grep -E "^test result|passed.*failed" "$O/suite.txt" | tail -1)
    summary+=("$t rc=$rc $(( $(date +%s) - start ))s: $line")
done
# The match kernels once more on the portable popcount path, and on PTX JIT instead of the fatbin.
echo "== cuda_match popcount" >> "$O/suite.txt"
CLATCH_MATCH_KERNEL=popcount timeout 300 "$B/cuda_match" small_ >> "$O/suite.txt" 2>&1
summary+=("cuda_match small_ (popcount) rc=$?: $(grep -E '^test result' "$O/suite.txt" | tail -1)")
echo "== cuda_collection PTX" >> "$O/suite.txt"
CLATCH_FORCE_PTX=1 CLATCH_TEST_SCALE=sanitizer timeout 300 "$B/cuda_collection" >> "$O/suite.txt" 2>&1
summary+=("cuda_collection scaled (PTX JIT) rc=$?: $(grep -E '^test result' "$O/suite.txt" | tail -1)")
echo "== cuda_describe PTX" >> "$O/suite.txt"
CLATCH_FORCE_PTX=1 timeout 300 "$B/cuda_describe" describe_every_width >> "$O/suite.txt" 2>&1
summary+=("cuda_describe every_width (PTX JIT) rc=$?: $(grep -E '^test result' "$O/suite.txt" | tail -1)")
fi

san() { # tool binary filter
    echo "== $1 $2 $3" >> "$O/sanitize.txt"
    timeout 240 compute-sanitizer --tool "$1" "$B/$2" "$3" > /tmp/san.txt 2>&1; local rc=$?
    tail -4 /tmp/san.txt >> "$O/sanitize.txt"
    summary+=("sanitizer $1 $2 $3 rc=$rc: $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' /tmp/san.txt | tail -1)")
}
if [ "$part" = sanitize ] || [ "$part" = all ]; then
for tool in memcheck racecheck initcheck synccheck; do san $tool cuda_match sanitizer_subset; done
for tool in memcheck initcheck; do san $tool cuda_async eight_images_in_flight; done
for tool in memcheck initcheck synccheck; do san $tool cuda_extract_stream one_stream_shrinking; done
for tool in memcheck racecheck initcheck synccheck; do san $tool cuda_collection collection_many_blocks; done
for tool in memcheck initcheck racecheck; do
    san $tool cuda_describe describe_sizes_subpixel_and_borders
    san $tool cuda_describe_opencv opencv_borders_and_patch_sizes
done
san memcheck cuda_detect detect_stage_by_stage

{
    echo "== gpu_streams example"; timeout 60 "$B/gpu_streams"; echo "rc $?"
    echo "== clatch demo --backend cuda"; timeout 60 "$B/clatch" demo --backend cuda -o /tmp/demo.png; echo "rc $?"
    echo "== bench gpu_detect"; timeout 120 "$B/bench_gpu_detect"; echo "rc $?"
    echo "== bench gpu_match"; timeout 200 "$B/bench_gpu_match"; echo "rc $?"
    echo "== bench gpu_pool"; timeout 200 "$B/bench_gpu_pool"; echo "rc $?"
    echo "== bench gpu_extract_stream"; timeout 200 "$B/bench_gpu_extract_stream"; echo "rc $?"
    echo "== bench gpu_collection (200 sets)"; CLATCH_COLLECTION_SETS=200 CLATCH_COLLECTION_REPEATS=1 timeout 200 "$B/bench_gpu_collection"; echo "rc $?"
} > "$O/tools.txt" 2>&1
summary+=("tools: $(grep -c '^rc 0' "$O/tools.txt") of 6 exited 0")
fi
if [ "$part" = soak ]; then
    echo "== cuda_soak ${2:-570} s" >> "$O/suite.txt"
    CLATCH_SOAK_SECONDS=${2:-570} timeout 595 "$B/cuda_soak" --nocapture >> "$O/suite.txt" 2>&1
    summary+=("cuda_soak ${2:-570} s rc=$?: $(grep -E 'extractions and matchings|^test result' "$O/suite.txt" | tail -2 | tr '\n' ' ')")
fi
if [ "$part" = sanitize-all ]; then
    shift
    tools=${*:-memcheck racecheck initcheck synccheck}
    for tool in $tools; do
        # racecheck is far slower than the others: the GPU tests shrink their workload for it.
        scale=full
        [ "$tool" = racecheck ] && scale=sanitizer
        # Cheapest first, so a short call still covers the most binaries; SAN_TIMEOUT bounds each run.
        for t in cuda_async cuda_extract_stream cuda_faults cuda_collection cuda_match cuda_pyramid cuda_detect cuda_describe cuda_describe_opencv; do
            start=$(date +%s)
            echo "== $tool $t (whole, CLATCH_TEST_SCALE=$scale)" >> "$O/sanitize.txt"
            log=/tmp/san_$tool.txt
            CLATCH_TEST_SCALE=$scale timeout "${SAN_TIMEOUT:-590}" compute-sanitizer --tool "$tool" "$B/$t" > "$log" 2>&1; rc=$?
            grep -E "^test result|SUMMARY" "$log" >> "$O/sanitize.txt"
            [ $rc -ne 0 ] && { echo "-- $tool $t: last lines"; tail -30 "$log"; } >> "$O/sanitize.txt"
            summary+=("sanitizer $tool $t (whole, $scale) rc=$rc $(( $(date +%s) - start ))s: $(grep -E '^test result' "$log" | tail -1 | cut -c1-60) $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' "$log" | tail -1)")
        done
    done
fi
if [ "$part" = racecheck-parallel ]; then
    shift
    bins=${*:-cuda_async cuda_extract_stream cuda_faults cuda_collection cuda_match cuda_pyramid cuda_detect cuda_describe cuda_describe_opencv}
    mkdir -p /tmp/racecheck
    for t in $bins; do
        (
            start=$(date +%s)
            CLATCH_TEST_SCALE=sanitizer timeout "${SAN_TIMEOUT:-300}" \
                compute-sanitizer --tool racecheck "$B/$t" > "/tmp/racecheck/$t.txt" 2>&1
            echo "rc=$? $(( $(date +%s) - start ))s" > "/tmp/racecheck/$t.rc"
        ) &
    done
    wait
    for t in $bins; do
        log=/tmp/racecheck/$t.txt
        tail -n 400 "$log" > "$O/racecheck_$t.txt"
        echo "== racecheck $t (whole, CLATCH_TEST_SCALE=sanitizer, in parallel) $(cat "/tmp/racecheck/$t.rc")" >> "$O/sanitize.txt"
        grep -E "^test result|SUMMARY" "$log" >> "$O/sanitize.txt"
        summary+=("racecheck $t (whole, scaled, in parallel) $(cat "/tmp/racecheck/$t.rc"): $(grep -E '^test result' "$log" | tail -1 | cut -c1-60) $(grep -E 'RACECHECK SUMMARY|ERROR SUMMARY' "$log" | tail -1)")
    done
fi
printf '%s\n' "${summary[@]}" | tee "$O/summary.txt"
