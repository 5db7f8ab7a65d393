#!/usr/bin/env bash
# Device calls for issue 13's extraction side (per-stream scratch arenas, pinned staging and read-back,
# the image stream API, page-locked images copied straight, the CLI on the stream). Two calls:
#
# 1. Correctness. Prepare here: bash tools/pack_gpu_suite.sh
#    then with the device tool: run `bash tools/gpu_extract_call.sh tests`, carry [".gpu/suite.tar.xz"],
#    timeout 600 (about 5 minutes): every GPU suite but the soak, the changed paths first
#    (tests/cuda_extract_stream.rs: no allocation when warm, shrinking and growing sizes, iterator
#    stream, pinned and pageable, images in bands, threads on one stream; cuda_faults with cold starts
#    and the arena-growth trial). Log: $OUT/suite.txt. Then `bash tools/gpu_extract_call.sh sanitize`,
#    same carry (about 8 minutes): memcheck, initcheck and synccheck with CLATCH_TEST_SCALE=sanitizer
#    on the banded-upload, panic and release trials of cuda_extract_stream one by one, then on the
#    whole of cuda_extract_stream and cuda_faults. Log: $OUT/sanitize.txt.
#
# 2. Measurements. Prepare here: bash tools/pack_gpu_extract.sh
#    then: run `bash tools/gpu_extract_call.sh bench`, carry [".gpu/extract.tar.xz", ".gpu/folders"],
#    timeout 600 (about 5 minutes). benches/gpu_extract_stream.rs (1080p frame stream from page-locked
#    memory against the device bound; the 21 MP photo, pageable and page-locked, whole call), then on the
#    real folders (Sceaux 11 photos, Herz-Jesu 8) `clatch colmap --no-colmap` and `clatch extract` of the
#    whole folder, --backend cuda against --backend cpu, each printing images/s, pairs/s and the decode
#    time summed over the decoding threads with how long extraction waited for it; CPU and GPU feature
#    files compared byte for byte. Logs: $OUT/bench.txt, $OUT/folders.txt.
#
# The last lines printed are the summary ($OUT/summary.txt).
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
part=${1:-tests}
summary=()
if [ "$part" = tests ]; then
    mkdir -p .gpu/bin
    [ .gpu/bin/.unpacked -nt .gpu/suite.tar.xz ] || { tar -xJf .gpu/suite.tar.xz -C .gpu/bin && touch .gpu/bin/.unpacked; }
    B=.gpu/bin
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > "$OUT/suite.txt" 2>&1
    # The changed paths first, so that a short call still answers the main question.
    for t in cuda_extract_stream cuda_faults cuda_async cuda_pyramid cuda_detect cuda_describe \
             cuda_describe_opencv cuda_match cuda_pool clatch_unit backend; do
        echo "== $t" >> "$OUT/suite.txt"
        start=$(date +%s)
        timeout "${TEST_LIMIT:-240}" "$B/$t" >> "$OUT/suite.txt" 2>&1; rc=$?
        summary+=("$t rc=$rc $(( $(date +%s) - start ))s: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)")
    done
    grep -E "allocations|growth sites|streamed|page-locked|on one stream|in bands|released|panics" "$OUT/suite.txt" | head -30
fi
if [ "$part" = sanitize ]; then
    mkdir -p .gpu/bin
    [ .gpu/bin/.unpacked -nt .gpu/suite.tar.xz ] || { tar -xJf .gpu/suite.tar.xz -C .gpu/bin && touch .gpu/bin/.unpacked; }
    B=.gpu/bin
    for tool in memcheck initcheck synccheck; do
        # The banded upload (2100x2100 at this scale: 2 bands on the copy stream), the panics that
        # must wait for copies reading page-locked images, and the release call, each on its own
        # first, so that a whole-binary run cut short by its timeout cannot hide them.
        for trial in large_images_arrive_in_bands a_panic_in_a_stream_waits_for_the_copies release_cached_memory; do
            echo "== $tool cuda_extract_stream $trial (CLATCH_TEST_SCALE=sanitizer)" >> "$OUT/sanitize.txt"
            CLATCH_TEST_SCALE=sanitizer timeout 150 compute-sanitizer --tool "$tool" "$B/cuda_extract_stream" --exact "$trial" > /tmp/san.txt 2>&1; rc=$?
            grep -E "^test result|SUMMARY|in bands|released|panics" /tmp/san.txt >> "$OUT/sanitize.txt"
            [ $rc -ne 0 ] && tail -30 /tmp/san.txt >> "$OUT/sanitize.txt"
            summary+=("$tool $trial rc=$rc: $(grep -E '^test result' /tmp/san.txt | tail -1 | cut -c1-60) $(grep -E 'ERROR SUMMARY' /tmp/san.txt | tail -1)")
        done
        for t in cuda_extract_stream cuda_faults; do
            echo "== $tool $t (CLATCH_TEST_SCALE=sanitizer)" >> "$OUT/sanitize.txt"
            CLATCH_TEST_SCALE=sanitizer timeout 80 compute-sanitizer --tool "$tool" "$B/$t" > /tmp/san.txt 2>&1; rc=$?
            grep -E "^test result|SUMMARY" /tmp/san.txt >> "$OUT/sanitize.txt"
            [ $rc -ne 0 ] && tail -30 /tmp/san.txt >> "$OUT/sanitize.txt"
            summary+=("$tool $t rc=$rc: $(grep -E '^test result' /tmp/san.txt | tail -1 | cut -c1-60) $(grep -E 'ERROR SUMMARY' /tmp/san.txt | tail -1)")
        done
    done
fi
if [ "$part" = bench ]; then
    mkdir -p .gpu/xbin
    [ .gpu/xbin/.unpacked -nt .gpu/extract.tar.xz ] || { tar -xJf .gpu/extract.tar.xz -C .gpu/xbin && touch .gpu/xbin/.unpacked; }
    B=.gpu/xbin
    { nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; nproc; } > "$OUT/bench.txt" 2>&1
    timeout 240 "$B/bench_gpu_extract_stream" >> "$OUT/bench.txt" 2>&1
    summary+=("bench gpu_extract_stream rc=$?")
    while read -r line; do summary+=("$line"); done < <(grep -E "^frame stream|^photo" "$OUT/bench.txt")
    : > "$OUT/folders.txt"
    for folder in sceaux herzjesu; do
        dir=.gpu/folders/$folder
        for be in cpu cuda; do
            # A first run warms the page cache (and the GPU's context); the second is timed.
            for round in warm timed; do
                rm -rf "/tmp/ws_${folder}_$be" "/tmp/db_${folder}_$be.db"
                start=$(date +%s%N)
                timeout 200 "$B/clatch" colmap --images "$dir" --database "/tmp/db_${folder}_$be.db" \
                    --workspace "/tmp/ws_${folder}_$be" --no-colmap --force --backend "$be" > /tmp/colmap.txt 2>&1; rc=$?
                wall=$(( ($(date +%s%N) - start) / 1000000 ))ms
            done
            { echo "== colmap --no-colmap $folder --backend $be rc=$rc whole process $wall"; cat /tmp/colmap.txt; } >> "$OUT/folders.txt"
            summary+=("colmap $folder $be rc=$rc whole process $wall: $(grep -E '^  (extract|decode|match) ' /tmp/colmap.txt | sed 's/  */ /g' | tr '\n' ';')")
            rm -rf "/tmp/f_${folder}_$be"
            start=$(date +%s%N)
            timeout 200 "$B/clatch" extract "$dir"/* -o "/tmp/f_${folder}_$be" --backend "$be" > /tmp/extract.txt 2>&1; rc=$?
            wall=$(( ($(date +%s%N) - start) / 1000000 ))ms
            { echo "== extract $folder/* --backend $be rc=$rc whole process $wall"; cat /tmp/extract.txt; } >> "$OUT/folders.txt"
            summary+=("extract $folder $be rc=$rc whole process $wall: $(grep -E '^  (extract|decode) ' /tmp/extract.txt | sed 's/  */ /g' | tr '\n' ';')")
        done
        if diff -r "/tmp/f_${folder}_cpu" "/tmp/f_${folder}_cuda" > /dev/null; then
            summary+=("extract $folder: every CPU and GPU file identical")
        else
            summary+=("extract $folder: CPU and GPU files DIFFER")
        fi
    done
    # One photo, one process (the issue's 574 ms against 163 ms: process start and context included).
    one=$(ls .gpu/folders/herzjesu/* | head -1)
    for be in cpu cuda; do
        start=$(date +%s%N)
        "$B/clatch" extract "$one" -o /tmp/one_$be --backend $be > /tmp/one.txt 2>&1; rc=$?
        wall=$(( ($(date +%s%N) - start) / 1000000 ))ms
        { echo "== extract one photo --backend $be rc=$rc whole process $wall"; cat /tmp/one.txt; } >> "$OUT/folders.txt"
        summary+=("extract one photo $be rc=$rc whole process $wall")
    done
fi
printf '%s\n' "${summary[@]}" | tee "$OUT/summary.txt"
