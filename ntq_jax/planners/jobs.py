"""Planning a query pool: the run's planner, in resumable chunks on disk.

The planner runs over the pool in chunks of ``chunk`` queries; each
chunk's verified :class:`ntq_jax.types.PlanResult` is written atomically with
the queries it solved to ``<work>/plan_<start>_<stop>.npz``. A rerun reuses
every completed chunk whose queries match (whatever the chunk size was then)
and plans only the missing ranges. ``astar`` and ``visgraph`` are
deterministic, so the result does not depend on the chunk size; BIT* stops on
a time budget and is not (its per-chunk seed does not make it so), but its
completed chunks are kept all the same.

Results of the registry (:func:`ntq_jax.planners.plan`) are verified there; a
user's planner callable is verified here, once, by
:func:`ntq_jax.planners.verify.finalize`.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Callable, NamedTuple, Optional, Union

import numpy as np

from ntq_jax import artifacts
from ntq_jax.planners import plan
from ntq_jax.planners.path_modes import planner_smooth
from ntq_jax.planners.verify import finalize
from ntq_jax.progress import open_bar
from ntq_jax.types import PlanResult, PlanStatus

__all__ = [
    "PlannerSettings",
    "planner_options",
    "resolve_planner",
    "NamedPlanner",
    "PoolPlan",
    "chunk_ranges",
    "plan_chunk",
    "plan_pool",
    "seed_from_record",
]

_CHUNK_FILE = re.compile(r"plan_(\d+)_(\d+)\.npz")
_CHUNK_KEYS = ("queries", "paths", "lengths", "costs", "status", "rejected")


@dataclasses.dataclass(frozen=True)
class PlannerSettings:
    """One environment's settings of the classical planners (the defaults are the paper's).

    Attributes:
        name: the planner, ``astar``, ``visgraph``, ``bitstar`` or ``roadmap``.
        resolution: grid resolution of A* (workspace units per cell).
        milestones: roadmap size (``roadmap``; doubled on each growth round).
        neighbors: roadmap neighbours per milestone (None: PRM*'s rule).
        grow_rounds: roadmap growth rounds for unconnected queries.
        roadmap_seed: the roadmap's sampling seed.
        time_budget: BIT* seconds per query during data generation.
        eval_time_budget: BIT* seconds per query at evaluation.
        workers: BIT* worker processes (0 = number of cores).
        data_paths: the data planner's output before includeData
            (:mod:`ntq_jax.planners.path_modes`; None: the planner's default).
        motion_check: the evaluation's motion check (``certified`` or ``discretized``),
            used with ``evaluation=True``.
        data_check: the motion check of the data planner's paths (the paper's
            ``discretized``, or ``certified``: every data path proven free).
    """

    name: str = "astar"
    resolution: float = 0.1
    milestones: int = 20_000
    neighbors: Optional[int] = None
    grow_rounds: int = 2
    roadmap_seed: int = 0
    time_budget: float = 3.0
    eval_time_budget: float = 2.0
    workers: int = 0
    data_paths: Union[float, str, None] = None
    motion_check: str = "certified"
    data_check: str = "discretized"


def planner_options(
    settings: PlannerSettings, name: str | None = None, *, evaluation: bool = False
) -> dict:
    """The keyword options passed to ``ntq_jax.planners.plan`` for planner ``name``.

    ``name`` defaults to ``settings.name``; ``evaluation`` picks BIT*'s
    evaluation budget instead of the data-generation one, and the evaluation's
    motion check (``settings.motion_check``) for the planner's checks and the
    verification of its paths. Data generation uses ``settings.data_check`` (passed
    only when it is not the planners' default, the discretised check, the paper's),
    at the data padding, and passes the
    ``smooth`` option of ``settings.data_paths`` (when set) to ``astar`` and
    ``roadmap`` (:func:`ntq_jax.planners.path_modes.planner_smooth`).
    """
    ps = settings
    name = name or ps.name
    if evaluation:
        extra = {"check": ps.motion_check}
    else:
        extra = {} if ps.data_check == "discretized" else {"check": ps.data_check}
    smooth = None if evaluation else planner_smooth(ps.data_paths, name)
    if smooth is not None:
        extra["smooth"] = smooth
    if name == "astar":
        return {"resolution": ps.resolution, **extra}
    if name == "bitstar":
        budget = ps.eval_time_budget if evaluation else ps.time_budget
        return {"time_budget": budget, "workers": ps.workers, **extra}
    if name == "roadmap":
        return {
            "milestones": ps.milestones,
            "k": ps.neighbors,
            "grow_rounds": ps.grow_rounds,
            "roadmap_seed": ps.roadmap_seed,
            **extra,
        }
    return extra


def resolve_planner(planner, options: dict, cache_dir: Path | None = None) -> tuple[Callable, str]:
    """A callable ``(env, queries, *, padding, seed) -> PlanResult`` and its name.

    Args:
        planner: a name (``astar``, ``visgraph``, ``bitstar``, or any registered
            one; solved and verified by ``ntq_jax.planners.plan``) or a callable
            with that signature (e.g. a test's fake planner), returned as it is:
            :func:`plan_pool` verifies its results (``verify=True``).
        options: extra keyword options for a named planner.
        cache_dir: where the ``roadmap`` planner keeps its roadmaps (not part of
            ``options``, which are recorded in the datasets' metadata).
    """
    if callable(planner):
        return planner, getattr(planner, "__name__", "custom")
    name = str(planner)
    extra = {"cache_dir": cache_dir} if name == "roadmap" and cache_dir is not None else {}
    return NamedPlanner(name, dict(options), extra), name


class NamedPlanner:
    """``(env, queries, *, padding, seed) -> PlanResult`` of a registered planner and options.

    A plain picklable object (an executor sends it to its tasks); ``extra`` holds
    the options that are not part of the run's identity (the roadmap cache folder).
    """

    def __init__(self, name: str, options: dict, extra: dict | None = None):
        self.name, self.options, self.extra = name, dict(options), dict(extra or {})

    def __call__(self, env, queries, *, padding, seed=0):
        return plan(
            env,
            queries,
            planner=self.name,
            padding=padding,
            seed=seed,
            **self.options,
            **self.extra,
        )

    def with_options(self, **options) -> "NamedPlanner":
        """The same planner with ``options`` replaced (e.g. BIT*'s ``workers`` in a task)."""
        return NamedPlanner(self.name, {**self.options, **options}, self.extra)

    def __repr__(self) -> str:
        return f"NamedPlanner({self.name!r}, {self.options!r})"


class PoolPlan(NamedTuple):
    """A planned pool, merged over its chunks.

    Attributes:
        result: the verified :class:`PlanResult` of every pooled query (``info`` empty).
        rejected: ``(n,)`` bool, a path the planner reported solved failed
            verification (only for planners verified here; it counts as unsolved).
        reused: queries whose chunk was reused from disk.
    """

    result: PlanResult
    rejected: np.ndarray
    reused: int


def chunk_seed(seed: int, start: int) -> int:
    """The seed of the chunk starting at pool row ``start`` (distinct per chunk for BIT*)."""
    return (int(seed) * 1_000_003 + start) % (2**31 - 1)


def _completed_chunks(work: Path, n: int) -> dict[int, tuple[int, Path]]:
    """``start -> (stop, file)`` of the chunk files in ``work`` (the longest per start)."""
    done: dict[int, tuple[int, Path]] = {}
    for p in work.glob("plan_*_*.npz"):
        m = _CHUNK_FILE.fullmatch(p.name)
        if m:
            lo, hi = int(m.group(1)), int(m.group(2))
            if 0 <= lo < hi <= n and (lo not in done or done[lo][0] < hi):
                done[lo] = (hi, p)
    return done


def chunk_ranges(
    n: int, chunk: int, done: dict[int, tuple[int, Path]]
) -> list[tuple[int, int, Optional[Path]]]:
    """``(start, stop, file or None)`` covering ``0..n``: the completed chunks of
    ``done`` where they start, new ranges of at most ``chunk`` rows between them."""
    parts: list[tuple[int, int, Optional[Path]]] = []
    starts = sorted(done)
    i = 0
    while i < n:
        if i in done:
            hi, p = done[i]
            parts.append((i, hi, p))
        else:
            hi = min(i + chunk, min([s for s in starts if s > i] + [n]))
            parts.append((i, hi, None))
        i = hi
    return parts


def _load_chunk(path: Path, queries: np.ndarray) -> tuple[PlanResult, np.ndarray] | None:
    z = artifacts.load_npz(path)
    if (
        z is None
        or any(k not in z for k in _CHUNK_KEYS)
        or not np.array_equal(z["queries"], queries)
    ):
        return None
    return PlanResult(z["paths"], z["lengths"], z["costs"], z["status"], {}), z["rejected"]


def _plan_chunk(
    env, queries: np.ndarray, plan_fn: Callable, verify: bool | str, padding: float, seed: int
) -> tuple[PlanResult, np.ndarray]:
    raw = plan_fn(env, queries, padding=padding, seed=seed)
    k, d = queries.shape[0], queries.shape[2]
    if not verify:
        return raw, np.zeros(k, bool)
    paths = np.asarray(raw.paths, np.float32)
    if paths.ndim != 3 or paths.shape[0] != k or paths.shape[2] != d:
        raise ValueError(f"planner returned paths of shape {paths.shape}, expected ({k}, L, {d})")
    status = np.asarray(raw.status, np.int8)
    check = verify if isinstance(verify, str) else "discretized"
    res = finalize(
        queries,
        paths,
        np.asarray(raw.lengths, np.int32),
        status,
        dict(raw.info),
        env,
        padding,
        check,
    )
    return res, (status == PlanStatus.SOLVED) & ~res.solved


def _merge(parts, results, n: int, d: int) -> tuple[PlanResult, np.ndarray]:
    width = max([r.paths.shape[1] for r, _ in results] + [2])
    paths = np.full((n, width, d), np.nan, np.float32)
    lengths = np.zeros(n, np.int32)
    costs = np.full(n, np.inf)
    status = np.zeros(n, np.int8)
    rejected = np.zeros(n, bool)
    for (lo, hi, _), (r, rej) in zip(parts, results):
        paths[lo:hi, : r.paths.shape[1]] = r.paths
        lengths[lo:hi], costs[lo:hi], status[lo:hi], rejected[lo:hi] = (
            r.lengths,
            r.costs,
            r.status,
            rej,
        )
    return PlanResult(paths, lengths, costs, status, {}), rejected


#: Test hook: called with the path of every chunk file the driver writes (None: nothing).
chunk_written: Callable[[Path], None] | None = None

_TASK_ENVS: dict[str, object] = {}  # a task process's environments by fingerprint (see plan_chunk)


def plan_chunk(
    env_key: str | None,
    env,
    queries: np.ndarray,
    plan_fn: Callable,
    verify: bool | str,
    padding: float,
    seed: int,
) -> tuple[PlanResult, np.ndarray]:
    """One chunk, a pure function of its arguments: ``(verified result without info, rejected)``.

    Runs in the driver (local executor) or in a task (Ray). ``env_key`` (the
    environment's fingerprint, None in the driver) lets a task process keep ONE
    environment object per map across its tasks, so the planners' per-environment
    caches (grids, roadmaps in memory) stay warm.
    """
    if env_key is not None:
        env = _TASK_ENVS.setdefault(env_key, env)
        if len(_TASK_ENVS) > 8:
            _TASK_ENVS.pop(next(iter(_TASK_ENVS)))
    res, rej = _plan_chunk(env, queries, plan_fn, verify, padding, seed)
    return PlanResult(res.paths, res.lengths, res.costs, res.status, {}), rej


def plan_pool(
    env,
    pool: np.ndarray,
    plan_fn: Callable,
    *,
    verify: bool | str,
    padding: float,
    seed: int,
    chunk: int,
    work: Path,
    progress=None,
    desc: str = "plan",
    executor=None,
) -> PoolPlan:
    """Plans ``pool`` ``(n, 2, d)`` in chunks, reusing the completed chunk files in ``work``.

    Args:
        plan_fn: ``(env, queries, *, padding, seed) -> PlanResult`` (:func:`resolve_planner`).
        verify: verify ``plan_fn``'s results with ``verify.finalize`` (a user's
            callable; the registry's planners verify their own): ``True`` with the
            discretised check, a motion check's name (``"certified"``) with that one.
        padding: the planning clearance (a number).
        seed: the run's seed (each chunk gets :func:`chunk_seed`).
        chunk: queries per new chunk.
        work: the folder of the chunk files.
        progress: a progress bar request (:func:`ntq_jax.progress.open_bar`).
        executor: where the missing chunks run (:mod:`ntq_jax.executors`; None: in
            this process, in order). The results are written here, by the
            driver, atomically, each once, as they arrive; the ``roadmap``
            planner's first chunk runs alone first, so that the roadmap is built
            once (and cached in its folder) before the other chunks search it.
    """
    from ntq_jax.executors import LocalExecutor

    executor = executor or LocalExecutor()
    n, d = len(pool), pool.shape[2]
    parts = chunk_ranges(n, chunk, _completed_chunks(work, n))
    results: list = [None] * len(parts)
    reused, todo = 0, []
    with open_bar(progress, desc=desc, total=n, unit="query") as bar:
        for j, (lo, hi, path) in enumerate(parts):
            got = _load_chunk(path, pool[lo:hi]) if path is not None else None
            if got is not None:
                reused += hi - lo
                results[j] = got
                bar.update(hi - lo)
            else:
                if path is not None:  # stale or damaged: plan again
                    path.unlink(missing_ok=True)
                todo.append(j)
        if todo:
            env_key = None if executor.name == "local" else artifacts.fingerprint(env.to_json())
            task_fn = executor.adapt_planner(plan_fn)
            items = [
                (
                    env_key,
                    env,
                    pool[parts[j][0] : parts[j][1]],
                    task_fn,
                    verify,
                    padding,
                    chunk_seed(seed, parts[j][0]),
                )
                for j in todo
            ]
            first = (
                1
                if (
                    executor.slots > 1
                    and len(todo) > 1
                    and getattr(plan_fn, "name", None) == "roadmap"
                )
                else 0
            )
            for batch in ([(0, items[:first])] if first else []) + [(first, items[first:])]:
                off, its = batch
                for i, got in executor.imap_unordered(plan_chunk, its):
                    j = todo[off + i]
                    lo, hi, _ = parts[j]
                    res, rej = got
                    out = artifacts.save_npz(
                        work / f"plan_{lo:09d}_{hi:09d}.npz",
                        queries=pool[lo:hi],
                        paths=res.paths,
                        lengths=res.lengths,
                        costs=res.costs,
                        status=res.status,
                        rejected=rej,
                    )
                    if chunk_written is not None:
                        chunk_written(out)
                    results[j] = got
                    bar.update(hi - lo)
    result, rejected = _merge(parts, results, n, d)
    return PoolPlan(result, rejected, reused)


def seed_from_record(
    work: Path, record: Path, pool: np.ndarray, n_u: int, *, env_name: str, padding: float
) -> int:
    """Copies a record's chunk files (``scripts/record_paths.py``) into ``work``.

    The record's ``U/plan_<a>_<b>.npz`` become ``plan_<a>_<b>.npz`` and its
    ``N/plan_<a>_<b>.npz`` become ``plan_<n_u+a>_<n_u+b>.npz`` (the pooled rows),
    so that :func:`plan_pool` reuses them instead of planning those queries.
    Chunks beyond the pools are ignored (a larger record serves a smaller run).

    Returns:
        The number of queries seeded.

    Raises:
        ValueError: the record is of another map or padding, or a chunk's queries
            are not this run's (the message names the chunk).
        FileNotFoundError: no ``record.json`` in ``record``.
    """
    import json

    record = Path(record)
    meta = json.loads((record / "record.json").read_text())
    if meta.get("env") != env_name or not np.isclose(float(meta.get("padding", -1)), padding):
        raise ValueError(
            f"{record} records {meta.get('env')} at padding {meta.get('padding')}, "
            f"not {env_name} at {padding}: point data.per_env's paths_from at "
            "this map's record"
        )
    spans = {"U": (0, n_u), "N": (n_u, len(pool))}
    seeded = 0
    for name, (lo0, hi0) in spans.items():
        for f in sorted((record / name).glob("plan_*_*.npz")):
            m = _CHUNK_FILE.fullmatch(f.name)
            if m is None:
                continue
            a, b = lo0 + int(m.group(1)), lo0 + int(m.group(2))
            if b > hi0:
                continue
            with np.load(f) as z:
                same = np.array_equal(z["queries"], pool[a:b])
            if not same:
                raise ValueError(
                    f"{f}: its queries are not this run's pool rows {a}..{b} (the "
                    "record was made with another config, seed or sampler)"
                )
            dest = work / f"plan_{a:09d}_{b:09d}.npz"
            if not dest.exists():
                artifacts.write_bytes(dest, f.read_bytes())
            seeded += b - a
    return seeded
