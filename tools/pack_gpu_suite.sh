#!/usr/bin/env bash
# Builds, here (no GPU needed), everything the GPU suite runs on the device machine and packs it into
# .gpu/suite.tar.xz (git-ignored): the GPU test binaries (tests/cuda_*.rs), the library's unit tests and
# tests/backend.rs with the `cuda` feature, the command-line tool, the gpu_streams example, the
# gpu_detect and gpu_match benches (they load the bench-only kernels), the gpu_pool bench (the
# multi-device scheduler on the one GPU), the gpu_extract_stream bench (whole extraction calls against
# the device's busy time) and the gpu_collection bench (exhaustive collection matching). Then, with the device tool:
#     run: bash tools/gpu_suite.sh      carry: [".gpu"]
# Needs NVCC (see the README's CUDA section) and libclang.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p .gpu && rm -rf .gpu/bin && mkdir -p .gpu/bin
# (git's path: in a worktree .git is a file, the exclude list is the main checkout's)
exclude=$(git rev-parse --git-path info/exclude)
mkdir -p "$(dirname "$exclude")"
grep -qx '/.gpu/' "$exclude" 2>/dev/null || echo '/.gpu/' >> "$exclude"

# Test binaries: their paths from cargo's JSON messages.
cargo test -p clatch --features cuda --no-run --message-format=json 2>/dev/null \
    | python3 tools/copy_test_binaries.py .gpu/bin
cargo bench -p clatch --features cuda --no-run --message-format=json 2>/dev/null \
    | python3 tools/copy_bench_binaries.py .gpu/bin gpu_detect gpu_match gpu_pool gpu_extract_stream gpu_collection
cargo build --release -p clatch-cli --features cuda
cargo build --release -p clatch --features cuda --example gpu_streams
cp target/release/clatch .gpu/bin/clatch
cp target/release/examples/gpu_streams .gpu/bin/gpu_streams
strip .gpu/bin/*
tar -C .gpu/bin -cJf .gpu/suite.tar.xz .
rm -rf .gpu/bin
ls -la .gpu/suite.tar.xz
