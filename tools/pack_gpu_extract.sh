#!/usr/bin/env bash
# Builds, here (no GPU needed), what the second call of tools/gpu_extract_call.sh runs, into .gpu/
# (git-ignored): .gpu/extract.tar.xz (the command-line tool and the gpu_extract_stream bench, with the
# `cuda` feature) and .gpu/folders/{sceaux,herzjesu} (the real photo folders, JPEGs as they are, from
# ../shared/data or DATA). About 45 MB in all, under a call's 64 MiB carry. The first call carries
# .gpu/suite.tar.xz from tools/pack_gpu_suite.sh instead (both together exceed the carry).
#     bash tools/pack_gpu_extract.sh [--folders-only] [DATA]
# --folders-only copies the folders alone (tools/gpu_pending_call.sh carries them beside suite.tar.xz).
# Needs NVCC (see the README's CUDA section) and libclang.
set -euo pipefail
cd "$(dirname "$0")/.."
folders_only=0
if [ "${1:-}" = --folders-only ]; then folders_only=1; shift; fi
data=${1:-../shared/data}
mkdir -p .gpu
# (git's path: in a worktree .git is a file, the exclude list is the main checkout's)
exclude=$(git rev-parse --git-path info/exclude)
mkdir -p "$(dirname "$exclude")"
grep -qx '/.gpu/' "$exclude" 2>/dev/null || echo '/.gpu/' >> "$exclude"
if [ $folders_only = 0 ]; then
rm -rf .gpu/xbin && mkdir -p .gpu/xbin
cargo bench -p clatch --features cuda --bench gpu_extract_stream --no-run --message-format=json 2>/dev/null \
    | python3 -c '
import json, sys, shutil
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "gpu_extract_stream":
        shutil.copy(m["executable"], ".gpu/xbin/bench_gpu_extract_stream")
        print("packed bench gpu_extract_stream")
'
cargo build --release -p clatch-cli --features cuda
cp target/release/clatch .gpu/xbin/clatch
strip .gpu/xbin/*
tar -C .gpu/xbin -cJf .gpu/extract.tar.xz .
rm -rf .gpu/xbin
fi
rm -rf .gpu/folders && mkdir -p .gpu/folders/sceaux .gpu/folders/herzjesu
cp "$data"/sceaux_castle/*.JPG .gpu/folders/sceaux/
cp "$data"/strecha_herzjesu_p8/images/*.jpg .gpu/folders/herzjesu/
du -sh .gpu/folders $([ $folders_only = 1 ] || echo .gpu/extract.tar.xz)
