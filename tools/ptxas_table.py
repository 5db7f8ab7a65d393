#!/usr/bin/env python3
"""Turns the ptxas resource report build.rs keeps (OUT_DIR/ptxas-report.txt, `nvcc -Xptxas -v` for sm_90)
into a Markdown table: kernel, registers, spill stores/loads, static shared memory, stack.

    python3 tools/ptxas_table.py $(ls -t target/release/build/clatch-*/out/ptxas-report.txt | head -1)
"""

import re
import sys


def main(path):
    rows = []
    current = None
    for line in open(path):
        m = re.search(r"Compiling entry function '(\w+)' for '(sm_\d+)'", line)
        if m:
            current = {"kernel": m.group(1), "arch": m.group(2)}
            continue
        if current is None:
            continue
        m = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", line)
        if m:
            current["stack"], current["spill_st"], current["spill_ld"] = m.groups()
            continue
        m = re.search(r"Used (\d+) registers(?:, used \d+ barriers)?(?:, (\d+) bytes smem)?", line)
        if m:
            current["registers"] = m.group(1)
            current["smem"] = m.group(2) or "0"
            rows.append(current)
            current = None
    print("| kernel | arch | registers | spill stores / loads (bytes) | static shared (bytes) | stack (bytes) |")
    print("|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: r["kernel"]):
        print(
            f"| `{r['kernel']}` | {r['arch']} | {r['registers']} | {r.get('spill_st', '?')} / "
            f"{r.get('spill_ld', '?')} | {r['smem']} | {r.get('stack', '?')} |"
        )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
