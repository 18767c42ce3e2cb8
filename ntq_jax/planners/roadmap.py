"""The ``"roadmap"`` planner: one probabilistic roadmap per environment, searched for every query.

All queries of a dataset live in one environment, so a roadmap built once
amortises every collision check over thousands of queries (PRM*, Karaman and
Frazzoli 2011):

1. **Build** (:func:`build_roadmap`): ``milestones`` valid states sampled at the
   planning padding; each joined to its ``k`` nearest neighbours under the
   robot's metric (default the PRM* rule ``k = ceil(e (1 + 1/d) log N)``;
   neighbours found by a KD-tree on the embedding ``metric_weights * q`` with
   the periodic coordinates on a circle, then re-ranked by the exact metric);
   every edge checked with the package's one batched ``steer_to`` and weighted
   by the metric. Deterministic for ``roadmap_seed``; cached per environment
   in memory and, with ``cache_dir``, on disk keyed by a fingerprint of the
   map, robot, padding and settings.
2. **Query** (:func:`plan_roadmap`, registered as ``"roadmap"``): each start is
   joined to the nearest milestones it reaches by ``steer_to`` (start to
   milestone), each goal to those that reach it (milestone to goal), and the
   start to its goal when the straight connection is free. Starts only have
   outgoing and goals only incoming edges, so every query is solved on the
   roadmap alone, independently of the other queries of the batch (and of the
   chunking). A* per query (:mod:`ntq_jax.planners.graph_search`, the robot's
   metric to the goal as heuristic, queries in parallel); the node sequence is shortcut
   (:mod:`ntq_jax.planners.smoothing`) and verified
   (:mod:`ntq_jax.planners.verify`).
3. **Growth**: a query whose ends are not connected is retried on a roadmap
   with twice the milestones (another sample), at most ``grow_rounds`` times,
   then reported ``NO_PATH``. Nothing loops unboundedly.

Measurements against BIT*: BENCHMARKS.md ("Roadmap planner").
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from ntq_jax.planners.graph_search import heuristic_metric, search_graph, shortest_paths
from ntq_jax.planners.options import (
    bool_option,
    int_option,
    motion_check_option,
    roadmap_memory_option,
)
from ntq_jax.planners.roadmap_build import (
    ALGORITHM_VERSION,
    MetricIndex,
    Roadmap,
    build_roadmap,
    prm_star_k,
    roadmap_for,
)
from ntq_jax.planners.roadmap_ends import query_edges
from ntq_jax.planners.smoothing import SHORTCUT_GROUP, shortcut_paths
from ntq_jax.planners.verify import finalize, motions_free, valid_queries
from ntq_jax.types import PlanResult, PlanStatus

__all__ = [
    "Roadmap",
    "MetricIndex",
    "prm_star_k",
    "build_roadmap",
    "roadmap_for",
    "plan_roadmap",
    "roadmap_defaults",
    "DEFAULT_MILESTONES",
    "ARM_DEFAULTS",
    "ALGORITHM_VERSION",
]

DEFAULT_MILESTONES = 20_000

#: The defaults for a 3-D serial arm (``robot.kind == "serial_arm"``, the Panda), where
#: the planar robots' defaults (20,000 milestones, PRM*'s k, every end joined to k
#: milestones, every check ``check``) would cost minutes. Measured on the Panda in
#: MotionBenchMaker's scenes (``benchmarks/bench_panda_plan.py``):
#:
#: * ``milestones``: see the value's comment;
#: * ``k`` 10 neighbours per milestone: in 7-D PRM*'s rule asks for 24-26, but
#:   shortcutting straightens the paths, so fewer, checked edges connect the
#:   same components at less than half the cost;
#: * ``attach`` 4: each query end tries its 4 nearest milestones first and only an
#:   end that reaches none of them the next 8, 16, ... (up to ``k``): joining the
#:   ends was most of the work of a pool of 10,000 queries with all k at once;
#: * ``edge_check`` ``"discretized"``: the certified check costs 20-60x the
#:   discretised one per motion on the Panda, so the roadmap's edges, the query
#:   ends and the shortcuts use the discretised check, and with ``check="certified"``
#:   only the final segments are certified; a shortcut segment that fails is
#:   replaced by the roadmap edges it skipped, certified in turn
#:   (:func:`ntq_jax.planners.verify.finalize`'s ``fallback``), so every SOLVED
#:   path's every segment passes ``check`` all the same.
ARM_DEFAULTS = {
    "milestones": 4000,
    "k": 10,
    "attach": 4,
    "edge_check": "discretized",
    "end_rounds": 8,
}


def roadmap_defaults(robot) -> dict:
    """The defaults of ``milestones``, ``k``, ``attach`` and ``edge_check`` for ``robot``
    (None: ``k`` by PRM*'s rule, ``attach`` = ``k``, ``edge_check`` = ``check``)."""
    if getattr(robot, "kind", None) == "serial_arm":
        return dict(ARM_DEFAULTS)
    return {
        "milestones": DEFAULT_MILESTONES,
        "k": None,
        "attach": None,
        "edge_check": None,
        "end_rounds": 0,
    }


# ---------------------------------------------------------------------------
# Queries
# ---------------------------------------------------------------------------

_GRAPHS: list = []  # (roadmap edges, SearchGraph) of the last GRAPHS_KEPT roadmaps searched
GRAPHS_KEPT = 4


def _graph_for(rm: Roadmap):
    """The roadmap's :class:`~ntq_jax.planners.graph_search.SearchGraph`, built once per
    roadmap object (identified by its ``edges`` array, which the entry keeps alive)."""
    for edges, graph in _GRAPHS:
        if edges is rm.edges:
            return graph
    graph = search_graph(len(rm.milestones), rm.edges, rm.costs, rm.milestones)
    _GRAPHS.append((rm.edges, graph))
    del _GRAPHS[:-GRAPHS_KEPT]
    return graph


def _search(
    robot,
    world,
    rm: Roadmap,
    q: np.ndarray,
    k: int,
    padding: float,
    threads: int,
    check: str,
    attach: int | None = None,
    end_rounds: int = 0,
    seed: int = 0,
    reach: int = 0,
    direct: bool = True,
) -> list[np.ndarray | None]:
    """Per query, the states of its shortest roadmap path (start ... goal), or None
    (see :func:`ntq_jax.planners.graph_search.shortest_paths`; the other arguments:
    :func:`ntq_jax.planners.roadmap_ends.query_edges`)."""
    ends = query_edges(
        robot,
        world,
        rm,
        MetricIndex(robot, world, rm.milestones),
        q,
        k,
        padding,
        check,
        attach,
        end_rounds,
        seed,
        reach,
        direct,
    )
    _, seqs = shortest_paths(
        _graph_for(rm), q[:, 1], ends.edges, heuristic_metric(robot), threads=threads
    )
    out: list[np.ndarray | None] = []
    for i, s in enumerate(seqs):
        if s is None:
            out.append(None)
            continue
        head = ends.start_chains.get(i, q[i, :1]) if len(s) else q[i, :1]
        tail = ends.goal_chains.get(i, q[i, 1:]) if len(s) else q[i, 1:]
        out.append(np.concatenate([head, rm.milestones[s], tail]))
    return out


def _pack(paths: list[np.ndarray | None], d: int) -> tuple[np.ndarray, np.ndarray]:
    """NaN-padded ``(K, L, d)`` paths and ``(K,)`` lengths (0 for None)."""
    lengths = np.array([0 if p is None else len(p) for p in paths], np.int32)
    out = np.full((len(paths), max(2, int(lengths.max(initial=0))), d), np.nan, np.float32)
    for i, p in enumerate(paths):
        if p is not None:
            out[i, : len(p)] = p
    return out, lengths


def plan_roadmap(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    milestones: int | None = None,
    k: int | None = None,
    grow_rounds: int = 2,
    roadmap_seed: int = 0,
    smooth: bool = True,
    smooth_chunk: int = SHORTCUT_GROUP,
    cache_dir: str | Path | None = None,
    threads: int | None = None,
    check: str = "discretized",
    attach: int | None = None,
    edge_check: str | None = None,
    end_rounds: int | None = None,
) -> PlanResult:
    """Plans every query on the environment's roadmap (the registry's ``"roadmap"``).

    Args:
        env: the environment (any robot).
        queries: ``(K, 2, d)`` (start, goal) states.
        padding: planning clearance (None: the environment's padding).
        seed: unused: the roadmap depends on ``roadmap_seed`` only, so a query's
            path does not depend on the batch or chunk it is planned in.
        milestones: roadmap size of the first round (doubled at each growth round);
            None: :data:`DEFAULT_MILESTONES`, or the serial arm's
            (:data:`ARM_DEFAULTS`).
        k: neighbours per milestone and candidate milestones per query end
            (None: :func:`prm_star_k`; the serial arm's: :data:`ARM_DEFAULTS`).
        grow_rounds: extra rounds on larger roadmaps for unconnected queries.
        roadmap_seed: seed of the milestone sample.
        smooth: shortcut the roadmap paths; ``smooth_chunk``: paths shortcut together
            (:func:`~ntq_jax.planners.smoothing.shortcut_paths`' ``chunk_size``).
        cache_dir: a folder to keep built roadmaps in (reused when the map, robot,
            padding and settings match).
        threads: search threads (None: the CPU count); the result does not depend on it.
        check: the motion check every segment of a SOLVED path passes,
            ``"discretized"`` (the paper's) or ``"certified"`` (see
            :func:`ntq_jax.robots.batch.motion_check`).
        attach: candidate milestones each query end tries first; an end that reaches
            none of them tries the next ``2 attach``, ``4 attach``, ... up to
            ``max(k, roadmap_ends.ATTACH_REACH)`` (None: the ``k`` nearest at once; the serial
            arm's: :data:`ARM_DEFAULTS`).
        edge_check: the motion check of the roadmap's edges, the query ends and the
            shortcuts (None: ``check``; the serial arm's: ``"discretized"``). When it
            differs from ``check``, the final paths are checked with ``check``, a
            failing shortcut segment is replaced by the roadmap edges it skipped, and
            a query whose path still fails is planned again with ``check`` for all
            but the roadmap's edges (its ends joined to their ``attach`` nearest
            milestones only; see :data:`ARM_DEFAULTS`).
        end_rounds: rounds of a small tree grown from each query end that reaches no
            milestone of the first roadmap (:mod:`ntq_jax.planners.end_trees`; None: 0,
            the serial arm's: :data:`ARM_DEFAULTS`).

    Returns:
        A verified :class:`PlanResult`; unconnected after the last round: NO_PATH.
        ``info`` holds the settings used (``milestones``, ``k``, ``attach``,
        ``edge_check``, ``end_rounds``), per-stage times, ``repaired`` (paths saved by
        the fallback to the roadmap edges), ``replanned`` (queries solved when
        planned again) and ``unreachable_ends`` (rejected queries not planned again
        because an end fails its own null motion under ``check``: with the certified
        check, a state within about half the check's margin of contact).

    Raises:
        TypeError, ValueError: an option of the wrong type or out of range (the
            message names it).
    """
    del seed
    defaults = roadmap_defaults(env.robot)
    milestones = int_option("roadmap", "milestones", milestones, 2, none_ok=True)
    k = int_option("roadmap", "k", k, 1, none_ok=True)
    attach = int_option("roadmap", "attach", attach, 1, none_ok=True)
    end_rounds = int_option("roadmap", "end_rounds", end_rounds, 0, 64, none_ok=True)
    opts = {
        "grow_rounds": int_option("roadmap", "grow_rounds", grow_rounds, 0, 8),
        "roadmap_seed": int_option("roadmap", "roadmap_seed", roadmap_seed, 0),
        "check": motion_check_option("roadmap", check),
        "milestones": defaults["milestones"] if milestones is None else milestones,
        "attach": defaults["attach"] if attach is None else attach,
        "end_rounds": defaults["end_rounds"] if end_rounds is None else end_rounds,
    }
    smooth = bool_option("roadmap", "smooth", smooth)
    smooth_chunk = int_option("roadmap", "smooth_chunk", smooth_chunk, 1)
    threads = int_option("roadmap", "threads", threads, 1, none_ok=True)
    opts["threads"] = (os.cpu_count() or 1) if threads is None else int(threads)
    opts["edge_check"] = motion_check_option(
        "roadmap", edge_check if edge_check is not None else defaults["edge_check"] or check
    )
    if cache_dir is not None and not isinstance(cache_dir, (str, os.PathLike)):
        raise TypeError(
            f"roadmap: cache_dir must be a folder path or None, got {cache_dir!r} "
            f"({type(cache_dir).__name__})"
        )
    opts["cache_dir"] = cache_dir
    k = defaults["k"] if k is None else k
    padding = env.resolve_padding(padding)
    q = np.asarray(queries, np.float32)
    t0 = time.perf_counter()
    nq, d = q.shape[0], q.shape[2]
    opts["k"] = prm_star_k(opts["milestones"], d) if k is None else int(k)
    roadmap_memory_option("roadmap", opts["milestones"], d, opts["k"], opts["grow_rounds"])
    status = np.full(nq, PlanStatus.NO_PATH, np.int8)
    status[~valid_queries(env, q, padding)] = PlanStatus.INVALID
    info: dict = {
        "planner": "roadmap",
        "milestones": opts["milestones"],
        "k": opts["k"],
        "attach": opts["attach"],
        "edge_check": opts["edge_check"],
        "end_rounds": opts["end_rounds"],
        "rounds": 0,
        "build_time": 0.0,
        "search_time": 0.0,
        "smooth_time": 0.0,
        "check_time": 0.0,
        "replanned": 0,
    }
    paths = _roadmap_paths(
        env,
        q,
        np.flatnonzero(status == PlanStatus.NO_PATH),
        padding,
        opts,
        info,
        opts["edge_check"],
    )
    res = _finish(
        env,
        q,
        paths,
        status,
        info,
        padding,
        opts["check"],
        opts["edge_check"],
        smooth,
        smooth_chunk,
    )
    if opts["edge_check"] != opts["check"]:
        res = _plan_rejected_again(
            env, q, paths, res, status, padding, opts, info, smooth, smooth_chunk
        )
    info["time"] = time.perf_counter() - t0
    return res


def _roadmap_paths(
    env, q: np.ndarray, rows: np.ndarray, padding: float, opts: dict, info: dict, query_check: str
) -> list[np.ndarray | None]:
    """The raw roadmap paths (start ... goal states, or None) of the queries ``rows``
    (the others: None), over the growth rounds, the queries' own edges (ends, direct
    connection, end trees) checked with ``query_check``; times and sizes added to
    ``info``."""
    paths: list[np.ndarray | None] = [None] * len(q)
    for r in range(opts["grow_rounds"] + 1):
        todo = np.asarray([i for i in rows if paths[i] is None], np.int64)
        if not len(todo):
            break
        tb = time.perf_counter()
        rm = roadmap_for(
            env,
            padding,
            milestones=opts["milestones"],
            k=opts["k"],
            roadmap_seed=opts["roadmap_seed"],
            round_=r,
            cache_dir=opts["cache_dir"],
            check=opts["edge_check"],
        )
        ts = time.perf_counter()
        found = _search(
            env.robot,
            env.world,
            rm,
            q[todo],
            opts["k"],
            padding,
            threads=opts["threads"],
            check=query_check,
            attach=opts["attach"],
            end_rounds=opts["end_rounds"] if r == 0 else 0,
            seed=opts["roadmap_seed"],
            reach=opts.get("reach", 0),
            direct=opts.get("direct", True),
        )
        for i, p in zip(todo, found):
            paths[i] = p
        info["rounds"] = r + 1
        info["build_time"] += ts - tb
        info["search_time"] += time.perf_counter() - ts
        info[f"round{r}"] = {
            "milestones": len(rm.milestones),
            "edges": len(rm.edges),
            "queries": len(todo),
        }
    return paths


def _finish(
    env,
    q: np.ndarray,
    paths: list,
    status: np.ndarray,
    info: dict,
    padding: float,
    check: str,
    edge_check: str,
    smooth: bool,
    smooth_chunk: int,
) -> PlanResult:
    """The raw paths shortcut (``edge_check``) and verified (``check``, with the raw paths as
    the fallback when the two differ)."""
    nq, d = q.shape[0], q.shape[2]
    status = status.copy()
    found = np.array([p is not None for p in paths], bool)
    status[found] = PlanStatus.SOLVED
    out, lengths = _pack(paths, d)
    fallback = None
    t1 = time.perf_counter()
    if smooth and found.any():
        sp, sl, _, idx = shortcut_paths(
            env.robot,
            env.world,
            out[found],
            lengths[found],
            padding,
            chunk_size=int(smooth_chunk),
            check=edge_check,
            return_index=True,
        )
        if edge_check != check:
            index = np.full((nq, sp.shape[1]), -1, np.int32)
            index[found] = idx
            fallback = (out, lengths, index)
        out = np.full((nq, sp.shape[1], d), np.nan, np.float32)
        lengths = lengths.copy()
        out[found], lengths[found] = sp, sl
    t2 = time.perf_counter()
    info["smooth_time"] += t2 - t1
    res = finalize(q, out, lengths, status, info, env, padding, check, fallback=fallback)
    info["check_time"] += time.perf_counter() - t2
    return res


def _replace_rows(res: PlanResult, rows: np.ndarray, sub: PlanResult) -> PlanResult:
    """``res`` with its rows ``rows`` replaced by those of ``sub`` (same query order)."""
    width = max(res.paths.shape[1], sub.paths.shape[1])
    k, _, d = res.paths.shape
    paths = np.full((k, width, d), np.nan, np.float32)
    paths[:, : res.paths.shape[1]] = res.paths
    paths[rows] = np.nan
    paths[rows, : sub.paths.shape[1]] = sub.paths
    lengths, costs, status = res.lengths.copy(), res.costs.copy(), res.status.copy()
    lengths[rows], costs[rows], status[rows] = sub.lengths, sub.costs, sub.status
    return PlanResult(
        paths[:, : max(2, int(lengths.max(initial=0)))], lengths, costs, status, res.info
    )


def _plan_rejected_again(
    env,
    q: np.ndarray,
    paths: list,
    res: PlanResult,
    status: np.ndarray,
    padding: float,
    opts: dict,
    info: dict,
    smooth: bool,
    smooth_chunk: int,
) -> PlanResult:
    """``res`` with the queries the final check rejected planned again with ``check`` on
    all but the roadmap's edges (a direct connection, an end's edge or an unrepairable
    shortcut failed it); ``info``'s times, ``replanned``, ``rejected`` and
    ``unreachable_ends`` updated."""
    d = q.shape[2]
    again = np.flatnonzero(~res.solved & np.array([p is not None for p in paths], bool))
    # an end no motion passing ``check`` can reach (certified: within about half the
    # check's margin of contact) fails its null motion: not worth planning again
    ends = q[again].reshape(-1, d)
    reachable = (
        motions_free(env.robot, env.world, ends, ends, padding, opts["check"])
        .reshape(-1, 2)
        .all(axis=1)
    )
    info["unreachable_ends"] = int((~reachable).sum())
    again = again[reachable]
    if len(again):
        sub_info = {
            "rounds": 0,
            "build_time": 0.0,
            "search_time": 0.0,
            "smooth_time": 0.0,
            "check_time": 0.0,
        }
        # the costly check on the queries' own edges: their ``attach`` nearest milestones
        # only, no end trees, and not the direct connection (it failed ``check``, or was
        # blocked already by ``edge_check``)
        sub_opts = dict(opts, end_rounds=0, reach=opts["attach"] or opts["k"], direct=False)
        sub_paths = _roadmap_paths(
            env, q[again], np.arange(len(again)), padding, sub_opts, sub_info, opts["check"]
        )
        sub = _finish(
            env,
            q[again],
            sub_paths,
            status[again],
            sub_info,
            padding,
            opts["check"],
            opts["check"],
            smooth,
            smooth_chunk,
        )
        res = _replace_rows(res, again, sub)
        for key in ("build_time", "search_time", "smooth_time", "check_time"):
            info[key] += sub_info[key]
        info["repaired"] += sub_info["repaired"]
        info["replanned"] = int(sub.solved.sum())
        info["rejected"] = int(res.info["rejected"]) - info["replanned"]
    return res
