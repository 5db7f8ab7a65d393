#!/usr/bin/env bash
# One device call for the multi-device scheduler (issue 11, part 1): tests/cuda_pool.rs (the one GPU as 1,
# 2 and 4 workers, equal to one device and to the CPU), the one-device collection trials it is compared
# with, and benches/gpu_pool.rs (the scheduler's overhead against the one-device calls). Prepare here:
#     bash tools/pack_gpu_suite.sh
# then with the device tool: run `bash tools/gpu_pool_call.sh`, carry [".gpu"], timeout 600.
# $OUT/pool.txt gets the logs; the last lines printed are the summary.
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" .gpu/bin
[ .gpu/bin/.unpacked -nt .gpu/suite.tar.xz ] || { tar -xJf .gpu/suite.tar.xz -C .gpu/bin && touch .gpu/bin/.unpacked; }
B=.gpu/bin
summary=()
step() { # name timeout command...
    local name=$1 limit=$2; shift 2
    echo "== $name" >> "$OUT/pool.txt"
    timeout "$limit" "$@" >> "$OUT/pool.txt" 2>&1; local rc=$?
    summary+=("$name rc=$rc: $(grep -E '^test result|pool / one device' "$OUT/pool.txt" | tail -1)")
}
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > "$OUT/pool.txt" 2>&1
step cuda_pool 300 "$B/cuda_pool" --nocapture
step "cuda_match match_pairs" 200 "$B/cuda_match" match_pairs_of_a_collection
step "cuda_async batch" 200 "$B/cuda_async" batch_of_images_in_input_order
step bench_gpu_pool 280 "$B/bench_gpu_pool"
grep -E "one device|worker" "$OUT/pool.txt" | tail -12
printf '%s\n' "${summary[@]}" | tee "$OUT/summary.txt"
