#!/usr/bin/env bash
# Every GPU test binary, whole, under each of compute-sanitizer's four tools: memcheck, racecheck,
# initcheck and synccheck. Needs what dev/gpu_suite.sh needs, plus compute-sanitizer (part of the CUDA
# toolkit; found on PATH, under CUDA_HOME/bin or /usr/local/cuda/bin, or named by COMPUTE_SANITIZER).
#
# The binaries are built by `dev/gpu_suite.sh --build-only`. The four tools run side by side, each
# going through the binaries one after another. memcheck, initcheck and synccheck run the full
# workload; racecheck tracks every shared-memory access, so for it the suites run with
# CLATCH_TEST_SCALE=sanitizer (tests/common/scale.rs: fewer random trials, smaller images and sets,
# fewer launches, yet every kernel and path still compared bit for bit with the CPU).
#
#     bash dev/sanitize.sh                  every cuda_* binary but the soak, under all four tools
#     bash dev/sanitize.sh NAME...          only these binaries (cuda_match, backend, clatch_unit, ...)
#     TOOLS="memcheck racecheck" bash dev/sanitize.sh cuda_detect
#
# Environment: BINARIES (prebuilt binaries, as for dev/gpu_suite.sh), OUT (default target/sanitize),
# SCALE (the workload of memcheck, initcheck and synccheck: default full, or sanitizer), TOOLS (default all four), SAN_TIMEOUT (seconds one
# binary may run under one tool, default 3600), RACECHECK_SCALE (default sanitizer; `full` for the
# normal workload), SEQUENTIAL=1 (the tools one after another instead of side by side, for a GPU with
# little memory), JOBS=N (every tool-and-binary run as its own job, N at a time: all binaries side by
# side, which is what lets the whole set finish within minutes on a large GPU and many cores), TRIALS=1
# with JOBS (every test function of every binary as its own job: a binary's trials side by side, so
# the whole set takes about as long as its slowest trial), TRIAL_MATCH=REGEX with TRIALS=1 (only the
# trials whose names match the extended regular expression, to run again the ones that failed).
#
# Logs: $OUT/TOOL/NAME.txt or, with TRIALS=1, $OUT/TOOL/NAME.TRIAL.txt (each run's whole output),
# $OUT/progress.txt (each run's summary line as it ends), $OUT/summary.txt (one line a run, printed last).
# A run passes when the binary exits 0 and the tool reports no error (racecheck: no hazard). The one
# error memcheck reports in cuda_faults is expected: that suite asks for 4 TiB on purpose and checks
# that the out-of-memory answer leaves the device usable; out-of-memory answers of the driver are
# counted apart in the summary and do not fail a run that passed.
set -uo pipefail
cd "$(dirname "$0")/.."

OUT=${OUT:-target/sanitize}
TOOLS=${TOOLS:-memcheck racecheck initcheck synccheck}
SAN_TIMEOUT=${SAN_TIMEOUT:-3600}

san=${COMPUTE_SANITIZER:-}
if [ -z "$san" ]; then
    for c in compute-sanitizer "${CUDA_HOME:-/nonexistent}/bin/compute-sanitizer" /usr/local/cuda/bin/compute-sanitizer; do
        if command -v "$c" > /dev/null 2>&1; then san=$(command -v "$c"); break; fi
    done
fi
[ -n "$san" ] || { echo "compute-sanitizer not found: put it on PATH or set COMPUTE_SANITIZER" >&2; exit 1; }

mkdir -p "$OUT"
OUT="$OUT/build" BINARIES="${BINARIES:-}" bash dev/gpu_suite.sh --build-only > /dev/null || exit 1
list="$OUT/build/binaries.txt"
if [ $# -gt 0 ]; then
    names=("$@")
else
    mapfile -t names < <(awk '{ print $1 }' "$list" | grep '^cuda_' | grep -vx cuda_soak | sort)
fi
for name in "${names[@]}"; do
    awk -v n="$name" '$1 == n { found = 1 } END { exit !found }' "$list" \
        || { echo "no such test binary: $name" >&2; exit 1; }
done

# one TOOL NAME [TRIAL]: the binary (or one trial of it) under the tool; writes its summary line to
# $OUT/TOOL/runs/, gathered into $OUT/TOOL/summary.txt at the end.
one() {
    local tool=$1 name=$2 trial=${3:-}
    local path; path=$(awk -v n="$name" '$1 == n { print $2 }' "$list")
    local scale=${SCALE:-full}
    [ "$tool" = racecheck ] && scale=${RACECHECK_SCALE:-sanitizer}
    local label=$name args=()
    if [ -n "$trial" ]; then label="$name.$trial"; args=(--exact "$trial"); fi
    local log="$OUT/$tool/$label.txt"
    local start; start=$(date +%s)
    CLATCH_TEST_SCALE=$scale timeout "$SAN_TIMEOUT" "$san" --tool "$tool" --print-limit 1000 "$path" "${args[@]}" \
        > "$log" 2>&1
    local rc=$?
    local secs=$(( $(date +%s) - start ))
    local result; result=$(grep -E '^test result' "$log" | tail -1 | sed 's/; [0-9]* measured.*//')
    local summary errors oom=0 verdict=ok
    if [ "$tool" = racecheck ]; then
        summary=$(grep -E 'RACECHECK SUMMARY' "$log" | tail -1 | sed 's/^=* *//')
        errors=$(sed -n 's/.*RACECHECK SUMMARY: \([0-9]*\) hazard.*/\1/p' <<< "$summary")
    else
        summary=$(grep -E 'ERROR SUMMARY: [0-9]+ errors?$' "$log" | tail -1 | sed 's/^=* *//')
        errors=$(sed -n 's/.*ERROR SUMMARY: \([0-9]*\) error.*/\1/p' <<< "$summary")
        oom=$(grep -c 'Program hit CUDA_ERROR_OUT_OF_MEMORY' "$log")
    fi
    if grep -q '^skipped: no CUDA device' "$log"; then verdict=SKIPPED
    elif [ "$rc" -eq 124 ]; then verdict=TIMEOUT
    elif [ "$rc" -ne 0 ]; then verdict=FAILED
    elif [ -z "$errors" ]; then verdict=FAILED; summary="no sanitizer summary"
    elif [ $(( errors - oom )) -gt 0 ]; then verdict=ERRORS
    fi
    local note=""
    [ "$oom" -gt 0 ] && note=" ($oom of them out-of-memory answers to a deliberate request)"
    printf '%-8s %-9s %s (CLATCH_TEST_SCALE=%s) rc=%s %ss: %s | %s%s\n' "$verdict" "$tool" "$label" \
        "$scale" "$rc" "$secs" "${result:-no test result}" "${summary:-no sanitizer summary}" "$note" \
        > "$OUT/$tool/runs/$label"
    # One line appended as each run ends, so a session cut short still shows what finished.
    cat "$OUT/$tool/runs/$label" >> "$OUT/progress.txt"
}

# trials NAME: the names of the binary's test functions (an ignored one stays ignored when run).
trials() {
    local path; path=$(awk -v n="$1" '$1 == n { print $2 }' "$list")
    "$path" --list --format terse 2> /dev/null | sed -n 's/: test$//p' | grep -E -- "${TRIAL_MATCH:-.}"
}

# sequence TOOL: every binary under the tool, one after another.
sequence() {
    local tool=$1
    for name in "${names[@]}"; do one "$tool" "$name"; done
}

{
    if command -v nvidia-smi > /dev/null; then
        nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1
    else
        echo "nvidia-smi not found"
    fi
    "$san" --version | grep -i version | tail -1
    echo "commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown), $(date -u +%Y-%m-%dT%H:%MZ)${BINARIES:+ (test binaries built elsewhere: $BINARIES; the commit is that of the checkout, not of the binaries)}"
} > "$OUT/summary.txt"
: > "$OUT/progress.txt"
for tool in $TOOLS; do
    rm -rf "$OUT/$tool"
    mkdir -p "$OUT/$tool/runs"
done
if [ -n "${JOBS:-}" ]; then
    # Every (tool, binary) pair as its own job, or with TRIALS=1 every (tool, binary, trial), JOBS at a
    # time. Racecheck first: it is the slowest tool.
    jobs_list=()
    for tool in racecheck memcheck initcheck synccheck; do
        [[ " $TOOLS " == *" $tool "* ]] || continue
        for name in "${names[@]}"; do
            if [ "${TRIALS:-0}" = 1 ]; then
                while read -r trial; do jobs_list+=("$tool $name $trial"); done < <(trials "$name")
            else
                jobs_list+=("$tool $name")
            fi
        done
    done
    running=0
    for job in "${jobs_list[@]}"; do
        # shellcheck disable=SC2086 # the job's words are the arguments
        one $job &
        running=$(( running + 1 ))
        if [ "$running" -ge "$JOBS" ]; then wait -n; running=$(( running - 1 )); fi
    done
    wait
else
    for tool in $TOOLS; do
        if [ "${SEQUENTIAL:-0}" = 1 ]; then sequence "$tool"; else sequence "$tool" & fi
    done
    wait
fi
bad=0
for tool in $TOOLS; do
    cat "$OUT/$tool"/runs/* > "$OUT/$tool/summary.txt" 2>/dev/null
    rm -rf "$OUT/$tool/runs"
    cat "$OUT/$tool/summary.txt" >> "$OUT/summary.txt"
    bad=$(( bad + $(grep -vc '^ok ' "$OUT/$tool/summary.txt") ))
done
cat "$OUT/summary.txt"
echo "logs: $OUT/TOOL/NAME.txt"
if [ "$bad" -ne 0 ]; then echo "$bad run(s) did not pass"; exit 1; fi
echo "every run passed"
