#!/usr/bin/env bash
# Device calls for issue 13's matching side: the device-resident DescriptorCollection and the grouped
# kernels of kernels/match_pairs.cu (written without a GPU: this is their first run). Prepare here:
#     bash tools/pack_gpu_suite.sh
# then with the device tool, each part one call, carry [".gpu"] (kind nvidia-h200):
#     run `bash tools/gpu_collection_call.sh tests`  timeout 600  (about 6 min)
#         tests/cuda_collection.rs full, cuda_match (the refactored knn.cuh and knn_tensor.cuh, and
#         match_pairs through the collection), cuda_pool (DevicePool's CUDA workers now grouped), cuda_faults
#         (the collection's allocation sites), the library unit tests; cuda_collection on PTX JIT
#     run `bash tools/gpu_collection_call.sh sanitize`  timeout 600  (about 6 min)
#         cuda_collection whole under memcheck, initcheck, synccheck and racecheck, each with
#         CLATCH_TEST_SCALE=sanitizer, the four side by side (540 s bound each)
#     run `bash tools/gpu_collection_call.sh bench`  timeout 600  (about 8 min)
#         benches/gpu_collection.rs (1000 sets of 5000 and of 2000, 499,500 pairs, ratio + cross-check,
#         against the 64k x 64k single-pair rates) and the PyTorch baseline of the same sizes in the same
#         call (tools/peers.py --collection; each size times the first 100,000 pairs and extrapolates to
#         all 499,500, so that both fit one call: COLLECTION_PAIRS= times all of them)
# $OUT/collection_{tests,sanitize,bench}.txt get the logs; the last lines printed are the summary.
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
    step cuda_pool 200 "$B/cuda_pool"
    step cuda_faults 200 "$B/cuda_faults"
    step clatch_unit 120 "$B/clatch_unit"
    CLATCH_FORCE_PTX=1 CLATCH_TEST_SCALE=sanitizer step "cuda_collection PTX JIT (scaled)" 200 "$B/cuda_collection"
fi
if [ "$part" = sanitize ]; then
    # The four tools side by side (16 cores, one GPU): each bounded by 540 s.
    for tool in memcheck initcheck synccheck racecheck; do
        ( CLATCH_TEST_SCALE=sanitizer timeout 540 compute-sanitizer --tool $tool "$B/cuda_collection" \
              > "/tmp/san_$tool.txt" 2>&1; echo "rc=$?" > "/tmp/san_$tool.rc" ) &
    done
    wait
    for tool in memcheck initcheck synccheck racecheck; do
        { echo "== $tool cuda_collection (scaled)"; tail -n 80 "/tmp/san_$tool.txt"; } >> "$LOG"
        summary+=("$tool cuda_collection (scaled) $(cat "/tmp/san_$tool.rc"): $(grep -E '^test result|ERROR SUMMARY|RACECHECK SUMMARY' "/tmp/san_$tool.txt" | tail -2 | tr '\n' ' ')")
    done
fi
if [ "$part" = bench ]; then
    step bench_gpu_collection 330 "$B/bench_gpu_collection"
    # COLLECTION_PAIRS= (empty) times every pair; split into words on purpose.
    # shellcheck disable=SC2086
    step "peers.py --collection" 240 python3 tools/peers.py --skip-matching --collection \
        ${COLLECTION_PAIRS---collection-pairs 100000} --out "$OUT/peers_collection.json"
fi
grep -E "exhaustive|64k x 64k|sets x|PyTorch" "$LOG" | tail -12
printf '%s\n' "${summary[@]}" | tee "$OUT/summary.txt"
