"""``clatch.colmap``: a folder of photos → the database (and match list) of ``clatch colmap``, byte for
byte, with the command-line tool's own defaults and with its options; given pairs; errors."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import clatch
import clatch.colmap
from helpers import broken_copy, photo_folder

SIX_PAIRS = 15


def run_cli(cli: Path, images: Path, database: Path, flags: list[str]) -> None:
    subprocess.run(
        [str(cli), "colmap", "--images", str(images), "--database", str(database), "--no-colmap", "--backend", "cpu", *flags],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def match_list_pairs(path: Path) -> list[tuple[str, str, int]]:
    """(name1, name2, matches) of each pair of a match list, in order."""
    out = []
    for block in path.read_text().split("\n\n"):
        lines = block.splitlines()
        if lines:
            a, b = lines[0].split(" ")
            out.append((a, b, len(lines) - 1))
    return out


def database_pairs(database: Path) -> list[tuple[int, int]]:
    """(pair_id, matches) of each pair with matches in a database's ``matches`` table, by pair id."""
    import sqlite3

    with sqlite3.connect(database) as sql:
        rows = sql.execute("SELECT pair_id, rows, length(data) FROM matches WHERE rows > 0 ORDER BY pair_id").fetchall()
    assert all(size == 8 * n for _, n, size in rows), rows
    return [(pair, n) for pair, n, _ in rows]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return photo_folder(tmp_path_factory.mktemp("photos"), count=6)


# (command-line flags, the same settings as match_folder keywords)
OPTIONS = [
    ([], {}),
    (
        ["--grid", "4", "--subpixel", "corner", "--subpixel-radius", "2", "--ratio", "0.9", "--max-keypoints", "800"],
        {"extractor": {"grid": 4, "max_keypoints": 800}, "subpixel": "corner", "subpixel_radius": 2, "matcher": {"ratio": 0.9}},
    ),
    (
        ["--single-scale", "--subpixel", "none", "--no-cross-check", "--match-list"],
        {"extractor": {"single_scale": True}, "subpixel": "none", "matcher": {"cross_check": False}, "match_list": True},
    ),
    (["--no-verify"], {"verify": False}),
    (["--verify"], {"verify": True}),
]


@pytest.mark.parametrize(
    "flags,keywords", OPTIONS, ids=["defaults", "grid4-corner-ratio", "single-scale-none-list", "no-verify", "verify"]
)
def test_folder_is_byte_identical_to_the_tool(cli, backend, folder, tmp_path, flags, keywords):
    run_cli(cli, folder, tmp_path / "tool.db", flags)
    calls = []
    result = clatch.colmap.match_folder(
        folder, tmp_path / "py.db", backend=backend, progress=lambda *a: calls.append(a), **keywords
    )
    tool, ours = tmp_path / "tool.db", tmp_path / "py.db"
    assert ours.read_bytes() == tool.read_bytes(), "the databases differ"
    verify = keywords.get("verify", True)
    tool_list = tmp_path / "tool-colmap" / "matches.txt"
    if verify and not keywords.get("match_list"):
        # Verified, the matches are in the database; no match list is written.
        assert result.match_list is None and not tool_list.exists()
        pairs = database_pairs(ours)
    else:
        assert result.match_list == tmp_path / "py-colmap" / "matches.txt"
        assert result.match_list.read_bytes() == tool_list.read_bytes(), "the match lists differ"
        pairs = match_list_pairs(result.match_list)
    # Real matches between the overlapping views, or the comparison would say little.
    assert len(pairs) == result.pairs_with_matches >= 10, pairs
    assert result.matches == sum(n for *_, n in pairs) > 200
    assert (result.images, result.pairs) == (6, SIX_PAIRS)
    assert calls[-1] == ("match", SIX_PAIRS, SIX_PAIRS) and ("extract", 6, 6) in calls
    # Verified, every pair's geometry is in the database (the bytes above equal the tool's).
    verified = SIX_PAIRS if verify else 0
    assert result.pairs_verified == verified
    assert 0 < result.inliers <= result.matches if verified else result.inliers == 0
    # Nothing but the outputs is left behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["py-colmap", "py.db", "tool-colmap", "tool.db"]


def test_camera_matrix_as_file_and_array_equals_the_tool(cli, backend, folder, tmp_path):
    k = np.array([[300.5, 0, 128.25], [0, 301.0, 127.75], [0, 0, 1]])
    k_file = tmp_path / "K.txt"
    k_file.write_text("300.5 0 128.25\n0 301 127.75\n0 0 1\n")
    run_cli(cli, folder, tmp_path / "tool.db", ["--camera-k", str(k_file)])
    clatch.colmap.match_folder(folder, tmp_path / "file.db", camera_k=k_file, backend=backend)
    clatch.colmap.match_folder(folder, tmp_path / "array.db", camera_k=k, backend=backend)
    tool = (tmp_path / "tool.db").read_bytes()
    assert (tmp_path / "file.db").read_bytes() == tool
    assert (tmp_path / "array.db").read_bytes() == tool
    camera = clatch.colmap.ImageFolder(folder).shared_camera(k_file.read_text())
    assert (camera.fx, camera.cy, camera.width, camera.focal_is_known) == (300.5, 127.75, 256, True)


def test_given_pairs_are_the_exhaustive_run_s_in_the_given_order(backend, folder, tmp_path):
    # Without the ratio test (not symmetric), the cross-check makes (i, j) and (j, i) the same matches.
    mutual, lists = {"ratio": None}, {"verify": False}
    everything = clatch.colmap.match_folder(folder, tmp_path / "all.db", backend=backend, matcher=mutual, **lists)
    blocks = {tuple(b.splitlines()[0].split(" ")): b for b in everything.match_list.read_text().split("\n\n") if b}
    names = clatch.colmap.ImageFolder(folder).names
    # Indices and names, any order; (4, 1) swaps query and train of the exhaustive (1, 4).
    given = [(3, 5), (names[0], names[2]), (4, 1)]
    result = clatch.colmap.match_folder(folder, tmp_path / "some.db", pairs=given, backend=backend, matcher=mutual, **lists)
    assert result.pairs == 3
    assert (tmp_path / "some.db").read_bytes() == (tmp_path / "all.db").read_bytes()
    got = [b for b in result.match_list.read_text().split("\n\n") if b]
    assert got[0] == blocks[(names[3], names[5])]
    assert got[1] == blocks[(names[0], names[2])]
    header, *rows = got[2].splitlines()
    want_header, *want_rows = blocks[(names[1], names[4])].splitlines()
    assert header == f"{names[4]} {names[1]}"
    assert sorted(" ".join(r.split(" ")[::-1]) for r in rows) == sorted(want_rows)


def test_inputs_are_refused_with_typed_errors(backend, folder, tmp_path):
    db = tmp_path / "out.db"
    with pytest.raises(clatch.ImageReadError) as e:
        clatch.colmap.match_folder(tmp_path / "missing", db)
    assert e.value.kind == "ImageDir"
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no photo")
    with pytest.raises(clatch.InvalidInputError) as e:
        clatch.colmap.match_folder(empty, db)
    assert e.value.kind == "NoImages" and "no image in" in str(e.value)
    bad_pairs = {
        "PairOutOfRange": [(0, 6)],
        "SamePair": [(2, 2)],
        "DuplicatePair": [(0, 1), (1, 0)],
        "WrongShape": [(0, 1, 2)],
    }
    for kind, pairs in bad_pairs.items():
        with pytest.raises(clatch.InvalidInputError) as e:
            clatch.colmap.match_folder(folder, db, pairs=pairs)
        assert e.value.kind == kind, (kind, e.value)
    with pytest.raises(clatch.InvalidInputError, match="not an image of the folder"):
        clatch.colmap.match_folder(folder, db, pairs=[("view0.pgm", "nope.png")])
    with pytest.raises(clatch.InvalidInputError, match="subpixel must be one of"):
        clatch.colmap.match_folder(folder, db, subpixel="parabola")
    with pytest.raises(clatch.InvalidInputError, match="threshold"):
        clatch.colmap.match_folder(folder, db, extractor={"threshold": 0})
    with pytest.raises(clatch.InvalidInputError) as e:
        clatch.colmap.match_folder(folder, db, camera_k=np.eye(2))
    assert e.value.kind == "InvalidCamera"
    assert not db.exists() and not (tmp_path / "out-colmap").exists()


def test_an_existing_database_is_kept_unless_forced(backend, folder, tmp_path):
    db = tmp_path / "out.db"
    db.write_bytes(b"an older database")
    with pytest.raises(clatch.DatabaseError) as e:
        clatch.colmap.match_folder(folder, db, backend=backend)
    assert e.value.kind == "DatabaseExists" and isinstance(e.value, OSError)
    assert db.read_bytes() == b"an older database"
    result = clatch.colmap.match_folder(folder, db, backend=backend, force=True)
    assert db.read_bytes()[:16] == b"SQLite format 3\x00"
    assert result.images == 6


def test_a_database_another_run_is_writing_is_a_database_error(backend, folder, tmp_path):
    # Another run holds the database's lock (the operating system's advisory lock on the lock file,
    # as clatch takes it): refused as a DatabaseError naming the holder, nothing written.
    import fcntl

    db = tmp_path / "out.db"
    with open(tmp_path / ".out.db.clatch-lock", "w") as lock:
        lock.write("4242\n")
        lock.flush()
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(clatch.DatabaseError) as e:
            clatch.colmap.match_folder(folder, db, backend=backend)
    assert e.value.kind == "Locked" and "4242" in str(e.value)
    assert not db.exists()


def test_an_unreadable_photo_leaves_no_output(backend, folder, tmp_path):
    broken, last = broken_copy(folder, tmp_path / "broken")
    db = tmp_path / "out.db"
    with pytest.raises(clatch.ImageReadError) as e:
        clatch.colmap.match_folder(broken, db, backend=backend)
    assert last.name in str(e.value)
    assert not db.exists()
    # The workspace the run made is gone again, not left empty.
    assert not (tmp_path / "out-colmap").exists()


def test_outputs_are_readable_by_other_users(backend, folder, tmp_path):
    # As the command-line tool writes them (a COLMAP run under another uid reads them): 0644 under the
    # usual umask 022, not a temporary file's 0600.
    old = os.umask(0o022)
    try:
        clatch.colmap.match_folder(folder, tmp_path / "out.db", backend=backend, match_list=True)
    finally:
        os.umask(old)
    for path in [tmp_path / "out.db", tmp_path / "out-colmap" / "matches.txt"]:
        assert stat.S_IMODE(path.stat().st_mode) == 0o644, path


def test_the_writer_checks_every_index(tmp_path):
    writer = clatch.colmap._FolderWriter(tmp_path / "w.db", tmp_path / "w.txt")
    keypoints = np.zeros(3, dtype=clatch.KEYPOINT_DTYPE)
    assert writer.add_photo("a.png", 100, 80, None, keypoints) == 0
    assert writer.add_photo("b.png", 100, 80, 35, keypoints[:2]) == 1
    matches = np.array([(2, 1, 5)], dtype=clatch.MATCH_DTYPE)
    writer.add_matches(0, 1, matches)
    with pytest.raises(clatch.InvalidInputError) as e:
        writer.add_matches(1, 0, matches)  # keypoint 2 of b, which has 2
    assert e.value.kind == "MatchOutOfRange"
    with pytest.raises(clatch.InvalidInputError) as e:
        writer.add_matches(0, 2, matches)
    assert e.value.kind == "BadPair"
    with pytest.raises(clatch.InvalidInputError) as e:
        writer.add_photo("a.png", 100, 80, None, keypoints)
    assert e.value.kind == "InvalidImageName"
    writer.add_matches(0, 1, np.zeros(0, dtype=clatch.MATCH_DTYPE))  # left out of the list
    writer.finish()
    assert (tmp_path / "w.txt").read_text() == "a.png b.png\n2 1\n\n"
    with pytest.raises(clatch.InvalidInputError) as e:
        writer.finish()
    assert e.value.kind == "WriterClosed"


def test_clatch_and_clatch_ray_import_without_ray(tmp_path):
    # In a fresh interpreter where `import ray` fails: the package imports, and only running
    # clatch.ray says what to install.
    code = (
        "import sys; sys.modules['ray'] = None\n"
        "import clatch, clatch.colmap, clatch.ray\n"
        "try:\n"
        "    clatch.ray.match_folder('.', 'x.db')\n"
        "except ImportError as e:\n"
        "    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, check=True, capture_output=True, text=True)
    assert "clatch.ray needs Ray" in out.stdout and "pip install" in out.stdout, out.stdout + out.stderr
