"""``python -m clatch``: extract, match and colmap as the command-line tool's basic use."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

import clatch
import clatch.colmap
from helpers import ASTRONAUT, photo_folder, run_extract


def run(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "clatch", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_extract_writes_the_tools_files(cli, tmp_path):
    table, descriptors = run_extract(cli, ASTRONAUT, tmp_path / "tool", ["--max-keypoints", "700", "--backend", "cpu"])
    done = run("extract", str(ASTRONAUT), "-o", str(tmp_path / "ours"), "--max-keypoints", "700", "--backend", "cpu")
    assert done.returncode == 0, done.stderr
    ours = np.loadtxt(tmp_path / "ours.keypoints.csv", delimiter=",", skiprows=1, ndmin=2)
    assert (tmp_path / "ours.keypoints.csv").read_text().splitlines()[0] == "x,y,size,angle,response,octave"
    assert np.array_equal(ours.astype(np.float32), table.astype(np.float32))
    assert np.array_equal(np.load(tmp_path / "ours.descriptors.npy"), descriptors)


def test_match_and_colmap(tmp_path):
    (tmp_path / "photos").mkdir()
    folder = photo_folder(tmp_path / "photos", 3)
    a, b = sorted(folder.iterdir())[:2]
    done = run("match", str(a), str(b), "-o", str(tmp_path / "m.csv"), "--backend", "cpu")
    assert done.returncode == 0, done.stderr
    extractor = clatch.Extractor("cpu")
    expected = clatch.Matcher("cpu").match(extractor.detect_and_describe(clatch.imread(a))[1], extractor.detect_and_describe(clatch.imread(b))[1])
    rows = np.loadtxt(tmp_path / "m.csv", delimiter=",", skiprows=1, dtype=np.int64, ndmin=2)
    assert len(expected) > 10 and rows.tolist() == [[int(m["query"]), int(m["train"]), int(m["distance"])] for m in expected]
    assert f"{len(expected)} matches" in done.stdout
    done = run("colmap", "--images", str(folder), "--database", str(tmp_path / "py.db"), "--backend", "cpu")
    assert done.returncode == 0, done.stderr
    single = clatch.colmap.match_folder(folder, tmp_path / "lib.db", backend="cpu")
    assert (tmp_path / "py.db").read_bytes() == single.database.read_bytes()
    assert " verified in " in done.stdout and not (tmp_path / "py-colmap" / "matches.txt").exists()
    done = run("colmap", "--images", str(folder), "--database", str(tmp_path / "v.db"), "--backend", "cpu", "--verify")
    assert done.returncode == 0 and " verified in " in done.stdout, done.stderr
    assert (tmp_path / "v.db").read_bytes() == single.database.read_bytes(), "--verify is the default"
    done = run("colmap", "--images", str(folder), "--database", str(tmp_path / "n.db"), "--backend", "cpu", "--no-verify")
    assert done.returncode == 0 and " verified in " not in done.stdout, done.stderr
    single = clatch.colmap.match_folder(folder, tmp_path / "lib_n.db", backend="cpu", verify=False)
    assert (tmp_path / "n.db").read_bytes() == single.database.read_bytes()
    assert (tmp_path / "n-colmap" / "matches.txt").read_bytes() == (tmp_path / "lib_n-colmap" / "matches.txt").read_bytes()


def test_errors_are_one_line(tmp_path):
    done = run("extract", str(tmp_path / "missing.png"), "-o", str(tmp_path / "x"))
    assert done.returncode == 1 and done.stderr.startswith("error: ") and "Traceback" not in done.stderr
