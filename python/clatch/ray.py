"""A folder of photos matched over a Ray cluster, into the database ``clatch.colmap`` writes.

``match_folder(images, database, ...)`` takes the options of ``clatch.colmap.match_folder`` and
writes byte-identical files: it runs the stages of the same Rust library call
(``clatch::colmap::FolderJob``: the checks and the one writer on the driver, the extraction and the
matching on the actors), with the work spread over Ray actors:

- each actor holds the run's job on its ``backend`` (``"cpu"``: the actor's CPU threads; ``"cuda"``
  with ``actor_options={"num_gpus": 1}``: one device each) for the whole run;
- photos are extracted in tasks of ``photos_per_task`` photos; their descriptors go to Ray's object
  store (owned by the driver), their keypoints to the driver, which writes them to the database in
  image order;
- pairs are matched in blocks, tiles of the pair matrix (pairs whose photos fall in two groups of
  ``block_size`` photos); an actor fetches each descriptor set it needs from the object store once
  and keeps it resident (the ``cache_photos`` most recently used);
- the driver is the one writer: it writes each pair's matches in the pairs' order as soon as every
  pair before it is done, so the file does not depend on which block finished first, and it holds
  only the matches that wait for an earlier block;
- an actor that dies (its process killed or crashed, or gone with its node) has its unfinished
  tasks run again on the others and is replaced, up to ``max_actor_failures`` times. A lost node
  also loses the descriptor sets stored in its object store (those over Ray's 100 KiB inline limit,
  about 1600 keypoints); they are not extracted again: a block that needs one of which no other
  node holds a copy fails the run with a ``ClusterError``.

Ray is imported when ``match_folder`` runs (``import clatch`` never needs it). Without a running
Ray, ``match_folder`` starts a local one (``ray.init()``); on a cluster, connect first::

    ray start --head                          # on the head node
    ray start --address=HEAD_IP:6379          # on each worker node
    python script.py                          # calls ray.init(address="auto"), then match_folder

The photo folder must be readable at the same path on every node (a shared file system); the
database and match list are written by the driver only.
"""

from __future__ import annotations

import os
from collections import OrderedDict, deque
from typing import Any, Callable, Deque, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ._exceptions import ClatchError, ClusterError, MissingDependencyError
from .colmap import MatchFolderResult, PathArg, PhotoArg, Photo, Progress, _invalid, _job, _result

__all__ = ["match_folder"]

#: Tasks queued on each actor at a time: one running, one waiting (no idle gap between tasks).
_PER_ACTOR = 2


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as e:
        raise MissingDependencyError(
            "clatch.ray needs Ray, which is not installed: pip install 'clatch[ray]' (or 'ray==2.60.0')"
        ) from e
    return ray


def _cluster_error(kind: str, message: str) -> ClusterError:
    return ClusterError(message, kind=kind)


def _demands(options: Mapping[str, Any]) -> Dict[str, float]:
    """The resources one actor asks for, by the names ``ray.cluster_resources()`` uses."""
    # Without num_cpus an actor needs a CPU to be placed but holds none while it runs (Ray's
    # default): CPUs then bound nothing.
    demands = {"CPU": float(options.get("num_cpus", 0) or 0), "GPU": float(options.get("num_gpus", 0) or 0)}
    if options.get("memory"):
        demands["memory"] = float(options["memory"])
    for name, amount in (options.get("resources") or {}).items():
        demands[name] = float(amount)
    return {name: amount for name, amount in demands.items() if amount > 0}


def _check_resources(ray: Any, demands: Mapping[str, float], actors: int) -> None:
    """Refuses, before any actor is made, actors the cluster cannot hold at once: Ray would wait for
    them for ever (``actor_options={"num_gpus": 1}`` on a cluster without GPUs)."""
    total = ray.cluster_resources()
    for name, amount in demands.items():
        have = float(total.get(name, 0))
        if amount > have:
            raise _cluster_error(
                "ResourcesUnavailable",
                f"each actor asks for {name}={amount:g} (actor_options) but the Ray cluster has "
                f"{have:g} {name} in all (ray.cluster_resources())",
            )
        if amount * actors > have:
            raise _cluster_error(
                "ResourcesUnavailable",
                f"{actors} actors asking for {name}={amount:g} each need {amount * actors:g} {name}, "
                f"but the Ray cluster has {have:g} (ray.cluster_resources()); pass fewer num_actors",
            )


class _Worker:
    """One actor: the run's job on its backend for the whole run (the library's extraction and
    matching stages with the run's settings), and resident descriptor sets.

    Its constructor never raises: a backend that cannot start here is raised by ``ready``, so that
    the driver gets the clatch error rather than a dead actor.
    """

    def __init__(
        self,
        job_settings: Dict[str, Any],
        cache_photos: int,
        exit_after: Optional[Tuple[str, int]] = None,
    ) -> None:
        self.error: Optional[BaseException] = None
        try:
            self.job = _job(**job_settings)
        except ClatchError as e:
            self.error = e
        self.cache: "OrderedDict[int, np.ndarray]" = OrderedDict()
        self.cache_photos = cache_photos
        self.fetched = 0
        self.done = {"extract": 0, "match": 0}
        # Test hook: (stage, n): the process exits during its task number n + 1 of that stage.
        self.exit_after = exit_after

    def _maybe_exit(self, stage: str) -> None:
        if self.exit_after is not None and self.exit_after == (stage, self.done[stage]):
            os._exit(1)

    def ready(self) -> bool:
        if self.error is not None:
            raise self.error
        return True

    def extract(self, paths: List[str], names: List[str]) -> Tuple[Any, ...]:
        self._maybe_exit("extract")
        photos = [Photo(*photo) for photo in self.job.extract_photos(paths, names)]
        meta = [(p.name, p.width, p.height, p.focal_35mm, p.keypoints) for p in photos]
        self.done["extract"] += 1
        return (meta, *[p.descriptors for p in photos])

    def match(self, pairs: List[Tuple[int, int]], refs: Dict[int, Any]) -> List[np.ndarray]:
        ray = _import_ray()
        self._maybe_exit("match")
        missing = [i for i in refs if i not in self.cache]
        for i, descriptors in zip(missing, ray.get([refs[i] for i in missing])):
            self.cache[i] = descriptors
        self.fetched += len(missing)
        for i in refs:
            self.cache.move_to_end(i)
        found = self.job.match_pairs(self.cache, pairs)
        while len(self.cache) > max(self.cache_photos, len(refs)):
            self.cache.popitem(last=False)
        self.done["match"] += 1
        return found

    def stats(self) -> Tuple[int, int]:
        """Descriptor sets fetched from the object store, blocks matched."""
        return self.fetched, self.done["match"]


class _Pool:
    """Actors, replaced when they die; ``run`` spreads tasks over them and runs a dead actor's
    unfinished tasks again."""

    def __init__(
        self,
        ray: Any,
        make: Callable[[int], Any],
        count: int,
        max_failures: int,
        kill_after: Optional[int] = None,
        start_timeout: Optional[float] = None,
    ) -> None:
        self.ray = ray
        # Test hook: the first actor is killed (``ray.kill``) once this many results came back.
        self.kill_after = kill_after
        self.results = 0
        self.make = make
        self.made = 0
        self.actors: List[Optional[Any]] = []
        self.max_failures = max_failures
        self.lost = 0
        # Results not fetched when a run stops early (an error): fetched on close, so that Ray does
        # not print each one's traceback again ("Unhandled error") after the error was raised.
        self.unfetched: List[Any] = []
        try:
            for _ in range(count):
                self._add()
            # The constructors' clatch errors (a backend unavailable on the actors) raised here.
            readies = [a.ready.remote() for a in self.actors if a is not None]
            try:
                self._get(lambda refs: ray.get(refs, timeout=start_timeout), readies)
            except ray.exceptions.GetTimeoutError:
                self.unfetched.extend(readies)
                raise _cluster_error(
                    "ActorsNotStarted",
                    f"the {count} Ray actors did not start within start_timeout={start_timeout} s: "
                    "the cluster's resources are busy (ray status shows them)",
                ) from None
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Ends every actor, and fetches (and drops) the results nobody will read."""
        for actor in self.actors:
            if actor is not None:
                self.ray.kill(actor)
        self.actors = [None] * len(self.actors)
        refs, self.unfetched = self.unfetched, []
        if refs:
            # Their actors are gone: each is an error at once, or ready within the deadline.
            ready, _ = self.ray.wait(refs, num_returns=len(refs), timeout=10)
            for ref in ready:
                try:
                    self.ray.get(ref)
                except Exception:
                    pass

    def fetches(self) -> int:
        """Descriptor sets the living actors fetched from the object store."""
        total = 0
        for actor in self.actors:
            if actor is not None:
                try:
                    total += self.ray.get(actor.stats.remote())[0]
                except self.ray.exceptions.RayActorError:
                    pass  # died after its last task: its work is in
        return total

    def _add(self) -> None:
        self.actors.append(self.make(self.made))
        self.made += 1

    def _lose(self, slot: int) -> None:
        actor = self.actors[slot]
        if actor is None:
            return  # already replaced: another of its tasks failed first
        # Unreachable rather than dead (ActorUnavailableError): it must not come back to the work.
        self.ray.kill(actor)
        self.actors[slot] = None
        self.lost += 1
        if self.lost > self.max_failures:
            raise _cluster_error(
                "ActorsDied",
                f"{self.lost} Ray actors died, more than max_actor_failures={self.max_failures}",
            )
        self._add()

    def _get(self, get: Callable[[Any], Any], refs: Any) -> Any:
        """``ray.get``, a task's clatch error raised as itself."""
        try:
            return get(refs)
        except self.ray.exceptions.RayTaskError as e:
            cause = getattr(e, "cause", None)
            if isinstance(cause, ClatchError):
                raise cause from None
            raise _cluster_error("TaskFailed", f"a clatch task failed on the cluster: {e}") from e

    def run(
        self, count: int, submit: Callable[[Any, int], Tuple[Any, Any]]
    ) -> Iterator[Tuple[int, Any, Any]]:
        """Runs tasks ``0 .. count - 1`` (``submit(actor, k)`` returns the reference to wait on and
        anything that goes with it) and yields ``(k, value, extra)`` as they finish; a task whose
        actor died is submitted again. ``self.rerun`` counts those."""
        self.rerun = 0
        queue: Deque[int] = deque(range(count))
        in_flight: Dict[Any, Tuple[int, int, Any]] = {}
        try:
            yield from self._run(queue, in_flight, submit)
        except BaseException:
            for ref, (_, _, extra) in in_flight.items():
                self.unfetched.append(ref)
                self.unfetched.extend(extra or [])
            raise

    def _run(
        self,
        queue: Deque[int],
        in_flight: Dict[Any, Tuple[int, int, Any]],
        submit: Callable[[Any, int], Tuple[Any, Any]],
    ) -> Iterator[Tuple[int, Any, Any]]:
        load: Dict[int, int] = {}
        while queue or in_flight:
            while queue:
                alive = [s for s, a in enumerate(self.actors) if a is not None]
                free = [s for s in alive if load.get(s, 0) < _PER_ACTOR]
                if not free:
                    break
                slot = min(free, key=lambda s: (load.get(s, 0), s))
                k = queue.popleft()
                ref, extra = submit(self.actors[slot], k)
                in_flight[ref] = (k, slot, extra)
                load[slot] = load.get(slot, 0) + 1
            (ref,), _ = self.ray.wait(list(in_flight), num_returns=1)
            k, slot, extra = in_flight.pop(ref)
            load[slot] -= 1
            try:
                value = self._get(self.ray.get, ref)
            except ClatchError:
                # The task's other results (an extraction's descriptor sets) hold the same error.
                self.unfetched.extend(extra or [])
                raise
            except self.ray.exceptions.RayActorError:
                self.unfetched.extend(extra or [])
                self._lose(slot)
                queue.appendleft(k)
                self.rerun += 1
                continue
            self.results += 1
            if self.kill_after is not None and self.results == self.kill_after and self.actors[0]:
                self.ray.kill(self.actors[0], no_restart=True)
            yield k, value, extra


def _blocks(pairs: Sequence[Tuple[int, int]], block_size: int) -> List[List[int]]:
    """Pair positions grouped by tile of the pair matrix (both photos' groups of ``block_size``),
    tiles in the order of their first pair."""
    tiles: Dict[Tuple[int, int], List[int]] = {}
    for position, (i, j) in enumerate(pairs):
        key = (min(i, j) // block_size, max(i, j) // block_size)
        tiles.setdefault(key, []).append(position)
    return sorted(tiles.values(), key=lambda block: block[0])


def _positive(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise _invalid("InvalidConfig", f"{name} must be a positive integer, got {value!r}")
    return int(value)


def match_folder(
    images: PathArg,
    database: PathArg,
    *,
    workspace: Optional[PathArg] = None,
    pairs: Optional[Sequence[Sequence[PhotoArg]]] = None,
    camera_k: Any = None,
    backend: str = "cpu",
    extractor: Optional[Mapping[str, Any]] = None,
    matcher: Optional[Mapping[str, Any]] = None,
    subpixel: str = "score",
    subpixel_radius: int = 3,
    max_pixels: int = 100_000_000,
    force: bool = False,
    verify: bool = True,
    match_list: bool = False,
    progress: Optional[Progress] = None,
    num_actors: Optional[int] = None,
    actor_options: Optional[Mapping[str, Any]] = None,
    block_size: int = 16,
    photos_per_task: int = 8,
    cache_photos: Optional[int] = None,
    max_actor_failures: Optional[int] = None,
    start_timeout: Optional[float] = 300.0,
    _exit_after: Optional[Tuple[str, int]] = None,
    _kill_after_results: Optional[int] = None,
) -> MatchFolderResult:
    """``clatch.colmap.match_folder`` over a Ray cluster: the same options, the same files.

    - ``num_actors``: actors to start (default: the cluster's CPUs divided by each actor's
      ``num_cpus``, at least 1, at most one per block).
    - ``actor_options``: ``ray.remote`` options of each actor (default ``{"num_cpus": 1}``; e.g.
      ``{"num_gpus": 1}`` with ``backend="cuda"``). Unless ``runtime_env`` is given, each actor's
      CPU backend uses ``num_cpus`` threads (``RAYON_NUM_THREADS``).
    - ``block_size``: photos per side of a tile of the pair matrix; a block is the tile's pairs.
    - ``photos_per_task``: photos per extraction task.
    - ``cache_photos``: descriptor sets each actor keeps resident (default ``4 * block_size``).
    - ``max_actor_failures``: actor deaths tolerated (default: ``num_actors``); one more raises
      ``ClusterError``.
    - ``start_timeout``: seconds to wait for the actors to start (``None``: no limit); past it,
      ``ClusterError`` (kind ``"ActorsNotStarted"``: the cluster has the resources, but they are
      busy). Resources the cluster does not have at all (``{"num_gpus": 1}`` without a GPU, more
      actors than fit) raise ``ClusterError`` (kind ``"ResourcesUnavailable"``) before any actor
      is made (``ray.cluster_resources()``).

    The driver verifies each pair as it writes its matches (on its CPU), as
    ``clatch.colmap.match_folder`` does (``verify=False``: the match list alone).

    The result's ``blocks``, ``blocks_rerun`` (blocks and extraction tasks run again because their
    actor died), ``actors_lost`` and ``descriptor_fetches`` say how the run went. The two
    underscored keywords are test hooks: ``_exit_after=(stage, n)`` makes the first actor's process
    exit during its task ``n + 1`` of ``stage`` (``"extract"`` or ``"match"``);
    ``_kill_after_results=n`` has the driver ``ray.kill`` the first actor once ``n`` results came
    back. A clatch error in a task (a photo that
    cannot be read, say) is raised as itself.
    """
    ray = _import_ray()
    block_size = _positive("block_size", block_size)
    photos_per_task = _positive("photos_per_task", photos_per_task)
    # What the actors need of the job: its extraction and matching settings.
    settings: Dict[str, Any] = dict(
        images=images,
        database=database,
        extractor=extractor,
        matcher=matcher,
        subpixel=subpixel,
        subpixel_radius=subpixel_radius,
        max_pixels=max_pixels,
    )
    # Every check before any work, here, where the errors are plain clatch errors; the driver only
    # writes, so its job runs on the CPU.
    job = _job(
        backend="cpu",
        workspace=workspace,
        pairs=pairs,
        camera_k=camera_k,
        force=force,
        verify=verify,
        match_list=match_list,
        **settings,
    )
    plan = job.plan()
    pair_list = plan.pairs
    blocks = _blocks(pair_list, block_size)
    options = dict(actor_options or {"num_cpus": 1})
    cpus = options.get("num_cpus", 1)
    if "runtime_env" not in options and cpus:
        options["runtime_env"] = {"env_vars": {"RAYON_NUM_THREADS": str(max(1, int(cpus)))}}
    if not ray.is_initialized():
        ray.init()
    demands = _demands(options)
    if num_actors is None:
        # As many as the cluster holds at once (by each resource an actor asks for), at most one
        # per block.
        total = ray.cluster_resources()
        fits = [int(float(total.get(name, 0)) // amount) for name, amount in demands.items()]
        if "CPU" not in demands:
            fits.append(int(total.get("CPU", 1)))
        num_actors = max(1, min(min(fits, default=1), max(1, len(blocks))))
    num_actors = _positive("num_actors", num_actors)
    _check_resources(ray, demands, num_actors)
    failures = num_actors if max_actor_failures is None else int(max_actor_failures)
    cache = _positive("cache_photos", cache_photos) if cache_photos is not None else 4 * block_size
    actor_class = ray.remote(_Worker)

    def make(index: int) -> Any:
        return actor_class.options(**options).remote(
            dict(settings, backend=backend),
            cache,
            _exit_after if index == 0 else None,
        )

    pool = _Pool(ray, make, num_actors, failures, _kill_after_results, start_timeout)
    writer = plan.open_writer()
    try:
        paths = [os.fspath(p) for p in plan.paths]
        names = plan.names
        total = len(names)
        descriptor_refs: Dict[int, Any] = {}

        # Extraction: photo tasks; photos written in image order as the earliest ones finish.
        tasks = [range(s, min(total, s + photos_per_task)) for s in range(0, total, photos_per_task)]

        def submit_extract(actor: Any, k: int) -> Tuple[Any, Any]:
            photos = tasks[k]
            refs = actor.extract.options(num_returns=len(photos) + 1).remote(
                paths[photos.start : photos.stop], names[photos.start : photos.stop]
            )
            return refs[0], refs[1:]

        waiting: Dict[int, Tuple[Any, Any]] = {}
        next_task = 0
        for k, meta, refs in pool.run(len(tasks), submit_extract):
            waiting[k] = (meta, refs)
            while next_task in waiting:
                meta, refs = waiting.pop(next_task)
                for image, (photo, ref) in zip(tasks[next_task], zip(meta, refs)):
                    writer.add_photo(*photo)
                    descriptor_refs[image] = ref
                next_task += 1
                if progress is not None:
                    progress("extract", tasks[next_task - 1].stop, total)
        rerun = pool.rerun

        # Matching: blocks of pairs; each pair's matches written in the pairs' order.
        def submit_match(actor: Any, k: int) -> Tuple[Any, Any]:
            block_pairs = [pair_list[p] for p in blocks[k]]
            refs = {i: descriptor_refs[i] for pair in block_pairs for i in pair}
            return actor.match.remote(block_pairs, refs), None

        done: Dict[int, np.ndarray] = {}
        cursor = 0
        for k, found, _ in pool.run(len(blocks), submit_match):
            done.update(zip(blocks[k], found))
            while cursor in done:
                i, j = pair_list[cursor]
                writer.add_matches(i, j, done.pop(cursor))
                cursor += 1
            if progress is not None:
                progress("match", cursor, len(pair_list))
        rerun += pool.rerun
        report = writer.finish()
        if report is None:  # a plan's writer always reports
            raise ClatchError("the plan's writer gave no report (a bug in clatch)", kind="Internal")
        return _result(
            report,
            blocks=len(blocks),
            blocks_rerun=rerun,
            actors_lost=pool.lost,
            descriptor_fetches=pool.fetches(),
        )
    except BaseException:
        writer.close()
        raise
    finally:
        pool.close()
