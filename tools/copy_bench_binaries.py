"""Copies bench binaries out of `cargo bench --no-run --message-format=json` (stdin) into a folder
(argv[1]) as bench_NAME, for the benches named in argv[2:]. Used by tools/gpu_pack.sh and
tools/pack_gpu_suite.sh.
"""
import json
import shutil
import sys

folder, names = sys.argv[1], set(sys.argv[2:])
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] in names:
        shutil.copy(m["executable"], folder + "/bench_" + m["target"]["name"])
        print("packed bench", m["target"]["name"])
