#!/usr/bin/env python3
"""Correct matches per pair of several `clatch-eval` runs over the same pairs, side by side.

    python3 eval/scripts/eval_pairs.py [--markdown] BASE=RUN_DIR NAME=RUN_DIR [NAME=RUN_DIR ...]

One row per pair (image size, then each run's correct matches of its `clatch` column), a total per
group and over all pairs, and, for every run after the first, the pairs where it has fewer correct
matches than the first run (BASE: the configuration no pair may fall below). RUN_DIR is an `--out`
folder of `clatch-eval` (its `clatch.summary.csv` is read). Used for EVALUATION.md's "Keypoint
budgets on large images".
"""
import collections
import csv
import sys


def read(folder):
    rows = collections.OrderedDict()
    for row in csv.DictReader(open(f"{folder}/clatch.summary.csv")):
        if row["method"] == "clatch":
            rows[row["pair"]] = row
    return rows


def main(argv):
    markdown = "--markdown" in argv
    argv = [a for a in argv if a != "--markdown"]
    if len(argv) < 3:
        sys.exit(__doc__)
    runs = [(name, read(folder)) for name, folder in (a.split("=", 1) for a in argv[1:])]
    pairs = list(runs[0][1])
    for name, rows in runs[1:]:
        missing = [p for p in pairs if p not in rows]
        if missing:
            sys.exit(f"eval_pairs: run {name} lacks pairs {missing[:3]}")
    names = [name for name, _ in runs]
    if markdown:
        print("| pair | size | " + " | ".join(names) + " |")
        print("|---|---|" + "---:|" * len(names))
    else:
        print(f"{'pair':28} {'size':>10} " + " ".join(f"{n:>10}" for n in names))
    groups = collections.OrderedDict()
    for pair in pairs:
        first = runs[0][1][pair]
        size = f"{first['width_a']}x{first['height_a']}"
        counts = [int(rows[pair]["correct"]) for _, rows in runs]
        g = groups.setdefault(first["group"], [0] * len(runs))
        for i, c in enumerate(counts):
            g[i] += c
        if markdown:
            print(f"| {pair} | {size} | " + " | ".join(str(c) for c in counts) + " |")
        else:
            print(f"{pair:28} {size:>10} " + " ".join(f"{c:>10}" for c in counts))
    print()
    total = [0] * len(runs)
    for group, sums in groups.items():
        total = [t + s for t, s in zip(total, sums)]
        print(f"{'Σ ' + group:39} " + " ".join(f"{s:>10}" for s in sums))
    print(f"{'Σ all':39} " + " ".join(f"{s:>10}" for s in total))
    for name, rows in runs[1:]:
        below = [
            f"{p} ({rows[p]['correct']} < {runs[0][1][p]['correct']})"
            for p in pairs
            if int(rows[p]["correct"]) < int(runs[0][1][p]["correct"])
        ]
        print(f"{name} below {names[0]}: " + (", ".join(below) if below else "none"))


if __name__ == "__main__":
    main(sys.argv)
