#!/bin/bash
# The benchmark session behind BENCHMARKS.md, as run on the device machine: every GPU bench, the peers, clatch's
# CPU describe on that machine's cores, ncu on the two main kernels, sanitizers on the describe kernels.
# Expects, under .gpu/: bench.tar.xz (the gpu_match, gpu, gpu_detect, gpu_streams bench binaries and the
# cpu_describe example, built with `cargo bench --features cuda --no-run` / `cargo build --release --example
# cpu_describe`), describe.tar.xz (the cuda_describe and cuda_describe_opencv test binaries) and cv2pkg.tar.xz
# (opencv-contrib-python-headless 5.0.0.93 unpacked: cv2/ and its .libs/), carried with the working tree;
# writes everything to $OUT.
cd "$(dirname "$0")/.." && mkdir -p .gpu/bin .gpu/site && tar -xJf .gpu/bench.tar.xz -C .gpu/bin && tar -xJf .gpu/describe.tar.xz -C .gpu/bin && tar -xJf .gpu/cv2pkg.tar.xz -C .gpu/site
O=$OUT
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm --format=csv > $O/smi.txt 2>&1; date -u >> $O/smi.txt; nproc >> $O/smi.txt; lscpu | grep "Model name" >> $O/smi.txt
mkdir -p /tmp/dump
timeout 150 .gpu/bin/gpu_match > $O/bench_match.txt 2>&1; echo "rc $?" >> $O/bench_match.txt
CLATCH_BENCH_DUMP=/tmp/dump timeout 120 .gpu/bin/gpu > $O/bench_describe.txt 2>&1; echo "rc $?" >> $O/bench_describe.txt
timeout 60 .gpu/bin/gpu_detect > $O/bench_detect.txt 2>&1; echo "rc $?" >> $O/bench_detect.txt
for i in 1 2 3; do timeout 60 .gpu/bin/gpu_streams >> $O/bench_streams.txt 2>&1; done; echo "rc $?" >> $O/bench_streams.txt
PYTHONPATH=.gpu/site timeout 200 python3 tools/peers.py --dump /tmp/dump --out $O/peers.json > $O/peers.txt 2>&1; echo "rc $?" >> $O/peers.txt
for img in 1080p 5616x3744; do tail -n +2 /tmp/dump/${img}_10000.csv | tr ',' ' ' > /tmp/dump/$img.txt
  for th in 1 16; do echo "$img threads $th: $(.gpu/bin/cpu_describe time /tmp/dump/$img.pgm /tmp/dump/$img.txt $th 5)" >> $O/cpu_clatch.txt; done; done
timeout 120 ncu --target-processes all -k regex:clatch_knn_tensor_b512_k2 -s 40 -c 1 --section SpeedOfLight --section ComputeWorkloadAnalysis --section Occupancy --section WarpStateStats .gpu/bin/gpu_match > $O/ncu_knn.txt 2>&1
timeout 120 ncu --target-processes all -k regex:clatch_describe_binary -s 60 -c 1 --section SpeedOfLight --section ComputeWorkloadAnalysis --section MemoryWorkloadAnalysis --section Occupancy --section WarpStateStats .gpu/bin/gpu > $O/ncu_describe.txt 2>&1
for tool in memcheck initcheck racecheck; do
  echo "== $tool describe" >> $O/sanitize.txt
  timeout 150 compute-sanitizer --tool $tool .gpu/bin/cuda_describe describe_sizes_subpixel_and_borders 2>&1 | tail -3 >> $O/sanitize.txt
  echo "== $tool describe opencv" >> $O/sanitize.txt
  timeout 150 compute-sanitizer --tool $tool .gpu/bin/cuda_describe_opencv opencv_borders_and_patch_sizes 2>&1 | tail -3 >> $O/sanitize.txt
done
