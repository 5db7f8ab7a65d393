#!/usr/bin/env bash
# Builds, here, what tools/gpu_call.sh runs on the device and packs it into .gpu/part-main.tar.xz
# (git-ignored): every GPU test binary (tests/cuda_*.rs, the library's unit tests, tests/backend.rs,
# all with the `cuda` feature), the command-line tool, the gpu_collection bench, and with OLD=<commit> that commit's command-line
# tool under old/ (built in a worktree beside this checkout). One solid xz stream at -9 with one thread:
# the binaries share most of their bytes (the embedded kernels, the dependencies), which a 64 MiB
# dictionary finds, so 15 stripped binaries of 20-40 MB each pack into about 12 MB (separate or
# multi-threaded compression gave 48 MB, too much to carry with the photo folders).
# Needs NVCC (see the README's CUDA section) and libclang.
set -euo pipefail
cd "$(dirname "$0")/.."
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
cargo test -p clatch --features cuda --no-run --message-format=json 2>/dev/null \
    | python3 tools/copy_test_binaries.py "$stage"
cargo build --release -p clatch-cli --features cuda
cp target/release/clatch "$stage/clatch"
# The exhaustive-matching bench (issue 13), as bench_gpu_collection.
cargo bench -p clatch --features cuda --bench gpu_collection --no-run --message-format=json 2>/dev/null \
    | python3 tools/copy_bench_binaries.py "$stage" gpu_collection
if [ -n "${OLD:-}" ]; then
    tree=$(mktemp -d)/old
    git worktree add -f "$tree" "$OLD" > /dev/null
    (cd "$tree" && CARGO_TARGET_DIR=${OLD_TARGET:-$PWD/../target-old} cargo build --release -p clatch-cli --features cuda)
    mkdir -p "$stage/old" && cp "${OLD_TARGET:-$tree/../target-old}/release/clatch" "$stage/old/clatch"
    git worktree remove --force "$tree"
fi
strip "$stage"/* "$stage"/old/* 2>/dev/null || true
mkdir -p .gpu
tar -C "$stage" -cf - . | xz -9 -T1 > .gpu/part-main.tar.xz
ls -la .gpu/part-main.tar.xz
