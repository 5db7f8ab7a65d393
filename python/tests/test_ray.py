"""``clatch.ray`` on a local Ray cluster (two CPUs, two actors, CPU backend): the database and match
list byte-identical to the single-process run of ``clatch.colmap`` (and so to ``clatch colmap``),
with a worker that dies mid-run, with a given pair list; errors.

Skipped when Ray is not installed, unless ``CLATCH_REQUIRE_RAY`` is set (as in CI): then a missing
Ray fails.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

import clatch
import clatch.colmap
from helpers import broken_copy, photo_folder

try:
    import ray
except ImportError:
    if os.environ.get("CLATCH_REQUIRE_RAY"):
        raise
    pytest.skip("ray is not installed (pip install ray==2.60.0)", allow_module_level=True)

import clatch.ray

PHOTOS = 7
# Tiles of 2 x 2 photos: groups {0, 1}, {2, 3}, {4, 5}, {6}; 9 tiles hold the 21 pairs.
BLOCK = 2
BLOCKS = 9


@pytest.fixture(scope="module")
def cluster():
    # The tests make tasks fail on purpose; Ray would print each failed result nobody fetched.
    os.environ.setdefault("RAY_IGNORE_UNHANDLED_ERRORS", "1")
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return photo_folder(tmp_path_factory.mktemp("photos"), count=PHOTOS)


@pytest.fixture(scope="module")
def single(folder, tmp_path_factory, backend) -> clatch.colmap.MatchFolderResult:
    """The single-process run the cluster runs must equal."""
    return clatch.colmap.match_folder(folder, tmp_path_factory.mktemp("single") / "one.db", backend=backend)


def same_files(a: clatch.colmap.MatchFolderResult, b: clatch.colmap.MatchFolderResult) -> bool:
    lists = [None if r.match_list is None else r.match_list.read_bytes() for r in (a, b)]
    return a.database.read_bytes() == b.database.read_bytes() and lists[0] == lists[1]


def report(label: str, result: clatch.colmap.MatchFolderResult) -> None:
    print(
        f"\n{label}: {result.images} photos, {result.pairs} pairs, {result.matches} matches, "
        f"{result.blocks} blocks, {result.blocks_rerun} rerun, {result.actors_lost} actors lost, "
        f"{result.descriptor_fetches} descriptor sets fetched"
    )


def test_two_actors_write_the_single_process_files(cluster, backend, folder, single, cli, tmp_path):
    calls = []
    result = clatch.ray.match_folder(
        folder,
        tmp_path / "ray.db",
        backend=backend,
        num_actors=2,
        block_size=BLOCK,
        photos_per_task=2,
        progress=lambda *a: calls.append(a),
    )
    report("two actors", result)
    assert (result.blocks, result.blocks_rerun, result.actors_lost) == (BLOCKS, 0, 0)
    assert (result.images, result.pairs, result.matches) == (single.images, single.pairs, single.matches)
    assert single.matches > 500 and single.pairs_with_matches >= 15
    assert same_files(result, single), "the cluster's files differ from the single-process run's"
    # Resident descriptor sets: each actor fetched each photo's at most once (fetched per block,
    # the 9 blocks would take 27).
    assert PHOTOS <= result.descriptor_fetches <= 2 * PHOTOS
    # And the command-line tool's.
    subprocess.run(
        [str(cli), "colmap", "--images", str(folder), "--database", str(tmp_path / "tool.db"), "--no-colmap", "--backend", "cpu"],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    assert (tmp_path / "tool.db").read_bytes() == result.database.read_bytes()
    assert result.match_list is None and not (tmp_path / "tool-colmap" / "matches.txt").exists()
    assert calls[-1] == ("match", single.pairs, single.pairs)
    assert ("extract", PHOTOS, PHOTOS) in calls


# How a worker dies: its process exits during its second block (that block and any queued behind it
# are lost), during its second extraction task, or the driver kills it (ray.kill) after the first
# three results (the one extraction task and two blocks), with blocks left to give it. The first
# actor is sure to get a second block and a second extraction task: the driver hands each actor two
# tasks at the start (`_PER_ACTOR`), the first actor first. A third block was not sure: under load the
# other actor could take all the rest while the first was still on its first block.
DEATHS = {
    "exits-in-block-2": {"_exit_after": ("match", 1)},
    "exits-in-extraction-2": {"_exit_after": ("extract", 1), "photos_per_task": 2},
    "killed-by-the-driver": {"_kill_after_results": 3},
}


@pytest.mark.parametrize("death", DEATHS.values(), ids=DEATHS.keys())
def test_a_worker_killed_mid_run_has_its_tasks_rerun(cluster, backend, folder, single, tmp_path, death):
    result = clatch.ray.match_folder(
        folder, tmp_path / "killed.db", backend=backend, num_actors=2, block_size=BLOCK, **death
    )
    report(f"a worker killed {death}", result)
    assert result.actors_lost == 1
    assert 1 <= result.blocks_rerun <= 2
    assert same_files(result, single), "the files differ after a worker was killed"


def test_given_pairs_equal_the_single_process_run(cluster, backend, folder, tmp_path):
    names = clatch.colmap.ImageFolder(folder).names
    pairs = [(6, 0), (names[1], names[2]), (5, 3), (0, 4), (2, 6)]
    one = clatch.colmap.match_folder(folder, tmp_path / "one.db", pairs=pairs, backend=backend, match_list=True)
    result = clatch.ray.match_folder(
        folder, tmp_path / "ray.db", pairs=pairs, backend=backend, match_list=True, num_actors=2, block_size=BLOCK
    )
    report("given pairs", result)
    assert result.pairs == 5 and result.blocks == 5
    assert same_files(result, one)
    assert result.match_list is not None
    first = result.match_list.read_text().splitlines()[0]
    assert first == f"{names[6]} {names[0]}"


def test_verified_run_equals_the_single_process_run(cluster, backend, folder, tmp_path):
    # The driver verifies each pair as it writes it; the single process verifies a group at a time:
    # the same geometries, the same bytes.
    k = [[300.5, 0, 128.25], [0, 301.0, 127.75], [0, 0, 1]]
    one = clatch.colmap.match_folder(folder, tmp_path / "one.db", backend=backend, camera_k=k, verify=True)
    result = clatch.ray.match_folder(
        folder, tmp_path / "ray.db", backend=backend, camera_k=k, verify=True, num_actors=2, block_size=3
    )
    assert same_files(result, one)
    assert result.pairs_verified == one.pairs_verified == result.pairs
    assert 0 < result.inliers == one.inliers <= result.matches


def test_unverified_run_equals_the_single_process_run(cluster, backend, folder, tmp_path):
    # Without verification: the match list, the same bytes; neither run writes matches into the database.
    one = clatch.colmap.match_folder(folder, tmp_path / "one.db", backend=backend, verify=False)
    result = clatch.ray.match_folder(folder, tmp_path / "ray.db", backend=backend, verify=False, num_actors=2, block_size=3)
    assert result.match_list is not None and same_files(result, one)
    assert result.pairs_verified == 0 and result.match_list.stat().st_size > 100


def test_options_reach_the_actors(cluster, backend, folder, tmp_path):
    options = {
        "camera_k": [[300.5, 0, 128.25], [0, 301.0, 127.75], [0, 0, 1]],
        "extractor": {"grid": 4, "max_keypoints": 120},
        "subpixel": "corner",
        "subpixel_radius": 2,
        "matcher": {"ratio": 0.9},
    }
    one = clatch.colmap.match_folder(folder, tmp_path / "one.db", backend=backend, **options)
    result = clatch.ray.match_folder(folder, tmp_path / "ray.db", backend=backend, num_actors=2, block_size=3, **options)
    assert same_files(result, one)
    # The options changed the run: fewer keypoints than the defaults' (single-process) run.
    default = clatch.colmap.match_folder(folder, tmp_path / "default.db", backend=backend)
    assert result.keypoints <= 120 * PHOTOS < default.keypoints
    assert result.matches > 100


def test_bad_input_is_refused_before_any_work(cluster, folder, tmp_path):
    db = tmp_path / "out.db"
    with pytest.raises(clatch.ImageReadError) as e:
        clatch.ray.match_folder(tmp_path / "missing", db)
    assert e.value.kind == "ImageDir"
    for kind, pairs in [("PairOutOfRange", [(0, PHOTOS)]), ("SamePair", [(1, 1)]), ("DuplicatePair", [(2, 3), (3, 2)])]:
        with pytest.raises(clatch.InvalidInputError) as e:
            clatch.ray.match_folder(folder, db, pairs=pairs)
        assert e.value.kind == kind
    with pytest.raises(clatch.InvalidInputError, match="block_size"):
        clatch.ray.match_folder(folder, db, block_size=0)
    with pytest.raises(clatch.InvalidInputError, match="max_keypoints"):
        clatch.ray.match_folder(folder, db, extractor={"max_keypoints": 0})
    assert not db.exists()


def test_a_photo_that_fails_on_an_actor_raises_its_own_error(cluster, backend, folder, tmp_path):
    broken, last = broken_copy(folder, tmp_path / "broken")
    db = tmp_path / "out.db"
    with pytest.raises(clatch.ImageReadError) as e:
        clatch.ray.match_folder(broken, db, backend=backend, num_actors=2)
    assert last.name in str(e.value)
    assert not db.exists()
    # The workspace the run made is gone again, not left empty.
    assert not (tmp_path / "out-colmap").exists()


def test_more_deaths_than_allowed_is_a_cluster_error(cluster, backend, folder, tmp_path):
    with pytest.raises(clatch.ClusterError, match="max_actor_failures=0") as e:
        clatch.ray.match_folder(
            folder, tmp_path / "out.db", backend=backend, num_actors=2, block_size=BLOCK, max_actor_failures=0, _exit_after=("match", 0)
        )
    assert e.value.kind == "ActorsDied"
    assert not (tmp_path / "out.db").exists()


def test_a_backend_the_actors_cannot_start_raises_its_own_error(cluster, folder, tmp_path):
    try:
        clatch.Extractor("cuda")
        pytest.skip("CUDA runs here: no backend to refuse")
    except clatch.BackendUnavailableError:
        pass
    with pytest.raises(clatch.BackendUnavailableError):
        clatch.ray.match_folder(folder, tmp_path / "out.db", backend="cuda", num_actors=2)
    assert not (tmp_path / "out.db").exists()


@pytest.mark.parametrize(
    "options,actors,words",
    [
        ({"num_gpus": 1}, None, "GPU=1"),
        ({"num_cpus": 1, "resources": {"tpu_pod": 1}}, None, "tpu_pod=1"),
        ({"num_cpus": 3}, None, "CPU=3"),
        ({"num_cpus": 1}, 3, "3 actors"),
    ],
)
def test_resources_the_cluster_lacks_are_refused_at_once(cluster, folder, tmp_path, options, actors, words):
    """``actor_options={"num_gpus": 1}`` on a cluster without GPUs never returned (Ray
    waits for a GPU for ever). The cluster's resources are checked first."""
    start = time.perf_counter()
    with pytest.raises(clatch.ClusterError) as e:
        clatch.ray.match_folder(folder, tmp_path / "out.db", actor_options=options, num_actors=actors)
    assert time.perf_counter() - start < 30
    assert e.value.kind == "ResourcesUnavailable" and words in str(e.value)
    assert not (tmp_path / "out.db").exists()


def test_actors_that_cannot_start_in_time_are_a_cluster_error(cluster, folder, tmp_path):
    """The wait bounded: the resources exist but another job holds them."""

    @ray.remote(num_cpus=2)
    class Hog:
        def ready(self) -> bool:
            return True

    hog = Hog.remote()
    ray.get(hog.ready.remote())
    try:
        start = time.perf_counter()
        with pytest.raises(clatch.ClusterError) as e:
            clatch.ray.match_folder(folder, tmp_path / "out.db", num_actors=1, start_timeout=3)
        assert e.value.kind == "ActorsNotStarted" and "start_timeout=3" in str(e.value)
        assert time.perf_counter() - start < 30
    finally:
        ray.kill(hog)
    assert not (tmp_path / "out.db").exists()


# As in an interactive session: the error is shown, and the session goes on (Ray prints what it
# finds unhandled a moment later).
FAILING_RUN = """
import time, traceback
import ray, clatch.ray
ray.init(num_cpus=2, include_dashboard=False)
try:
    clatch.ray.match_folder({folder!r}, {db!r}, num_actors=2, photos_per_task=3)
except clatch.ClatchError:
    traceback.print_exc()
import gc; gc.collect()
time.sleep(3)
"""


def test_a_failing_task_prints_one_traceback(folder, tmp_path):
    """A photo that fails on an actor printed Ray's "Unhandled error"
    tracebacks of the task's other results besides the clean error. Now one traceback: the error."""
    broken, last = broken_copy(folder, tmp_path / "broken")
    env = {k: v for k, v in os.environ.items() if k != "RAY_IGNORE_UNHANDLED_ERRORS"}
    run = subprocess.run(
        [sys.executable, "-c", FAILING_RUN.format(folder=str(broken), db=str(tmp_path / "out.db"))],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert run.returncode == 0, run.stderr
    err = run.stderr
    assert err.count("Traceback") == 1 and "Unhandled error" not in err, err
    assert "clatch._exceptions.ImageReadError" in err and last.name in err
