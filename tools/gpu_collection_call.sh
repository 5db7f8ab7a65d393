#!/usr/bin/env bash
# Device calls for issue 13's matching side: the device-resident DescriptorCollection and the grouped
# kernels of kernels/match_pairs.cu (written without a GPU: this is their first run). Prepare here:
#     bash tools/pack_gpu_suite.sh
# then with the device tool, each part one call, carry [".gpu"] (kind nvidia-h200):
#     run `bash tools/gpu_collection_call.sh tests`  timeout 600  (about 6 min)
#         tests/cuda_collection.rs full, cuda_match (the refactored knn.cuh and match_pairs through the
#         collection), the library unit tests; cuda_collection under memcheck, initcheck, synccheck (full)
#         and racecheck (CLATCH_TEST_SCALE=sanitizer); cuda_collection on PTX JIT
#     run `bash tools/gpu_collection_call.sh bench`  timeout 600  (about 8 min)
#         benches/gpu_collection.rs (1000 sets of 5000 and of 2000, 499,500 pairs, ratio + cross-check,
#         against the 64k x 64k single-pair rates) and the PyTorch baseline of the same sizes in the same
#         call (tools/peers.py --collection; its 5000 run times the first 100,000 pairs and extrapolates,
#         so that both fit one call: COLLECTION_PAIRS= for all of them)
# $OUT/collection_{tests,bench}.txt get the logs; the last lines printed are the summary.
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" .gpu/bin
[ .gpu/bin/.unpacked -nt .gpu/suite.tar.xz ] || { tar -xJf .gpu/suite.tar.xz -C .gpu/bin && touch .gpu/bin/.unpacked; }
B=.gpu/bin
part=${1:-tests}
LOG="$OUT/collection_$part.txt"
summary=()
step() { # name timeout command...
    local name=$1 limit=$2; shift 2
    echo "== $name" >> "$LOG"
    local start=$(date +%s)
    timeout "$limit" "$@" > /tmp/step.txt 2>&1; local rc=$?
    cat /tmp/step.txt >> "$LOG"
    summary+=("$name rc=$rc $(( $(date +%s) - start ))s: $(grep -E '^test result|ERROR SUMMARY|RACECHECK SUMMARY|exhaustive|collection peers|sets x' /tmp/step.txt | tail -3 | tr '\n' ' ')")
}
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,memory.total --format=csv > "$LOG" 2>&1
if [ "$part" = tests ]; then
    step cuda_collection 240 "$B/cuda_collection" --nocapture
    step cuda_match 300 "$B/cuda_match"
    step clatch_unit 120 "$B/clatch_unit"
    for tool in memcheck initcheck synccheck; do
        step "$tool cuda_collection" 300 compute-sanitizer --tool $tool "$B/cuda_collection" collection_many_blocks collection_search collection_tile_boundaries
    done
    CLATCH_TEST_SCALE=sanitizer step "racecheck cuda_collection (scaled)" 300 compute-sanitizer --tool racecheck "$B/cuda_collection"
    CLATCH_FORCE_PTX=1 CLATCH_TEST_SCALE=sanitizer step "cuda_collection PTX JIT (scaled)" 200 "$B/cuda_collection"
fi
if [ "$part" = bench ]; then
    step bench_gpu_collection 420 "$B/bench_gpu_collection"
    step "peers.py --collection" 420 python3 tools/peers.py --skip-matching --collection \
        ${COLLECTION_PAIRS-"--collection-pairs 100000"} --out "$OUT/peers_collection.json"
fi
grep -E "exhaustive|64k x 64k|sets x|PyTorch" "$LOG" | tail -12
printf '%s\n' "${summary[@]}" | tee "$OUT/summary.txt"
