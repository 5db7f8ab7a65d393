#!/usr/bin/env python3
"""Per-group totals of `clatch-eval` runs against OpenCV's ORB (and LATCH) from the same pairs.

    python3 eval/scripts/eval_groups.py OPENCV_SUMMARY.csv NAME=RUN_DIR [NAME=RUN_DIR ...]

For every pair group (Oxford sequences, OpenCV's graf sample, synthetic rotation / scale /
perspective), prints Σ correct matches, the mean matching score and the precision (correct / matches)
of ORB and of each run's `clatch` column, and each run's correct matches as a ratio to ORB's; the last
line gives the totals over all groups. RUN_DIR is an `--out` folder of `clatch-eval` (its
`clatch.summary.csv` is read).
"""
import collections
import csv
import sys


def totals(path, method):
    groups = collections.defaultdict(lambda: [0, 0, 0.0, 0])
    for row in csv.DictReader(open(path)):
        if row["method"] != method:
            continue
        g = groups[row["group"]]
        g[0] += int(row["correct"])
        g[1] += int(row["matches"])
        g[2] += float(row["matching_score"])
        g[3] += 1
    return groups


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    orb = totals(sys.argv[1], "OpenCV ORB")
    runs = [arg.split("=", 1) for arg in sys.argv[2:]]
    runs = [(name, totals(f"{folder}/clatch.summary.csv", "clatch")) for name, folder in runs]
    header = f"{'group':24} {'ORB correct':>11} {'score':>6} {'prec':>5}"
    for name, _ in runs:
        header += f" | {name + ' correct':>16} {'score':>6} {'prec':>5} {'/ORB':>5}"
    print(header)
    grand = [0] * (len(runs) + 1)
    for group in sorted(orb):
        oc, om, oscore, on = orb[group]
        line = f"{group:24} {oc:11d} {oscore / on:6.3f} {oc / max(om, 1):5.2f}"
        grand[0] += oc
        for i, (_, t) in enumerate(runs):
            c, m, score, n = t.get(group, [0, 0, 0.0, 1])
            grand[i + 1] += c
            line += f" | {c:16d} {score / n:6.3f} {c / max(m, 1):5.2f} {c / max(oc, 1):5.2f}"
        print(line)
    line = f"{'all groups':24} {grand[0]:11d} {'':6} {'':5}"
    for i in range(len(runs)):
        line += f" | {grand[i + 1]:16d} {'':6} {'':5} {grand[i + 1] / max(grand[0], 1):5.2f}"
    print(line)


if __name__ == "__main__":
    main()
