#!/usr/bin/env bash
# The GPU suite, on a machine with an NVIDIA GPU (driver for CUDA 13.0 or newer) and the CUDA build
# requirements of the README (nvcc 13.0 through NVCC, CUDA_HOME or PATH; libclang for bindgen).
#
# Builds the test binaries with the `cuda` feature (`cargo test -p clatch --features cuda --no-run`),
# then runs, one after another: every GPU suite (the `cuda_*` test targets), the library's unit tests
# and tests/backend.rs (both have device trials with the feature on), and three variants: the small
# matching trials on the portable popcount kernels (CLATCH_MATCH_KERNEL=popcount), the collection
# and describe trials with kernels loaded from PTX instead of the fatbin (CLATCH_FORCE_PTX=1), and the
# small matching trials with the driver's JIT off (CUDA_DISABLE_PTX_JIT=1: every kernel file must load
# from the fatbin's native code for this GPU, so a build that left its architecture out fails here).
#
#     bash dev/gpu_suite.sh                 build, run everything, print the summary
#     bash dev/gpu_suite.sh NAME...         only these binaries (cuda_match, backend, clatch_unit, ...)
#     bash dev/gpu_suite.sh --build-only    build, and list the binaries (NAME PATH) on stdout
#
# Environment: BINARIES (a "NAME PATH" list of test binaries built elsewhere, as --build-only prints
# it: nothing is built, for a GPU machine without a Rust toolchain), OUT (the log folder, default
# target/gpu-suite), TEST_TIMEOUT (seconds a binary may run,
# default 1800), CLATCH_SOAK_SECONDS (the soak's length, default 5), CLATCH_TEST_SCALE (`sanitizer`
# shrinks every suite's workload, see tests/common/scale.rs).
#
# Logs: $OUT/suite.txt (every binary's output), $OUT/summary.txt (one line a run, printed last).
# Exit status 0 only when every run passed; a suite that reports `skipped: no CUDA device` counts as a
# failure here, since this script exists to run them on a device.
set -uo pipefail
cd "$(dirname "$0")/.."

OUT=${OUT:-target/gpu-suite}
TEST_TIMEOUT=${TEST_TIMEOUT:-1800}

# build: compiles the test binaries and writes "NAME PATH" lines to $OUT/binaries.txt. The library's
# unit tests are named clatch_unit; the integration tests keep their target names.
build() {
    mkdir -p "$OUT"
    cargo test -p clatch --features cuda --no-run --message-format=json-render-diagnostics \
        > "$OUT/build.json" || { echo "build failed (see the messages above)" >&2; return 1; }
    python3 - "$OUT/build.json" > "$OUT/binaries.txt" <<'PY'
import json, sys
for line in open(sys.argv[1]):
    m = json.loads(line)
    if m.get("reason") != "compiler-artifact" or not m.get("executable"):
        continue
    t = m["target"]
    name = "clatch_unit" if t["kind"] == ["lib"] else t["name"]
    if name in ("clatch_unit", "backend") or name.startswith("cuda_"):
        print(name, m["executable"])
PY
    rm -f "$OUT/build.json"
}

if [ -n "${BINARIES:-}" ]; then
    mkdir -p "$OUT"
    [ "$(realpath "$BINARIES")" = "$(realpath -m "$OUT/binaries.txt")" ] || cp "$BINARIES" "$OUT/binaries.txt"
else
    build || exit 1
fi
if [ "${1:-}" = --build-only ]; then
    cat "$OUT/binaries.txt"
    exit 0
fi

bin() { awk -v n="$1" '$1 == n { print $2 }' "$OUT/binaries.txt"; }

if [ $# -gt 0 ]; then
    names=("$@")
else
    # The GPU suites, then the unit tests and tests/backend.rs, the soak last.
    mapfile -t names < <(awk '{ print $1 }' "$OUT/binaries.txt" | grep '^cuda_' | grep -vx cuda_soak | sort)
    names+=(clatch_unit backend)
    grep -q '^cuda_soak ' "$OUT/binaries.txt" && names+=(cuda_soak)
fi

: > "$OUT/suite.txt"
: > "$OUT/summary.txt"
failed=0
{
    if command -v nvidia-smi > /dev/null; then
        nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1
    else
        echo "nvidia-smi not found"
    fi
    echo "commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown), $(date -u +%Y-%m-%dT%H:%MZ)${BINARIES:+ (test binaries built elsewhere: $BINARIES; the commit is that of the checkout, not of the binaries)}"
} | tee -a "$OUT/summary.txt" >> "$OUT/suite.txt"

# run LABEL NAME [ARGS...]: one test binary (environment from the caller), logged and summarised.
run() {
    local label=$1 name=$2; shift 2
    local path; path=$(bin "$name")
    if [ -z "$path" ]; then
        echo "$label: no such test binary" | tee -a "$OUT/summary.txt"; failed=1; return
    fi
    local log; log=$(mktemp)
    local start; start=$(date +%s)
    timeout "$TEST_TIMEOUT" "$path" "$@" > "$log" 2>&1; local rc=$?
    local secs=$(( $(date +%s) - start ))
    { echo "== $label"; cat "$log"; echo "rc=$rc ${secs}s"; } >> "$OUT/suite.txt"
    local verdict=ok
    if grep -q '^skipped: no CUDA device' "$log"; then verdict=SKIPPED; fi
    [ "$rc" -ne 0 ] && verdict=FAILED
    [ "$rc" -eq 124 ] && verdict=TIMEOUT
    [ "$verdict" = ok ] || failed=1
    printf '%-8s %s rc=%s %ss: %s\n' "$verdict" "$label" "$rc" "$secs" \
        "$(grep -E '^test result' "$log" | tail -1)" | tee -a "$OUT/summary.txt"
    rm -f "$log"
}

for name in "${names[@]}"; do
    run "$name" "$name"
done
if [ $# -eq 0 ]; then
    CLATCH_MATCH_KERNEL=popcount run "cuda_match small_* (CLATCH_MATCH_KERNEL=popcount)" cuda_match small_
    CLATCH_FORCE_PTX=1 CLATCH_TEST_SCALE=sanitizer \
        run "cuda_collection (CLATCH_FORCE_PTX=1, CLATCH_TEST_SCALE=sanitizer)" cuda_collection
    CLATCH_FORCE_PTX=1 run "cuda_describe describe_every_width (CLATCH_FORCE_PTX=1)" cuda_describe describe_every_width
    CUDA_DISABLE_PTX_JIT=1 run "cuda_match small_* (CUDA_DISABLE_PTX_JIT=1)" cuda_match small_
fi

echo "logs: $OUT/suite.txt"
if [ $failed -ne 0 ]; then echo "NOT every run passed"; exit 1; fi
echo "every run passed"
