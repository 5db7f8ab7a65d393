"""Sums an `ncu --metrics gpu__time_duration.sum --csv` log: total device time and time per kernel.

    python3 tools/ncu_sum.py /tmp/ncu.csv
"""
import collections
import csv
import sys

rows = [r for r in csv.reader(open(sys.argv[1])) if len(r) > 10]
h = rows[0]
ki, vi, ui = h.index("Kernel Name"), h.index("Metric Value"), h.index("Metric Unit")
scale = {"ns": 1e-6, "nsecond": 1e-6, "us": 1e-3, "usecond": 1e-3, "ms": 1.0, "msecond": 1.0}
tot = 0.0
per, n = collections.Counter(), collections.Counter()
for r in rows[1:]:
    v = float(r[vi].replace(",", "")) * scale[r[ui]]
    tot += v
    k = r[ki].split("(")[0]
    per[k] += v
    n[k] += 1
print(f"kernels {sum(n.values())}  device time {tot:.3f} ms")
for k, v in per.most_common():
    print(f"  {k:40s} x{n[k]:3d} {v:.3f} ms")
