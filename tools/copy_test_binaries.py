"""Copies the GPU suite's test binaries out of `cargo test --no-run --message-format=json` (stdin)
into a folder (argv[1]): the library's unit tests as clatch_unit, tests/cuda_*.rs and tests/backend.rs
under their names. Used by tools/gpu_pack.sh and tools/pack_gpu_suite.sh.
"""
import json
import shutil
import sys

for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") != "compiler-artifact" or not m.get("executable"):
        continue
    t = m["target"]
    name = "clatch_unit" if t["kind"] == ["lib"] else t["name"]
    if name == "clatch_unit" or name.startswith("cuda_") or name == "backend":
        shutil.copy(m["executable"], sys.argv[1] + "/" + name)
        print("packed", name)
