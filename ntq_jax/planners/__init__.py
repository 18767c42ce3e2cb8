"""Classical planners behind one entry point: :func:`plan`.

Usage::

    import ntq_jax
    env = ntq_jax.make_env("point/3")
    res = ntq_jax.plan(env, queries)                         # grid A* + shortcutting
    res = ntq_jax.plan(env, queries, "visgraph", padding=0)  # exact point-robot optimum
    res = ntq_jax.plan(env, queries, "bitstar", time_budget=2.0, workers=2)

Every planner takes ``queries`` ``(K, 2, d)`` (start, goal) and returns a
:class:`PlanResult` with, per query, a NaN-padded path (start first and goal
last, exactly the query's float32 states), its waypoint count, its cost in the
``env.distance`` metric (float64 sum over segments) and a status:

* ``SOLVED = 0``: a path was found and EVERY segment passed ``env.steer_to``
  at the planning padding;
* ``NO_PATH = 1``: the planner proved (on its own representation) there is no
  path, or the path it found failed the exact check;
* ``TIMEOUT = 2``: the planner's budget ran out (BIT*'s time budget; A*'s
  open-list / path buffers);
* ``INVALID = 3``: the start or the goal is not a valid state at the planning
  padding (or not finite).

An unsolvable query never raises. ``padding=None`` plans in the environment's
own (data-generation) geometry, ``padding=0`` in the evaluation geometry.

Planners
--------
``"astar"`` (2-D configuration spaces: the point robot and the 2-link arm)
    The configuration box (``robot.config_bounds``: the workspace for the point
    robot, ``[-pi, pi)^2`` for the arm) is gridded at ``resolution`` (default
    0.1, workspace units or radians); a cell is free when its centre is a valid
    state (``env.is_valid``, the vmapped kernel; for the point robot this is
    ``env.rasterize``). Each query endpoint is joined to the nearest free cell
    of its 3 x 3 neighbourhood whose centre it reaches by ``steer_to`` (none:
    NO_PATH, counted in ``info["unsnapped"]``). Batched exact A* (JPS,
    :func:`ntq_jax.planners.astar.astar_chunked`) finds the 8-connected grid
    path, ``start, cell centres..., goal`` is shortcut with the greedy
    farthest-visible rule (:mod:`ntq_jax.planners.smoothing`, option
    ``smooth=True``), and every segment is verified with ``env.steer_to``.
    Options: ``resolution``, ``smooth``, ``chunk_size`` and any
    :func:`ntq_jax.planners.astar.astar` option (``open_capacity``,
    ``max_path_len``, ...).
``"visgraph"`` (point robot only)
    :class:`ntq_jax.planners.visgraph.VisGraph` (exact at padding 0 for boxes,
    see its docstring). Options: ``eps``, ``arc_step``, ``chunk_size``.
``"bitstar"`` (any robot; OMPL's BIT* in worker processes)
    :func:`ntq_jax.planners.ompl_bridge.plan_bitstar`. Options:
    ``time_budget`` (seconds per query, default 1.0), ``workers`` (0 = cores)
    and the other ``plan_bitstar`` options. Bridge statuses map as
    SOLVED -> SOLVED, NO_PATH -> TIMEOUT (BIT* is anytime: no solution within
    the budget does not prove there is none), INVALID -> INVALID, CRASHED and
    REJECTED -> NO_PATH (no verified path; the bridge's own status is kept in
    ``info["bitstar_status"]``).

Register your own with :func:`register_planner`.
"""

from __future__ import annotations

import functools
import math
import time
from typing import Callable, NamedTuple

import numpy as np

from ntq_jax.batching import map_chunks
from ntq_jax.planners.verify import CHECK_CHUNK, check_paths, finalize, valid_queries
from ntq_jax.types import STATUS_NAMES, PlannerFn, PlanResult, PlanStatus

SOLVED, NO_PATH, TIMEOUT, INVALID = (PlanStatus.SOLVED, PlanStatus.NO_PATH, PlanStatus.TIMEOUT,
                                     PlanStatus.INVALID)

_REGISTRY: dict[str, PlannerFn] = {}


def register_planner(name: str, fn: PlannerFn) -> None:
    """Registers (or replaces) a planner usable as ``plan(env, queries, name)``.

    Args:
        name: the planner's name.
        fn: ``fn(env, queries (K, 2, d) float32, *, padding: float, seed: int,
            **options) -> PlanResult``; ``padding`` is already resolved to a number.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"planner name must be a non-empty string, got {name!r}")
    if not callable(fn):
        raise TypeError(f"planner {name!r} must be callable, got {type(fn).__name__}")
    _REGISTRY[name] = fn


def available_planners() -> tuple[str, ...]:
    """Names of the registered planners, sorted."""
    return tuple(sorted(_REGISTRY))


def plan(env, queries, planner: str = "astar", *, padding: float | None = None, seed: int = 0,
         **options) -> PlanResult:
    """Plans a batch of queries with a registered planner.

    Args:
        env: an :class:`ntq_jax.Env`.
        queries: ``(K, 2, d)`` array of (start, goal) states.
        planner: ``"astar"``, ``"visgraph"``, ``"bitstar"`` or a registered name.
        padding: planning clearance; ``None`` = the environment's padding (the
            data-generation geometry), ``0`` = the evaluation geometry.
        seed: seed for randomised planners.
        **options: planner options (see the module docstring).

    Returns:
        A :class:`PlanResult`.

    Raises:
        ValueError: unknown planner (the message lists the available ones), bad
            query shape, or a planner that does not support the robot.
    """
    if planner not in _REGISTRY:
        raise ValueError(f"unknown planner {planner!r}; available: {', '.join(available_planners())}")
    pad = env.resolve_padding(padding)
    q = np.asarray(queries, np.float32)
    if q.ndim != 3 or q.shape[1:] != (2, env.dim):
        raise ValueError(f"queries must have shape (K, 2, {env.dim}) for {env.name}, got {q.shape}")
    return _REGISTRY[planner](env, q, padding=pad, seed=int(seed), **options)


# ---------------------------------------------------------------------------
# A* on a 2-D configuration-space grid
# ---------------------------------------------------------------------------

class ConfigGrid(NamedTuple):
    """A gridded 2-D configuration box: ``occ (H, W)`` bool, ``lo (2,)`` float64, ``resolution``."""

    occ: np.ndarray
    lo: np.ndarray
    resolution: float
    graph: object  # astar.GridGraph


@functools.lru_cache(maxsize=16)
def config_grid(env, resolution: float, padding: float) -> ConfigGrid:
    """The occupancy grid of ``env``'s 2-D configuration box (cached per env, resolution, padding).

    Cell ``(i, j)`` (row ``i`` = second coordinate, column ``j`` = first) is
    occupied when its centre ``lo + ((j + 0.5) r, (i + 0.5) r)`` is not a valid
    state. For the point robot this equals ``env.rasterize(resolution, padding)``.
    """
    from ntq_jax.planners.astar import prepare_grid

    if env.dim != 2:
        raise ValueError(f"the grid A* planner needs a 2-D configuration space (point robot or "
                         f"2-link arm); {env.name} has dimension {env.dim}: use 'bitstar'")
    if not (resolution > 0 and math.isfinite(resolution)):
        raise ValueError(f"resolution must be > 0, got {resolution!r}")
    lo, hi = (np.asarray(v, np.float64) for v in env.robot.config_bounds(env.world))
    if env.robot.kind == "point":
        occ = env.rasterize(resolution, padding=padding)
    else:
        w = int(round((hi[0] - lo[0]) / resolution))
        h = int(round((hi[1] - lo[1]) / resolution))
        xs = lo[0] + (np.arange(w) + 0.5) * resolution
        ys = lo[1] + (np.arange(h) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        pts = np.stack([gx.ravel(), gy.ravel()], 1).astype(np.float32)
        occ = ~map_chunks(lambda x: env.is_valid(x, padding=padding), pts, chunk=CHECK_CHUNK).astype(bool).reshape(h, w)
    occ = np.asarray(occ, bool)
    return ConfigGrid(occ, lo, float(resolution), prepare_grid(occ))


_NEIGH = np.array([(0, 0), (0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)],
                  np.int64)


def _snap(env, grid: ConfigGrid, pts: np.ndarray, padding: float, to_cell: bool):
    """Per point, the nearest free cell of its 3x3 neighbourhood joined to it by steer_to.

    Returns ``cells (N, 2)`` int (row, col), -1 where none.
    """
    n = pts.shape[0]
    h, w = grid.occ.shape
    r = grid.resolution
    base = np.floor((pts[:, ::-1].astype(np.float64) - grid.lo[::-1]) / r)
    base = np.where(np.isfinite(base), base, -10).astype(np.int64)  # (row, col)
    cand = base[:, None, :] + _NEIGH[None]  # (N, 9, 2)
    inside = (cand[..., 0] >= 0) & (cand[..., 0] < h) & (cand[..., 1] >= 0) & (cand[..., 1] < w)
    cc = np.clip(cand, 0, [h - 1, w - 1])
    free = inside & ~grid.occ[cc[..., 0], cc[..., 1]]
    centre = np.stack([grid.lo[0] + (cc[..., 1] + 0.5) * r,
                       grid.lo[1] + (cc[..., 0] + 0.5) * r], -1).astype(np.float32)  # (N, 9, 2)
    dist = np.linalg.norm(centre.astype(np.float64) - pts[:, None].astype(np.float64), axis=-1)
    dist = np.where(free, dist, np.inf)
    order = np.argsort(dist, axis=1, kind="stable")
    best = np.full(n, -1)
    todo = np.isfinite(dist[np.arange(n), order[:, 0]]) & np.isfinite(pts).all(1)
    for t in range(9):  # try candidates by distance; usually the first one works
        idx = np.flatnonzero(todo & (best < 0))
        if not len(idx):
            break
        c = order[idx, t]
        ok = np.isfinite(dist[idx, c])
        idx, c = idx[ok], c[ok]
        if not len(idx):
            continue
        p, cen = pts[idx], centre[idx, c]
        vis = map_chunks(lambda a, b: env.steer_to(a, b, padding=padding),
                         *((cen, p) if to_cell else (p, cen)), chunk=CHECK_CHUNK).astype(bool)
        best[idx[vis]] = c[vis]
    cells = np.where(best[:, None] >= 0, cand[np.arange(n), np.maximum(best, 0)], -1)
    return cells


def _plan_astar(env, q, *, padding, seed, resolution: float = 0.1, smooth: bool = True,
                chunk_size: int = 1024, smooth_chunk: int = 128, **astar_options) -> PlanResult:
    from ntq_jax.planners import astar as A
    from ntq_jax.planners.smoothing import shortcut_paths

    del seed  # deterministic
    t0 = time.perf_counter()
    grid = config_grid(env, float(resolution), float(padding))
    k, d = q.shape[0], q.shape[2]
    info: dict = {"planner": "astar", "resolution": float(resolution), "grid_shape": grid.occ.shape}
    status = np.full(k, NO_PATH, np.int8)
    valid = valid_queries(env, q, padding)
    status[~valid] = INVALID
    idx = np.flatnonzero(valid)
    s_cell = _snap(env, grid, q[idx, 0], padding, to_cell=False)  # start -> centre
    g_cell = _snap(env, grid, q[idx, 1], padding, to_cell=True)   # centre -> goal
    snapped = (s_cell[:, 0] >= 0) & (g_cell[:, 0] >= 0)
    info["unsnapped"] = int((~snapped).sum())
    idx, s_cell, g_cell = idx[snapped], s_cell[snapped], g_cell[snapped]
    t1 = time.perf_counter()
    res = A.astar_chunked(grid.graph, s_cell, g_cell, chunk_size=int(chunk_size), **astar_options)
    t2 = time.perf_counter()
    info["prep_time"], info["astar_time"] = t1 - t0, t2 - t1  # prep: grid, validity, snapping
    a_status = np.asarray(res.status)
    status[idx[a_status == A.NO_PATH]] = NO_PATH
    status[idx[a_status == A.CAPACITY]] = TIMEOUT
    status[idx[a_status == A.INVALID]] = NO_PATH  # cannot happen after snapping
    ok = a_status == A.SOLVED
    idx = idx[ok]
    cells = np.asarray(res.path)[ok]
    plen = np.asarray(res.path_len)[ok]
    m = len(idx)
    width = int(plen.max(initial=0)) + 2
    paths = np.full((m, width, d), np.nan, np.float32)
    if m:
        r = grid.resolution
        cen = np.stack([grid.lo[0] + (cells[:, :width - 2, 1] + 0.5) * r,
                        grid.lo[1] + (cells[:, :width - 2, 0] + 0.5) * r], -1).astype(np.float32)
        inner = np.arange(width - 2)[None, :] < plen[:, None]
        paths[:, 1:width - 1] = np.where(inner[:, :, None], cen, np.nan)
        paths[:, 0] = q[idx, 0]
        paths[np.arange(m), plen + 1] = q[idx, 1]
    lengths = plen + 2
    if smooth and m:
        paths, lengths, _ = shortcut_paths(env, paths, lengths, padding=padding,
                                           chunk_size=int(smooth_chunk))
    t3 = time.perf_counter()
    info["smooth_time"] = t3 - t2
    full_paths = np.full((k, paths.shape[1], d), np.nan, np.float32)
    full_len = np.zeros(k, np.int32)
    full_paths[idx] = paths
    full_len[idx] = lengths
    status[idx] = SOLVED
    out = finalize(q, full_paths, full_len, status, info, env, padding)
    info["check_time"] = time.perf_counter() - t3
    info["time"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------
# Visibility graph (point robot)
# ---------------------------------------------------------------------------

@functools.lru_cache(maxsize=16)
def _visgraph(env, padding: float, eps, arc_step):
    from ntq_jax.planners.visgraph import DEFAULT_ARC_STEP, VisGraph

    return VisGraph.build(env, padding, eps=eps,
                          arc_step=DEFAULT_ARC_STEP if arc_step is None else arc_step)


def _plan_visgraph(env, q, *, padding, seed, eps: float | None = None,
                   arc_step: float | None = None, chunk_size: int = 8192) -> PlanResult:
    from ntq_jax.planners import visgraph as V

    del seed
    if env.robot.kind != "point":
        raise ValueError(f"the 'visgraph' planner is for the point robot only; {env.name} has a "
                         f"{env.robot.kind!r} robot: use 'bitstar' (or 'astar' for the 2-link arm)")
    t0 = time.perf_counter()
    graph = _visgraph(env, float(padding), eps, arc_step)
    t1 = time.perf_counter()
    res = graph.plan(q, chunk_size=int(chunk_size))
    info = {"planner": "visgraph", "nodes": graph.num_nodes, "exact": graph.exact,
            "delta": graph.delta, "build_time": t1 - t0, "plan_time": time.perf_counter() - t1}
    status = np.select([res.status == V.SOLVED, res.status == V.INVALID], [SOLVED, INVALID],
                       NO_PATH).astype(np.int8)
    out = finalize(q, res.paths, res.path_lengths, status, info, env, padding)
    info["time"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------
# OMPL BIT*
# ---------------------------------------------------------------------------

from ntq_jax.planners import ompl_bridge  # noqa: E402 (its plan_bitstar is the adapter)


register_planner("astar", _plan_astar)
register_planner("visgraph", _plan_visgraph)
register_planner("bitstar", ompl_bridge.plan_bitstar)

__all__ = ["plan", "PlanResult", "register_planner", "available_planners", "check_paths",
           "valid_queries", "config_grid", "SOLVED", "NO_PATH", "TIMEOUT", "INVALID",
           "STATUS_NAMES"]
