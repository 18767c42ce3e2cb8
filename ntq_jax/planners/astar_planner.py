"""The ``"astar"`` planner: grid A* on a 2-D robot's configuration space, then shortcutting.

:func:`plan_astar` (registered as ``"astar"``) grids the configuration box of a 2-D
robot (the point robot, the 2-link arm) with :func:`config_grid`, joins each query
endpoint to a free cell centre it reaches by ``steer_to``, runs the grid search
(:func:`ntq_jax.planners.astar.astar_chunked`), shortcuts ``start, cell centres...,
goal`` (:mod:`ntq_jax.planners.smoothing`) and verifies every segment
(:mod:`ntq_jax.planners.verify`). Measurements: BENCHMARKS.md ("Classical planners").
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import numpy as np

from ntq_jax.geometry import rasterize
from ntq_jax.planners.astar import STATIC_ARGS, astar_chunked
from ntq_jax.planners.env_cache import EnvCache
from ntq_jax.planners.grid_graph import MAX_GRID_SIDE, GridGraph, prepare_grid
from ntq_jax.planners.jps import (
    MAX_OPEN_CAPACITY,
    MAX_QUERIES_PER_CALL,
)
from ntq_jax.planners.options import (
    bool_option,
    check_option_names,
    float_option,
    int_option,
    motion_check_option,
    unsupported_robot,
)
from ntq_jax.planners.smoothing import SHORTCUT_GROUP, shortcut_paths
from ntq_jax.planners.verify import finalize, valid_queries
from ntq_jax.robots.batch import steer_to_pairs, valid_states
from ntq_jax.types import PlanResult, PlanStatus

Array = jax.Array

__all__ = ["ConfigGrid", "config_grid", "grid_shape", "map_grid", "plan_astar"]


# ---------------------------------------------------------------------------
# The "astar" planner (configuration space)
# ---------------------------------------------------------------------------


class ConfigGrid(NamedTuple):
    """A gridded 2-D configuration box: ``occ (H, W)`` bool, ``lo (2,)`` float64, ``resolution``,
    and the grid's search tables ``graph``."""

    occ: np.ndarray
    lo: np.ndarray
    resolution: float
    graph: GridGraph


_GRIDS = EnvCache(per_env=4)


def config_grid(env, resolution: float, padding: float) -> ConfigGrid:
    """The occupancy grid of ``env``'s 2-D configuration box (cached per env, resolution, padding).

    Cell ``(i, j)`` (row ``i`` = second coordinate, column ``j`` = first) is
    occupied when its centre ``lo + ((j + 0.5) r, (i + 0.5) r)`` is not a valid
    state. For the point robot this equals ``env.rasterize(resolution, padding)``;
    for a point robot on a map imported from a grid (``env.grid``) at the grid's own
    resolution and padding 0 it is the map's own occupancy grid, read as is.
    """
    why = unsupported_robot("astar", env)
    if why:
        raise ValueError(why)
    resolution = float_option("astar", "resolution", resolution)
    grid_shape(env, resolution)  # 2 x 2 to MAX_GRID_SIDE cells a side, before building anything
    robot, world = env.robot, env.world
    own = map_grid(env)
    if own is not None and (float(resolution) != own.resolution or float(padding) != 0.0):
        own = None
    return _GRIDS.get(
        env,
        (float(resolution), float(padding)),
        lambda: _build_config_grid(robot, world, float(resolution), float(padding), own),
    )


def map_grid(env):
    """The occupancy grid a point robot's map was imported from (``env.grid``), or None.

    The grid A* planner plans on it, at its own resolution (the ``resolution``
    option is then ignored): cells are the map's cells, with no re-rasterisation.
    """
    grid = getattr(env, "grid", None)
    return grid if grid is not None and env.robot.kind == "point" else None


def grid_shape(env, resolution: float) -> tuple[int, int]:
    """``(H, W)`` of the grid :func:`config_grid` builds at ``resolution``; ValueError if it has
    fewer than 2 cells or more than ``MAX_GRID_SIDE`` cells along a side.

    ``W = round((hi_0 - lo_0) / resolution)`` and ``H`` likewise over the
    configuration box ``[lo, hi]`` (for the point robot, the workspace bounds:
    the same sizes as :func:`ntq_jax.geometry.rasterize`).
    """
    lo, hi = (np.asarray(v, np.float64) for v in env.robot.config_bounds(env.world))
    ext = hi[:2] - lo[:2]
    w, h = (int(round(e / resolution)) for e in ext)
    box = f"the {ext[0]:g} x {ext[1]:g} configuration box of {env.name}"
    if min(h, w) < 2:
        raise ValueError(
            f"astar: resolution {resolution:g} is too coarse: it grids {box} into "
            f"{w} x {h} cells and the grid needs at least 2 x 2; use a resolution "
            f"<= {float(ext.min()) / 2:g}"
        )
    if max(h, w) > MAX_GRID_SIDE:
        raise ValueError(
            f"astar: resolution {resolution:g} is too fine: it grids {box} into "
            f"{w} x {h} cells and a side may have at most {MAX_GRID_SIDE}; use a "
            f"resolution >= {float(ext.max()) / MAX_GRID_SIDE:.3g}"
        )
    return h, w


def _build_config_grid(robot, world, resolution: float, padding: float, own=None) -> ConfigGrid:
    lo, hi = (np.asarray(v, np.float64) for v in robot.config_bounds(world))
    if own is not None:
        occ = own.occupied
    elif robot.kind == "point":
        occ = rasterize(world, resolution, padding)
    else:
        w = int(round((hi[0] - lo[0]) / resolution))
        h = int(round((hi[1] - lo[1]) / resolution))
        xs = lo[0] + (np.arange(w) + 0.5) * resolution
        ys = lo[1] + (np.arange(h) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        pts = np.stack([gx.ravel(), gy.ravel()], 1).astype(np.float32)
        occ = ~valid_states(robot, world, pts, padding).reshape(h, w)
    occ = np.asarray(occ, bool)
    return ConfigGrid(occ, lo, resolution, prepare_grid(occ))


_NEIGH = np.array(
    [(0, 0), (0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)], np.int64
)


def _snap(
    robot,
    world,
    grid: ConfigGrid,
    pts: np.ndarray,
    padding: float,
    to_cell: bool,
    check: str = "discretized",
):
    """Per point, the nearest free cell of its 3x3 neighbourhood joined to it by steer_to
    (point -> centre, or centre -> point with ``to_cell``).

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
    centre = np.stack(
        [grid.lo[0] + (cc[..., 1] + 0.5) * r, grid.lo[1] + (cc[..., 0] + 0.5) * r], -1
    ).astype(np.float32)  # (N, 9, 2)
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
        vis = steer_to_pairs(
            robot, world, *((cen, p) if to_cell else (p, cen)), padding, check=check
        )
        best[idx[vis]] = c[vis]
    cells = np.where(best[:, None] >= 0, cand[np.arange(n), np.maximum(best, 0)], -1)
    return cells


def _cell_paths(grid: ConfigGrid, q: np.ndarray, cells: np.ndarray, plen: np.ndarray):
    """``start, cell centres..., goal`` as NaN-padded float32 paths ``(M, L, d)`` and their lengths."""
    m, d = q.shape[0], q.shape[2]
    width = int(plen.max(initial=0)) + 2
    paths = np.full((m, width, d), np.nan, np.float32)
    if m:
        r = grid.resolution
        cen = np.stack(
            [
                grid.lo[0] + (cells[:, : width - 2, 1] + 0.5) * r,
                grid.lo[1] + (cells[:, : width - 2, 0] + 0.5) * r,
            ],
            -1,
        ).astype(np.float32)
        inner = np.arange(width - 2)[None, :] < plen[:, None]
        paths[:, 1 : width - 1] = np.where(inner[:, :, None], cen, np.nan)
        paths[:, 0] = q[:, 0]
        paths[np.arange(m), plen + 1] = q[:, 1]
    return paths, plen + 2


def _check_astar_options(options: dict) -> None:
    """Types and ranges of the :func:`astar` options ``plan_astar`` forwards."""
    for name, lo, hi, none_ok in (
        ("max_path_len", 1, None, True),
        ("max_waypoints", 2, None, False),
        ("lanes", 1, None, True),
        ("open_capacity", 1, MAX_OPEN_CAPACITY, False),
        ("trace_steps", 1, None, False),
    ):
        if name in options:
            int_option("astar", name, options[name], lo, hi, none_ok=none_ok)


def plan_astar(
    env,
    queries,
    *,
    padding: float,
    seed: int = 0,
    resolution: float = 0.1,
    smooth: bool = True,
    chunk_size: int = 1024,
    smooth_chunk: int = SHORTCUT_GROUP,
    check: str = "discretized",
    **astar_options,
) -> PlanResult:
    """Grid A* + shortcutting for a 2-D configuration space (the registry's ``"astar"``).

    Args:
        env: the environment (point robot or 2-link arm).
        queries: ``(K, 2, 2)`` (start, goal) states.
        padding: planning clearance (a number).
        seed: unused (deterministic).
        resolution: grid cell side (workspace units or radians): a finite number
            > 0 giving 2 to ``MAX_GRID_SIDE`` cells along each side of the
            configuration box (see :func:`grid_shape`). Ignored for a point robot
            on a map imported from a grid: A* plans on the map's own cells
            (:func:`map_grid`).
        smooth: shortcut the grid paths (greedy farthest-visible rule).
        chunk_size: queries per :func:`astar` call; ``smooth_chunk``: paths shortcut
            together (:func:`~ntq_jax.planners.smoothing.shortcut_paths`' ``chunk_size``).
        check: the motion check of the snapping, the shortcuts and the final
            verification (see :func:`ntq_jax.robots.batch.motion_check`).
        **astar_options: :func:`astar` options (``open_capacity``, ``max_path_len``, ...).

    Returns:
        A verified :class:`PlanResult`; an endpoint that reaches no free cell
        centre is NO_PATH (counted in ``info["unsnapped"]``), a full A* buffer TIMEOUT.

    Raises:
        TypeError, ValueError: an unknown option, or an option of the wrong type
            or out of range (the message names it); a robot that is not 2-D.
    """
    del seed  # deterministic
    check_option_names("astar", plan_astar, astar_options, extra=STATIC_ARGS)
    resolution = float_option("astar", "resolution", resolution)
    smooth = bool_option("astar", "smooth", smooth)
    chunk_size = int_option("astar", "chunk_size", chunk_size, 1, MAX_QUERIES_PER_CALL)
    smooth_chunk = int_option("astar", "smooth_chunk", smooth_chunk, 1)
    check = motion_check_option("astar", check)
    _check_astar_options(astar_options)
    own = map_grid(env)
    if own is not None:
        h, w = own.occupied.shape
        if min(h, w) < 2:
            raise ValueError(
                f"astar: {env.name} was imported from a {w} x {h}-cell grid; grid A* "
                "plans on a grid map's own cells (the resolution option does not "
                "apply) and needs at least 2 x 2: import the map at a finer "
                "resolution, or use the roadmap or visgraph planner"
            )
        resolution = own.resolution
    q = np.asarray(queries, np.float32)
    t0 = time.perf_counter()
    grid = config_grid(env, resolution, float(padding))
    k, d = q.shape[0], q.shape[2]
    info: dict = {"planner": "astar", "resolution": float(resolution), "grid_shape": grid.occ.shape}
    if own is not None:
        info["map_grid"] = True
    status = np.full(k, PlanStatus.NO_PATH, np.int8)
    valid = valid_queries(env, q, padding)
    status[~valid] = PlanStatus.INVALID
    idx = np.flatnonzero(valid)
    s_cell = _snap(env.robot, env.world, grid, q[idx, 0], padding, False, check)  # start -> centre
    g_cell = _snap(env.robot, env.world, grid, q[idx, 1], padding, True, check)  # centre -> goal
    snapped = (s_cell[:, 0] >= 0) & (g_cell[:, 0] >= 0)
    info["unsnapped"] = int((~snapped).sum())
    idx, s_cell, g_cell = idx[snapped], s_cell[snapped], g_cell[snapped]
    t1 = time.perf_counter()
    res = astar_chunked(grid.graph, s_cell, g_cell, chunk_size=int(chunk_size), **astar_options)
    t2 = time.perf_counter()
    info["prep_time"], info["astar_time"] = t1 - t0, t2 - t1  # prep: grid, validity, snapping
    a_status = np.asarray(res.status)
    # the cells were snapped to free ones, so the search's INVALID cannot happen: NO_PATH
    status[idx] = np.where(a_status == PlanStatus.INVALID, PlanStatus.NO_PATH, a_status)
    ok = a_status == PlanStatus.SOLVED
    idx = idx[ok]
    paths, lengths = _cell_paths(
        grid, q[idx], np.asarray(res.path)[ok], np.asarray(res.path_len)[ok]
    )
    if smooth and len(idx):
        paths, lengths, _ = shortcut_paths(
            env.robot, env.world, paths, lengths, padding, chunk_size=int(smooth_chunk), check=check
        )
    t3 = time.perf_counter()
    info["smooth_time"] = t3 - t2
    full_paths = np.full((k, paths.shape[1], d), np.nan, np.float32)
    full_len = np.zeros(k, np.int32)
    full_paths[idx] = paths
    full_len[idx] = lengths
    out = finalize(q, full_paths, full_len, status, info, env, padding, check)
    info["check_time"] = time.perf_counter() - t3
    info["time"] = time.perf_counter() - t0
    return out
