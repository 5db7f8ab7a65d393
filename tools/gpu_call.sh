#!/usr/bin/env bash
# Device calls, one function per kind of work (tools/gpu_pending_call.sh is the record of the calls of
# 2026-12-02's second session; new calls go here). Prepare here:
#   bash tools/gpu_pack.sh            (test binaries, clatch, benches: .gpu/part-main.tar.xz)
#   bash tools/pack_gpu_extract.sh --folders-only   (.gpu/folders: Herz-Jesu and Sceaux JPEGs)
# then run on the device, under its 600 s limit:
#   bash tools/gpu_call.sh check   carry [.gpu/part-main.tar.xz, .gpu/folders, .gpu/img_src]
#       ncu device time of the default extraction of a 5616x3744 photo at 20k keypoints (issue 9), each
#       build in .gpu/bin and .gpu/old twice, alternating; CPU = GPU on that photo; the grid's cost per
#       photo; both folders CPU against GPU (colmap --no-colmap, extract, outputs compared); the
#       backend's start-up alone; every GPU suite; then the sanitizers side by side, bounded by what
#       is left of the call: memcheck, initcheck and synccheck of every binary whose paths changed,
#       racecheck trial by trial of the binaries a whole-binary run never finished.
#   bash tools/gpu_call.sh final   same carry: main as it lands (see the part's comment).
#   bash tools/gpu_call.sh s5      carry [.gpu/part-main.tar.xz, .gpu/img_src, .gpu/folders]: see its part.
#   bash tools/gpu_call.sh faults  carry [.gpu/part-main.tar.xz]: tools/PENDING_GPU.md item 1.
#   bash tools/gpu_call.sh soak    carry [.gpu/part-main.tar.xz]
#       the soak alone for what is left of the call (its memory samples must not see other processes).
#   bash tools/gpu_call.sh soak-start, then soak-end: a soak of SOAK_SECONDS (default 630) over two
#       calls, the second within the machine's warm window.
# Summaries go to $OUT/summary_all.txt (printed last); logs stay in $OUT (at most 8 files come back).
cd "$(dirname "$0")/.."
export OUT=${OUT:-/tmp/out}
mkdir -p "$OUT" .gpu/bin
start=$(date +%s)
left() { echo $(( ${CALL_SECONDS:-585} - ($(date +%s) - start) )); }
say() { echo "$*" >> "$OUT/summary_all.txt"; }
for tarball in .gpu/part-*.tar.xz; do
    [ -f "$tarball" ] && tar -xJf "$tarball" -C .gpu/bin
done
# An older build to compare with, beside the new one.
[ -d .gpu/bin/old ] && rm -rf .gpu/old && mv .gpu/bin/old .gpu/old
B=.gpu/bin
IMG=.gpu/img/herzjesu0_5616x3744.png

# The 21-megapixel photo of issue 9's bound, made on the device from a Herz-Jesu JPEG.
make_photo() {
    [ -f $IMG ] && return
    mkdir -p .gpu/img
    python3 -c "import cv2; im = cv2.imread('.gpu/img_src/0000.jpg', cv2.IMREAD_GRAYSCALE); cv2.imwrite('$IMG', cv2.resize(im, (5616, 3744), interpolation=cv2.INTER_CUBIC))"
}

# ncu_extract BINARY LABEL: summed kernel time of the default extraction at 20k keypoints.
ncu_extract() {
    timeout 100 ncu --clock-control none --cache-control none --metrics gpu__time_duration.sum --csv \
        "$1" extract --backend cuda $IMG --threshold 10 --max-keypoints 20000 -o /tmp/n > /tmp/ncu.csv 2>&1
    { echo "== ncu $2"; grep -E "keypoints  " /tmp/ncu.csv | head -1; python3 tools/ncu_sum.py /tmp/ncu.csv; } >> "$OUT/ncu.txt" 2>&1
    say "ncu $2: $(python3 tools/ncu_sum.py /tmp/ncu.csv 2>&1 | head -1)"
}

# same_files LABEL A B: whether two outputs are byte for byte the same.
same_files() {
    if diff -rq "$2" "$3" > /dev/null 2>&1; then say "$1: identical"; else say "$1: DIFFER"; fi
}

# photo_identity: clatch extract of the photo on both backends, files compared.
photo_identity() {
    for be in cpu cuda; do $B/clatch extract --backend $be $IMG -o /tmp/c_$be > /dev/null 2>&1; done
    for f in keypoints.csv descriptors.npy; do same_files "photo, cpu vs cuda $f" /tmp/c_cpu.$f /tmp/c_cuda.$f; done
}

# timed LOG COMMAND...: runs it twice (the first warms the page cache and the driver), logs the second
# with its whole-process wall time; sets $rc and $wall.
timed() {
    local log=$1 round; shift
    for round in warm timed; do
        local t0=$(date +%s%N)
        timeout 100 "$@" > "$log" 2>&1; rc=$?
        wall=$(( ($(date +%s%N) - t0) / 1000000 ))
    done
}

# folders NAME...: clatch colmap --no-colmap and clatch extract of each folder, CPU against GPU
# (CLI=another build's clatch, LABEL=its name in the summary).
folders() {
    local cli=${CLI:-$B/clatch} label=${LABEL:+$LABEL }
    for folder in "$@"; do
        for be in cpu cuda; do
            rm -rf /tmp/ws_$be /tmp/db_$be.db
            timed /tmp/colmap_$be.txt $cli colmap --images .gpu/folders/$folder --database /tmp/db_$be.db \
                --workspace /tmp/ws_$be --no-colmap --force --backend $be
            { echo "== ${label}colmap --no-colmap $folder --backend $be rc=$rc whole process ${wall}ms"; cat /tmp/colmap_$be.txt; } >> "$OUT/folders.txt"
            say "${label}colmap $folder $be rc=$rc whole process ${wall}ms: $(grep -E '^  (start|set-up|extract|decode|match|write) ' /tmp/colmap_$be.txt | sed 's/  */ /g' | tr '\n' ';')"
            rm -rf /tmp/f_$be
            timed /tmp/extract_$be.txt $cli extract .gpu/folders/$folder/* -o /tmp/f_$be --backend $be
            { echo "== ${label}extract $folder --backend $be rc=$rc whole process ${wall}ms"; cat /tmp/extract_$be.txt; } >> "$OUT/folders.txt"
            say "${label}extract $folder $be rc=$rc whole process ${wall}ms: $(grep -E '^  (start|extract) ' /tmp/extract_$be.txt | sed 's/  */ /g' | tr '\n' ';')"
        done
        same_files "$folder colmap databases cpu vs cuda" /tmp/db_cpu.db /tmp/db_cuda.db
        same_files "$folder extract files cpu vs cuda" /tmp/f_cpu /tmp/f_cuda
    done
}

# grid_cost BINARY LABEL: 8 copies of one Herz-Jesu JPEG in one process, each backend, with and
# without clatch colmap's 8x8 grid.
grid_cost() {
    mkdir -p /tmp/imgs && for i in 1 2 3 4 5 6 7 8; do cp .gpu/img_src/0000.jpg /tmp/imgs/$i.jpg; done
    for be in cpu cuda; do
        for grid in "" "--grid 8 --max-keypoints 8192"; do
            rm -rf /tmp/g && mkdir -p /tmp/g
            timed /tmp/g.txt "$1" extract --backend $be /tmp/imgs/*.jpg $grid -o /tmp/g
            say "$2 extract 8 x 0000.jpg --backend $be $grid: whole process ${wall}ms;$(grep -E '^  (start|extract) ' /tmp/g.txt | sed 's/  */ /g' | tr '\n' ';')"
        done
    done
}

# suites NAME...: each test binary whole, plainly.
suites() {
    for t in "$@"; do
        echo "== $t" >> "$OUT/suite.txt"
        local t0=$(date +%s)
        timeout 120 $B/$t >> "$OUT/suite.txt" 2>&1; local code=$?
        say "$t rc=$code $(( $(date +%s) - t0 ))s: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)"
    done
}

# sanitize PARALLEL JOB...: each JOB "tool binary [trial]" under compute-sanitizer with
# CLATCH_TEST_SCALE=sanitizer (a tool named plain... runs it plainly, at its usual scale), PARALLEL at a
# time, every one bounded by what is left of the call.
sanitize() {
    local parallel=$1; shift
    local bound=$(( $(left) - 15 ))
    say "##### sanitizers, $parallel at a time, each bounded by the call's end ($bound s from now)"
    local deadline=$(( $(date +%s) + bound ))
    printf '%s\n' "$@" | xargs -P "$parallel" -I{} bash -c '
        set -- {}
        name=$1_$2${3:+_$3}
        rest=$(( '"$deadline"' - $(date +%s) ))
        [ $rest -gt 5 ] || { echo "rc=skipped" > /tmp/s_$name.rc; exit 0; }
        trial=(); [ -n "$3" ] && trial=(--exact "$3")
        case $1 in
        plain*) timeout $rest '"$B"'/$2 "${trial[@]}" > /tmp/s_$name.txt 2>&1 ;;
        *) CLATCH_TEST_SCALE=sanitizer timeout $rest compute-sanitizer --tool $1 --print-limit 1000 \
               '"$B"'/$2 "${trial[@]}" > /tmp/s_$name.txt 2>&1 ;;
        esac
        echo "rc=$?" > /tmp/s_$name.rc'
    for job in "$@"; do
        set -- $job
        local name=$1_$2${3:+_$3} log=/tmp/s_$1_$2${3:+_$3}.txt
        { echo "== $job (CLATCH_TEST_SCALE=sanitizer) $(cat /tmp/s_$name.rc 2>/dev/null)"
          grep -E '^test result|SUMMARY|growth sites|second pass|wrong rows' "$log" 2>/dev/null | tail -6
          sed -n '/^failures:/,/^test result/p' "$log" 2>/dev/null | head -30
          grep -E 'Program hit|Invalid|Race|Uninitialized|Barrier' "$log" 2>/dev/null | sed 's/.*due to//' | sort | uniq -c | head -8; } >> "$OUT/sanitize.txt"
        say "$job $(cat /tmp/s_$name.rc 2>/dev/null): $(grep -E '^test result' "$log" 2>/dev/null | tail -1 | cut -c1-60) $(grep -E 'ERROR SUMMARY|RACECHECK SUMMARY' "$log" 2>/dev/null | tail -1)"
    done
}

# ncu_rounds OLD_LABEL: ncu_extract of .gpu/old (when there) and of main, twice, alternating.
ncu_rounds() {
    for round in 1 2; do
        [ -x .gpu/old/clatch ] && ncu_extract .gpu/old/clatch "$1 round $round"
        ncu_extract $B/clatch "main round $round"
    done
}

# start_up: the backend's set-up alone, one tiny image per backend (CLI, LABEL as for folders).
start_up() {
    python3 -c "import cv2, numpy; cv2.imwrite('/tmp/tiny.png', (numpy.arange(200*200) % 251).astype('uint8').reshape(200, 200))"
    for be in cpu cuda; do
        timed /tmp/tiny_$be.txt ${CLI:-$B/clatch} extract --backend $be /tmp/tiny.png -o /tmp/tiny_$be
        say "${LABEL:+$LABEL }tiny image $be: whole process ${wall}ms; $(grep -E '^  start' /tmp/tiny_$be.txt | sed 's/  */ /g')"
    done
}

# one_photo LABEL CLI: clatch extract of one Herz-Jesu JPEG, each backend (the whole process).
one_photo() {
    for be in cpu cuda; do
        timed /tmp/one_$be.txt "$2" extract --backend $be .gpu/img_src/0000.jpg -o /tmp/one_$be
        say "$1 one photo $be: whole process ${wall}ms; $(grep -E '^  (start|set-up|detect|describe) ' /tmp/one_$be.txt | sed 's/  */ /g' | tr '\n' ';')"
    done
}

# all_suites: every GPU test binary, then the pyramid's from PTX (JIT) instead of the fatbin.
all_suites() {
    suites cuda_pyramid cuda_detect cuda_extract_stream cuda_faults cuda_collection cuda_async cuda_pool \
        cuda_describe cuda_describe_opencv cuda_match clatch_unit backend
    CLATCH_FORCE_PTX=1 timeout 60 $B/cuda_pyramid >> "$OUT/suite.txt" 2>&1
    say "cuda_pyramid (PTX JIT) rc=$?: $(grep -E '^test result' "$OUT/suite.txt" | tail -1)"
}

# trials BINARY: its trial names.
trials() { $B/$1 --list 2>/dev/null | sed -n 's/: test$//p'; }

case "${1:-check}" in
check)
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    make_photo
    ncu_rounds "old (fb8ab9b)"
    photo_identity
    grid_cost $B/clatch main
    [ -x .gpu/old/clatch ] && grid_cost .gpu/old/clatch old
    folders herzjesu sceaux
    start_up
    # The failing trial first, plainly and under synccheck, with its diagnosis.
    CLATCH_TEST_SCALE=sanitizer timeout 120 compute-sanitizer --tool synccheck $B/cuda_faults --exact arena_growth_fails_cleanly > /tmp/arena.txt 2>&1
    { echo "== synccheck arena_growth_fails_cleanly rc=$?"; grep -E 'differs|growth sites|^test result|SUMMARY' /tmp/arena.txt; } >> "$OUT/sanitize.txt"
    say "synccheck arena_growth: $(grep -E '^test result' /tmp/arena.txt | cut -c1-40) $(grep -oE 'of the [0-9]+ wrong rows.*bits' /tmp/arena.txt | head -1)"
    all_suites
    jobs=()
    for tool in memcheck initcheck synccheck; do
        for t in cuda_pyramid cuda_detect cuda_extract_stream cuda_faults cuda_collection cuda_async cuda_pool; do
            jobs+=("$tool $t")
        done
    done
    for t in cuda_pyramid cuda_detect; do jobs+=("racecheck $t"); done
    for t in cuda_collection cuda_extract_stream cuda_faults; do
        for trial in $(trials $t); do jobs+=("racecheck $t $trial"); done
    done
    sanitize 12 "${jobs[@]}"
    ;;
final)
    # Main as it lands: issue 9's bound against the commit before (.gpu/old), CPU = GPU on the photo,
    # the real folders and the start-up, every GPU suite, then the sanitizers of the changed kernels
    # and host code. arena_growth_fails_cleanly (it fails only under a loaded sanitizer) also runs
    # with launches serialised (CUDA_LAUNCH_BLOCKING=1: the host cannot run ahead) and plainly three
    # times among the sanitizer jobs (a loaded device, no sanitizer): a race of host and device shows
    # in the second and not the first.
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    make_photo
    ncu_rounds "previous commit"
    photo_identity
    start_up
    folders herzjesu sceaux
    grid_cost $B/clatch main
    CUDA_LAUNCH_BLOCKING=1 CLATCH_TEST_SCALE=sanitizer timeout 60 $B/cuda_faults --exact arena_growth_fails_cleanly > /tmp/blocking.txt 2>&1
    say "arena_growth with CUDA_LAUNCH_BLOCKING=1 rc=$?: $(grep -E '^test result' /tmp/blocking.txt | cut -c1-40) $(grep -oE 'of the [0-9]+ wrong rows.*bits' /tmp/blocking.txt | head -1)"
    all_suites
    jobs=()
    for tool in memcheck initcheck synccheck; do
        for t in cuda_pyramid cuda_detect cuda_extract_stream cuda_faults; do jobs+=("$tool $t"); done
    done
    for i in 1 2 3; do jobs+=("plain$i cuda_faults arena_growth_fails_cleanly"); done
    for trial in $(trials cuda_pyramid); do jobs+=("racecheck cuda_pyramid $trial"); done
    jobs+=("racecheck cuda_detect subpixel_offsets_every_pixel_and_border_equal_cpu"
           "racecheck cuda_extract_stream warm_streams_allocate_nothing"
           "racecheck cuda_extract_stream large_images_arrive_in_bands"
           "racecheck cuda_faults arena_growth_fails_cleanly"
           "racecheck cuda_faults every_allocation_site_fails_cleanly")
    sanitize 12 "${jobs[@]}"
    ;;
faults)
    # tools/PENDING_GPU.md item 1: whole-binary cuda_faults (its trials now one at a time) under
    # memcheck, initcheck and synccheck, among other binaries' sanitizer runs: the load under which
    # arena_growth_fails_cleanly failed while every_allocation_site_fails_cleanly ran beside it.
    jobs=()
    for tool in memcheck initcheck synccheck; do
        for t in cuda_faults cuda_pyramid cuda_detect cuda_extract_stream cuda_collection; do
            jobs+=("$tool $t")
        done
    done
    sanitize 12 "${jobs[@]}"
    ;;
s5)
    # Fifth session of 2026-12-02: the cross-check's new column reduction (kernels/knn_tensor.cuh) through
    # the suites and the exhaustive-matching bench; the CLI's set-up overlapped with decoding
    # (Backend::start) against the build before it (.gpu/old, OLD=5e362bb), folders, one photo and a
    # tiny image; then the sanitizers of the changed kernel and host code.
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    suites cuda_match cuda_collection backend cuda_pool clatch_unit cuda_extract_stream
    for round in 1 2; do
        one_photo "main" $B/clatch
        [ -x .gpu/old/clatch ] && one_photo "old" .gpu/old/clatch
    done
    folders herzjesu sceaux
    [ -x .gpu/old/clatch ] && CLI=.gpu/old/clatch LABEL=old folders herzjesu sceaux
    start_up
    [ -x .gpu/old/clatch ] && CLI=.gpu/old/clatch LABEL=old start_up
    CLATCH_COLLECTION_REPEATS=2 timeout 200 $B/bench_gpu_collection > "$OUT/collection_bench.txt" 2>&1
    say "bench_gpu_collection rc=$?:"
    grep -E "64k x 64k|sets x|exhaustive|checked|differ" "$OUT/collection_bench.txt" >> "$OUT/summary_all.txt"
    jobs=()
    for tool in memcheck racecheck synccheck initcheck; do
        jobs+=("$tool cuda_match sanitizer_subset" "$tool cuda_collection collection_exhaustive_512_bits"
               "$tool cuda_collection collection_search")
    done
    jobs+=("memcheck backend" "initcheck backend" "synccheck backend" "racecheck backend"
           "memcheck cuda_match" "synccheck cuda_match" "memcheck cuda_collection" "synccheck cuda_collection")
    sanitize 12 "${jobs[@]}"
    ;;
suites)
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    all_suites
    ;;
modules)
    # The driver's module loading, lazy (each kernel loaded at its first launch, on the caller's
    # clock) against eager (everything in the set-up, which now runs beside decoding): folders, one
    # photo and a tiny image, two rounds alternating.
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    for round in 1 2; do
        for mode in LAZY EAGER; do
            export CUDA_MODULE_LOADING=$mode
            LABEL="$mode r$round" folders herzjesu sceaux
            one_photo "$mode r$round" $B/clatch
            LABEL="$mode r$round" start_up
        done
    done
    unset CUDA_MODULE_LOADING
    ;;
soak)
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    seconds=$(( $(left) - 25 ))
    CLATCH_SOAK_SECONDS=$seconds timeout $(( seconds + 20 )) $B/cuda_soak --nocapture > "$OUT/soak.txt" 2>&1
    say "cuda_soak ${seconds} s rc=$?: $(grep -E '^test result' "$OUT/soak.txt")"
    grep -E 'extractions|free device memory|fell|did not come back|differ' "$OUT/soak.txt" >> "$OUT/summary_all.txt"
    ;;
soak-start)
    # A soak longer than one call (the device allows 600 s a call): started in a process session of
    # its own (setsid), which outlives the call while the machine stays held, from a copy of the
    # binary (the next call's unpacking replaces .gpu/bin); this call then sleeps out its time.
    # Follow with `soak-end` within the machine's 30-s warm window.
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >> "$OUT/summary_all.txt" 2>&1
    cp $B/cuda_soak /tmp/cuda_soak_long
    rm -f /tmp/soak_long.rc
    setsid bash -c "CLATCH_SOAK_SECONDS=${SOAK_SECONDS:-630} /tmp/cuda_soak_long --nocapture > /tmp/soak_long.txt 2>&1; echo rc=\$? > /tmp/soak_long.rc" < /dev/null > /dev/null 2>&1 &
    sleep $(( $(left) - 5 ))
    say "soak of ${SOAK_SECONDS:-630} s running: $(tail -c 300 /tmp/soak_long.txt | tr '\n' ' ')"
    ;;
soak-end)
    while [ ! -f /tmp/soak_long.rc ] && [ "$(left)" -gt 10 ]; do sleep 5; done
    cp /tmp/soak_long.txt "$OUT/soak.txt" 2>/dev/null
    say "long soak $(cat /tmp/soak_long.rc 2>/dev/null || echo 'not finished'): $(grep -E '^test result' "$OUT/soak.txt")"
    grep -E 'extractions|free device memory|fell|did not come back|differ|grew' "$OUT/soak.txt" >> "$OUT/summary_all.txt"
    ;;
esac
say "call took $(( $(date +%s) - start )) s"
cat "$OUT/summary_all.txt"
