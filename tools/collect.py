#!/usr/bin/env python3
"""Collects one benchmark run's figures into a CSV the chart reads (`eval/examples/bench_chart.rs`).

Reads, from one run directory: bench_match.txt (`cargo bench --features cuda --bench gpu_match`),
bench_describe.txt (`--bench gpu`), cpu_clatch.txt (`examples/cpu_describe time` on the dumped image and
keypoints) and peers.json (`tools/peers.py --out`). Writes rows
`panel,series,x,y`: matching throughput (G pairs/s) against N for N x N, and extraction throughput
(M descriptors/s) against the number of keypoints.

    python3 tools/collect.py docs/bench/2026-11-23-h100 > docs/bench/2026-11-23-h100/figures.csv
"""

import json
import os
import re
import sys


def matching(run):
    rows = []
    for line in open(os.path.join(run, "bench_match.txt")):
        m = re.match(r"knn k=2 512 bits\s+(\d+) x (\d+)\s+(\w+)\s*:.*?([\d.]+) G pairs/s", line)
        if m:
            rows.append(("matching", f"clatch {m.group(3).lower()}", int(m.group(1)), float(m.group(4))))
    return rows


def extraction(run):
    rows = []
    for line in open(os.path.join(run, "bench_describe.txt")):
        m = re.match(r"describe\s+(\S+)\s+(\d+) keypoints,\s+7x7 mask:.*?([\d.]+) M descriptors/s", line)
        if m:
            rows.append(("extraction", f"clatch GPU {m.group(1)}", int(m.group(2)), float(m.group(3))))
    return rows


def cpu_clatch(run):
    """clatch's CPU describe on the same machine, image and keypoints (`examples/cpu_describe time`)."""
    rows = []
    path = os.path.join(run, "cpu_clatch.txt")
    if not os.path.exists(path):
        return rows
    for line in open(path):
        m = re.match(r"(\S+) threads (\d+): descriptors (\d+) threads \d+ median_us ([\d.]+)", line)
        if m:
            rows.append(("extraction", f"clatch CPU {m.group(2)} thread(s) {m.group(1)}", int(m.group(3)), 1.0 / float(m.group(4))))
    return rows


def peers(run):
    rows = []
    path = os.path.join(run, "peers.json")
    if not os.path.exists(path):
        return rows
    report = json.load(open(path))
    for r in report.get("matching", {}).get("runs", []):
        if "pairs_per_s" in r:
            rows.append(("matching", f"PyTorch {r['kind']} GEMM+topk", r["n"], r["pairs_per_s"] / 1e9))
    for r in report.get("extraction", {}).get("runs", []):
        if "us_per_descriptor_1_thread" in r:
            n = r["keypoints"]
            rows.append(("extraction", f"OpenCV LATCH 1 thread {r['image']}", n, 1.0 / r["us_per_descriptor_1_thread"]))
            cores = report["extraction"].get("cores", "all")
            rows.append(
                ("extraction", f"OpenCV LATCH {cores} cores {r['image']}", n, 1.0 / r["us_per_descriptor_all_cores"])
            )
    return rows


def main(run):
    print("panel,series,x,y")
    for panel, series, x, y in matching(run) + extraction(run) + cpu_clatch(run) + peers(run):
        print(f"{panel},{series},{x},{y:.6g}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
