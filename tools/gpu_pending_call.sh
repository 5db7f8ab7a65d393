#!/usr/bin/env bash
# tools/PENDING_GPU.md's seven calls folded into five device calls (2026-12-02: 30 minutes of device
# time, a fresh start costs one to two of them). Prepare here: bash tools/pack_gpu_suite.sh, then cut
# .gpu/suite.tar.xz into parts that fit a call's 64 MiB (.gpu/part-*.tar.xz, each unpacked into
# .gpu/bin; the whole suite with the JPEG folders is over it), and copy the folders with
# bash tools/pack_gpu_extract.sh --folders-only. Each call runs under timeout 600:
#
#   bash tools/gpu_pending_call.sh verify   (carry a part with every test binary and the collection and
#       pool benches) every GPU suite of the extraction and collection sides
#       (gpu_extract_call.sh tests, gpu_collection_call.sh tests), then issue 13's collection bench with the
#       PyTorch baseline (gpu_collection_call.sh bench, 2 timed runs) and issue 11's pool call
#       (gpu_pool_call.sh). About 9 minutes.
#   bash tools/gpu_pending_call.sh measure  (carry a part with clatch, the extraction and pool benches and
#       the four sanitized binaries, and .gpu/folders) cuda_collection and cuda_pool again (what changed after the
#       verify call), the pool bench, issue 13's extraction bench and real folders (gpu_extract_call.sh
#       bench), then the sanitizers side by side, each bounded by what is left of the call: memcheck,
#       initcheck and synccheck on cuda_extract_stream, cuda_collection, cuda_pool and cuda_faults,
#       racecheck on cuda_collection, cuda_extract_stream and cuda_faults, all with
#       CLATCH_TEST_SCALE=sanitizer. About 9.5 minutes.
#   bash tools/gpu_pending_call.sh candidate  (carry a part with the shipped clatch, the pool bench and the
#       changed test binaries, the candidate's clatch and suites under cand/, and .gpu/folders/herzjesu)
#       a kernel candidate (tools/candidates) against the shipped build: ncu device time of the default
#       extraction at 20k keypoints, two rounds alternating; the pool bench; clatch colmap of Herz-Jesu,
#       CPU against GPU; the PyTorch collection baseline; then side by side the candidate's suites, the
#       changed binaries and the sanitizers still owed. About 3 minutes.
#   bash tools/gpu_pending_call.sh final  (carry a part with every test binary and clatch, and
#       .gpu/img_src/0000.jpg) main as it lands: ncu, CPU = GPU on the photo, every GPU suite, then the
#       sanitizers on the binaries whose host code changed. About 4 minutes.
#   bash tools/gpu_pending_call.sh recheck  (carry a part with clatch and the stream, batch, pool and
#       pyramid suites, and .gpu/folders) those suites, then clatch colmap --no-colmap and clatch
#       extract of both folders, CPU against GPU, outputs compared. About 30 seconds.
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
# A candidate's build (tools/candidates), beside the shipped one.
[ -d .gpu/bin/cand ] && mv .gpu/bin/cand .gpu/cand
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
    # What changed since the verify call first: add_pending (cuda_collection) and the pool's resident
    # sets (cuda_pool, bench_gpu_pool).
    for t in cuda_collection cuda_pool; do
        echo "== $t" >> "$OUT/suite.txt"
        timeout 120 .gpu/bin/$t --nocapture >> "$OUT/suite.txt" 2>&1
        echo "$t rc=$?: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)" >> "$OUT/summary_all.txt"
    done
    grep -E "add_pending" "$OUT/suite.txt" >> "$OUT/summary_all.txt"
    part "pool bench" bash -c 'timeout 200 .gpu/bin/bench_gpu_pool > "$OUT/pool.txt" 2>&1; grep -E "one device|worker" "$OUT/pool.txt" > "$OUT/summary.txt"'
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
candidate)
    # tools/candidates/subpixel-lanes-tile16.patch: its build in .gpu/cand, the shipped one in .gpu/bin.
    # Timing first, nothing else on the device: ncu device time of the default extraction of a
    # 5616x3744 photo at 20k keypoints (issue 9: <= 2 ms), each build twice, alternating; the pool
    # bench; clatch colmap --no-colmap of the Herz-Jesu folder, CPU against GPU; the PyTorch collection
    # baseline. Then, side by side, the candidate's GPU suites of the paths it changes, the shipped
    # binaries changed since the measure call, and the sanitizers still owed.
    IMG=.gpu/img/herzjesu0_5616x3744.png
    if [ ! -f $IMG ]; then
        mkdir -p .gpu/img
        python3 -c "import cv2; im = cv2.imread('.gpu/folders/herzjesu/0000.jpg', cv2.IMREAD_GRAYSCALE); cv2.imwrite('$IMG', cv2.resize(im, (5616, 3744), interpolation=cv2.INTER_CUBIC))"
    fi
    for round in 1 2; do
        for bin in .gpu/bin/clatch .gpu/cand/clatch; do
            echo "== ncu $bin round $round" >> "$OUT/ncu.txt"
            timeout 100 ncu --clock-control none --cache-control none --metrics gpu__time_duration.sum --csv \
                $bin extract --backend cuda $IMG --threshold 10 --max-keypoints 20000 -o /tmp/n > /tmp/ncu.csv 2>&1
            grep -E "keypoints  " /tmp/ncu.csv | head -1 >> "$OUT/ncu.txt"
            python3 tools/ncu_sum.py /tmp/ncu.csv >> "$OUT/ncu.txt" 2>&1
            echo "ncu $bin round $round: $(python3 tools/ncu_sum.py /tmp/ncu.csv 2>&1 | head -1)" >> "$OUT/summary_all.txt"
        done
    done
    part "pool bench" bash -c 'timeout 200 .gpu/bin/bench_gpu_pool > "$OUT/pool.txt" 2>&1; grep -E "one device|worker" "$OUT/pool.txt" > "$OUT/summary.txt"'
    for be in cpu cuda; do
        for round in warm timed; do
            rm -rf /tmp/ws_$be /tmp/db_$be.db
            start_ns=$(date +%s%N)
            timeout 100 .gpu/bin/clatch colmap --images .gpu/folders/herzjesu --database /tmp/db_$be.db \
                --workspace /tmp/ws_$be --no-colmap --force --backend $be > /tmp/colmap_$be.txt 2>&1; rc=$?
            wall=$(( ($(date +%s%N) - start_ns) / 1000000 ))
        done
        { echo "== colmap --no-colmap herzjesu --backend $be rc=$rc whole process ${wall}ms"; cat /tmp/colmap_$be.txt; } >> "$OUT/folders.txt"
        echo "colmap herzjesu $be rc=$rc whole process ${wall}ms: $(grep -E '^  (extract|match) ' /tmp/colmap_$be.txt | sed 's/  */ /g' | tr '\n' ';')" >> "$OUT/summary_all.txt"
    done
    cmp -s /tmp/db_cpu.db /tmp/db_cuda.db && r=identical || r=DIFFER
    echo "colmap herzjesu databases cpu vs cuda: $r" >> "$OUT/summary_all.txt"
    part "PyTorch collection baseline" bash -c 'timeout 150 python3 tools/peers.py --skip-matching --collection --collection-pairs 100000 --out "$OUT/peers_collection.json" > "$OUT/peers.txt" 2>&1; tail -6 "$OUT/peers.txt" > "$OUT/summary.txt"'
    for be in cpu cuda; do .gpu/cand/clatch extract --backend $be $IMG -o /tmp/c_$be > /dev/null 2>&1; done
    for f in keypoints.csv descriptors.npy; do
        cmp -s /tmp/c_cpu.$f /tmp/c_cuda.$f && r=identical || r=DIFFER
        echo "candidate clatch extract of the photo, cpu vs cuda $f: $r" >> "$OUT/summary_all.txt"
    done
    bound=$(( $(left) - 10 ))
    echo "##### side by side, each bounded by $bound s" >> "$OUT/summary_all.txt"
    jobs=("plain cand/cuda_detect" "plain cand/cuda_pyramid" "plain cand/cuda_extract_stream"
          "plain bin/cuda_collection" "plain bin/cuda_pool" "plain bin/cuda_faults" "plain bin/cuda_extract_stream"
          "memcheck bin/cuda_faults" "synccheck bin/cuda_faults" "memcheck bin/cuda_pool"
          "memcheck bin/cuda_extract_stream" "memcheck bin/cuda_collection"
          "racecheck bin/cuda_collection")
    for job in "${jobs[@]}"; do
        set -- $job
        log=/tmp/j_$1_${2//\//_}.txt
        if [ "$1" = plain ]; then
            ( timeout "$bound" .gpu/$2 > "$log" 2>&1; echo "rc=$?" > "$log.rc" ) &
        else
            # racecheck: the trials of kernels added since its last clean run, one at a time.
            filter=(); [ "$1" = racecheck ] && filter=(collection_add_pending_equals_the_cpu)
            ( CLATCH_TEST_SCALE=sanitizer timeout "$bound" compute-sanitizer --tool "$1" --print-limit 100000 \
                  .gpu/$2 "${filter[@]}" > "$log" 2>&1; echo "rc=$?" > "$log.rc" ) &
        fi
    done
    wait
    for job in "${jobs[@]}"; do
        set -- $job
        log=/tmp/j_$1_${2//\//_}.txt
        { echo "== $1 $2 $(cat "$log.rc")"
          grep -E '^test result|SUMMARY|FAILED|panicked|differs|growth sites' "$log" | tail -12
          # Which API calls the sanitizer reported, counted.
          grep -E 'Program hit' "$log" | sed 's/.*due to//' | sort | uniq -c | head -8; } >> "$OUT/sanitize.txt"
        echo "$1 $2 $(cat "$log.rc"): $(grep -E '^test result' "$log" | tail -1 | cut -c1-70) $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' "$log" | tail -1)" >> "$OUT/summary_all.txt"
    done
    ;;
final)
    # Main as it will land (part-final.tar.xz: every test binary and clatch): every GPU suite, the
    # ncu device time of the default extraction at 20k keypoints, then the sanitizers on the binaries
    # whose host code changed, side by side, and the injected-failure trials under memcheck and
    # synccheck with their whole failure reports.
    IMG=.gpu/img/herzjesu0_5616x3744.png
    mkdir -p .gpu/img
    python3 -c "import cv2; im = cv2.imread('.gpu/img_src/0000.jpg', cv2.IMREAD_GRAYSCALE); cv2.imwrite('$IMG', cv2.resize(im, (5616, 3744), interpolation=cv2.INTER_CUBIC))"
    timeout 100 ncu --clock-control none --cache-control none --metrics gpu__time_duration.sum --csv \
        .gpu/bin/clatch extract --backend cuda $IMG --threshold 10 --max-keypoints 20000 -o /tmp/n > /tmp/ncu.csv 2>&1
    { echo "== ncu main"; grep -E "keypoints  " /tmp/ncu.csv | head -1; python3 tools/ncu_sum.py /tmp/ncu.csv; } >> "$OUT/ncu.txt" 2>&1
    echo "ncu main: $(python3 tools/ncu_sum.py /tmp/ncu.csv 2>&1 | head -1)" >> "$OUT/summary_all.txt"
    for be in cpu cuda; do .gpu/bin/clatch extract --backend $be $IMG -o /tmp/c_$be > /dev/null 2>&1; done
    for f in keypoints.csv descriptors.npy; do
        cmp -s /tmp/c_cpu.$f /tmp/c_cuda.$f && r=identical || r=DIFFER
        echo "clatch extract of the photo, cpu vs cuda $f: $r" >> "$OUT/summary_all.txt"
    done
    # The grid's cost per photo (clatch colmap spreads 8192 keypoints over an 8x8 grid): one JPEG,
    # several times in one process, each backend, with and without the grid.
    mkdir -p /tmp/imgs && for i in 1 2 3 4 5 6 7 8; do cp .gpu/img_src/0000.jpg /tmp/imgs/$i.jpg; done
    for be in cpu cuda; do
        for grid in "" "--grid 8 --max-keypoints 8192"; do
            rm -rf /tmp/g && mkdir -p /tmp/g
            timeout 60 .gpu/bin/clatch extract --backend $be /tmp/imgs/*.jpg $grid -o /tmp/g > /tmp/g.txt 2>&1
            echo "extract 8 x 0000.jpg --backend $be $grid: $(grep -E '^  extract' /tmp/g.txt | sed 's/  */ /g')" >> "$OUT/summary_all.txt"
        done
    done
    for t in cuda_extract_stream cuda_collection cuda_pool cuda_faults cuda_async cuda_pyramid cuda_detect \
             cuda_describe cuda_describe_opencv cuda_match cuda_soak clatch_unit backend; do
        echo "== $t" >> "$OUT/suite.txt"
        start_t=$(date +%s)
        timeout 120 .gpu/bin/$t >> "$OUT/suite.txt" 2>&1; rc=$?
        echo "$t rc=$rc $(( $(date +%s) - start_t ))s: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)" >> "$OUT/summary_all.txt"
    done
    CLATCH_FORCE_PTX=1 timeout 60 .gpu/bin/cuda_describe every_width >> "$OUT/suite.txt" 2>&1
    echo "cuda_describe every_width (PTX JIT) rc=$?: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)" >> "$OUT/summary_all.txt"
    bound=$(( $(left) - 10 ))
    echo "##### sanitizers side by side, each bounded by $bound s" >> "$OUT/summary_all.txt"
    jobs=("memcheck cuda_extract_stream" "memcheck cuda_pool" "memcheck cuda_faults" "synccheck cuda_faults"
          "memcheck cuda_collection" "initcheck cuda_collection" "synccheck cuda_collection"
          "racecheck cuda_describe")
    for job in "${jobs[@]}"; do
        set -- $job
        filter=(); [ "$1" = racecheck ] && filter=(describe_sizes_subpixel_and_borders)
        ( CLATCH_TEST_SCALE=sanitizer timeout "$bound" compute-sanitizer --tool "$1" --print-limit 100000 \
              .gpu/bin/$2 "${filter[@]}" > "/tmp/s_$1_$2.txt" 2>&1; echo "rc=$?" > "/tmp/s_$1_$2.txt.rc" ) &
    done
    wait
    for job in "${jobs[@]}"; do
        set -- $job
        log=/tmp/s_$1_$2.txt
        { echo "== $1 $2 (CLATCH_TEST_SCALE=sanitizer) $(cat "$log.rc")"
          grep -E '^test result|SUMMARY' "$log" | tail -3
          sed -n '/^failures:/,/^test result/p' "$log" | head -30
          grep -E 'Program hit|Invalid|Race|Uninitialized|Barrier' "$log" | sed 's/.*due to//' | sort | uniq -c | head -8; } >> "$OUT/sanitize.txt"
        echo "$1 $2 $(cat "$log.rc"): $(grep -E '^test result' "$log" | tail -1 | cut -c1-70) $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' "$log" | tail -1)" >> "$OUT/summary_all.txt"
    done
    ;;
recheck)
    # After the stream's results were read several at a time (src/facade/batch.rs): the suites of the
    # stream, batch and pool paths, then clatch colmap --no-colmap and clatch extract of both folders,
    # CPU against GPU, second of two runs, outputs compared byte for byte. Carries part-recheck.tar.xz
    # and .gpu/folders.
    for t in cuda_extract_stream cuda_async cuda_pool cuda_pyramid; do
        echo "== $t" >> "$OUT/suite.txt"
        timeout 120 .gpu/bin/$t >> "$OUT/suite.txt" 2>&1
        echo "$t rc=$?: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)" >> "$OUT/summary_all.txt"
    done
    for folder in herzjesu sceaux; do
        for be in cpu cuda; do
            for round in warm timed; do
                rm -rf /tmp/ws_$be /tmp/db_$be.db /tmp/f_$be
                start_ns=$(date +%s%N)
                timeout 100 .gpu/bin/clatch colmap --images .gpu/folders/$folder --database /tmp/db_$be.db \
                    --workspace /tmp/ws_$be --no-colmap --force --backend $be > /tmp/colmap_$be.txt 2>&1; rc=$?
                wall=$(( ($(date +%s%N) - start_ns) / 1000000 ))
            done
            { echo "== colmap --no-colmap $folder --backend $be rc=$rc whole process ${wall}ms"; cat /tmp/colmap_$be.txt; } >> "$OUT/folders.txt"
            echo "colmap $folder $be rc=$rc whole process ${wall}ms: $(grep -E '^  (extract|decode|match) ' /tmp/colmap_$be.txt | sed 's/  */ /g' | tr '\n' ';')" >> "$OUT/summary_all.txt"
            start_ns=$(date +%s%N)
            timeout 100 .gpu/bin/clatch extract .gpu/folders/$folder/* -o /tmp/f_$be --backend $be > /tmp/extract_$be.txt 2>&1; rc=$?
            wall=$(( ($(date +%s%N) - start_ns) / 1000000 ))
            { echo "== extract $folder --backend $be rc=$rc whole process ${wall}ms"; cat /tmp/extract_$be.txt; } >> "$OUT/folders.txt"
            echo "extract $folder $be rc=$rc whole process ${wall}ms: $(grep -E '^  extract ' /tmp/extract_$be.txt | sed 's/  */ /g')" >> "$OUT/summary_all.txt"
        done
        cmp -s /tmp/db_cpu.db /tmp/db_cuda.db && r=identical || r=DIFFER
        diff -rq /tmp/f_cpu /tmp/f_cuda > /dev/null && r2=identical || r2=DIFFER
        echo "$folder: colmap databases cpu vs cuda $r; extract files $r2" >> "$OUT/summary_all.txt"
    done
    ;;
esac
echo "call took $(( $(date +%s) - start )) s" >> "$OUT/summary_all.txt"
cat "$OUT/summary_all.txt"
