"""The ``"astar"`` planner: batched exact grid A* on a 2-D configuration space, then shortcutting.

Grid level: :func:`astar` solves a batch of cell-to-cell queries on an
occupancy grid exactly (the graph of :mod:`ntq_jax.planners.grid_graph`: 8
neighbours, step costs 1 and sqrt(2), no corner cutting; the JPS search of
:mod:`ntq_jax.planners.jps`), one compiled program per grid shape, batch size
and options; :func:`astar_chunked` takes batches of any size. Statuses are
:class:`ntq_jax.types.PlanStatus` values; unsolved queries have ``cost = inf``
and an empty path.

Planner level: :func:`plan_astar` (registered as ``"astar"``) grids the
configuration box of a 2-D robot (the point robot, the 2-link arm) with
:func:`config_grid`, joins each query endpoint to a free cell centre it reaches
by ``steer_to``, runs :func:`astar_chunked`, shortcuts ``start, cell
centres..., goal`` (:mod:`ntq_jax.planners.smoothing`) and verifies every
segment (:mod:`ntq_jax.planners.verify`). Measurements: BENCHMARKS.md
("Classical planners").
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.batching import pad_rows, padded_chunks
from ntq_jax.geometry import rasterize
from ntq_jax.planners.env_cache import EnvCache
from ntq_jax.planners.grid_graph import MAX_GRID_SIDE, GridGraph, prepare_grid
from ntq_jax.planners.jps import (
    MAX_OPEN_CAPACITY,
    MAX_QUERIES_PER_CALL,
    cells_from_jump_points,
    search,
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

__all__ = [
    "AStarResult",
    "astar",
    "astar_chunked",
    "default_lanes",
    "default_max_path_len",
    "ConfigGrid",
    "config_grid",
    "grid_shape",
    "plan_astar",
]


# ---------------------------------------------------------------------------
# Grid A* (cells)
# ---------------------------------------------------------------------------


class AStarResult(NamedTuple):
    """Per-query results of :func:`astar` (N queries).

    Attributes:
        status: ``(N,)`` int8 :class:`ntq_jax.types.PlanStatus` values: SOLVED, NO_PATH
            (start and goal in different components), INVALID (start or goal
            outside the grid or occupied), TIMEOUT (``open_capacity``,
            ``max_waypoints`` or ``max_path_len`` too small: raise them).
        cost: ``(N,)`` float32 path cost in cells (straight step 1, diagonal
            step sqrt(2)); ``inf`` unless solved.
        path: ``(N, max_path_len, 2)`` int32 cells ``(row, col)``, start first
            and goal last, every step to one of the 8 neighbours, padded with -1.
        path_len: ``(N,)`` int32 number of valid cells in ``path`` (0 unless solved).
        waypoints: ``(N, max_waypoints, 2)`` int32 the path's jump points, start
            first and goal last, padded with -1: consecutive waypoints are joined
            by a straight or diagonal line of cells.
        num_waypoints: ``(N,)`` int32 number of valid waypoints (0 unless solved).
    """

    status: Array
    cost: Array
    path: Array
    path_len: Array
    waypoints: Array
    num_waypoints: Array


def default_max_path_len(shape) -> int:
    """Default path buffer: ``2 * (H + W)`` cells (a path may need more in mazes)."""
    h, w = shape
    return 2 * (h + w)


def default_lanes(shape, n: int) -> int:
    """Search lanes: about 6 MB of per-lane state, between 8 and 64, at most ``n``."""
    h, w = shape
    return int(max(1, min(n, max(8, min(64, (6 << 20) // max(1, 4 * h * w))))))


def _check_sizes(shape, n: int, max_path_len, max_waypoints, open_capacity) -> tuple[int, int]:
    """Validates the batch and buffer sizes; returns ``(max_path_len, max_waypoints)``."""
    if n > MAX_QUERIES_PER_CALL:
        raise ValueError(
            f"at most {MAX_QUERIES_PER_CALL} queries per astar call, got {n}: use astar_chunked"
        )
    if min(shape) < 1:
        raise ValueError(
            f"astar: the grid of shape {tuple(shape)} has no cell; pass a grid "
            "with at least 1 row and 1 column"
        )
    if max(shape) > MAX_GRID_SIDE:
        raise ValueError(f"grid sides must be <= {MAX_GRID_SIDE}, got {shape}")
    max_len = int(max_path_len) if max_path_len is not None else default_max_path_len(shape)
    jmax = int(max_waypoints)
    if not 1 <= int(open_capacity) <= MAX_OPEN_CAPACITY:
        raise ValueError(f"open_capacity must be in [1, {MAX_OPEN_CAPACITY}], got {open_capacity}")
    if max_len < 1 or jmax < 2:
        raise ValueError(f"need max_path_len >= 1 and max_waypoints >= 2, got {max_len}, {jmax}")
    return max_len, jmax


def astar(
    occ,
    starts,
    goals,
    *,
    max_path_len: int | None = None,
    max_waypoints: int = 128,
    lanes: int | None = None,
    open_capacity: int = 256,
    trace_steps: int = 4,
) -> AStarResult:
    """Solves a batch of grid shortest-path queries exactly (8-connected, no corner cutting).

    Args:
        occ: ``(H, W)`` bool occupancy grid (True = occupied; other dtypes are
            refused, see :func:`prepare_grid`), or a :class:`GridGraph` from
            :func:`prepare_grid` (faster for repeated calls).
        starts, goals: ``(N, 2)`` int cells ``(row, col)`` (``row`` indexes
            the first axis of ``occ``, the ``y`` cell).
        max_path_len: length ``L`` of the returned cell path buffer (default
            :func:`default_max_path_len`); a longer path is a TIMEOUT.
        max_waypoints: length ``J`` of the returned waypoint buffer (the path's
            jump points); a path with more is a TIMEOUT.
        lanes: queries searched simultaneously (default :func:`default_lanes`;
            ``4 * H * W`` bytes per lane).
        open_capacity: open-list entries per lane; an overflow is a TIMEOUT.
            JPS open lists are small on maps of boxes, large on salt-and-pepper noise.
        trace_steps: parent links followed per loop iteration when tracing a path.

    Returns:
        An :class:`AStarResult`. Every call with the same grid shape, batch size
        and options (a grid or its :class:`GridGraph` alike) reuses one compiled
        program. ``occ`` must be concrete (the tables are built on the host).

    Raises:
        ValueError: on bad shapes, a grid that is not bool or has no cell,
            ``N > MAX_QUERIES_PER_CALL`` (use :func:`astar_chunked`) or a grid
            side above ``MAX_GRID_SIDE``.
        TypeError: if ``occ`` is a traced grid (see :func:`prepare_grid`).
    """
    graph = occ if isinstance(occ, GridGraph) else prepare_grid(occ)  # host tables, no program
    return _search_batch(
        graph,
        starts,
        goals,
        max_path_len=max_path_len,
        max_waypoints=max_waypoints,
        lanes=lanes,
        open_capacity=open_capacity,
        trace_steps=trace_steps,
    )


def _astar(
    graph: GridGraph,
    starts,
    goals,
    *,
    max_path_len: int | None,
    max_waypoints: int,
    lanes: int | None,
    open_capacity: int,
    trace_steps: int,
) -> AStarResult:
    """:func:`astar` on a prepared grid (traced; one program per grid shape, batch size, options)."""
    h, w = graph.occ.shape
    starts = jnp.asarray(starts)
    goals = jnp.asarray(goals)
    if starts.ndim != 2 or starts.shape[-1] != 2 or goals.shape != starts.shape:
        raise ValueError(
            f"starts and goals must both be (N, 2) (row, col) cells, got {starts.shape} "
            f"and {goals.shape}"
        )
    starts = starts.astype(jnp.int32)
    goals = goals.astype(jnp.int32)
    n = starts.shape[0]
    max_len, jmax = _check_sizes((h, w), n, max_path_len, max_waypoints, open_capacity)
    nl = int(lanes) if lanes is not None else default_lanes((h, w), n)
    if n == 0:
        return AStarResult(
            jnp.zeros(0, jnp.int8),
            jnp.zeros(0, jnp.float32),
            jnp.zeros((0, max_len, 2), jnp.int32),
            jnp.zeros(0, jnp.int32),
            jnp.zeros((0, jmax, 2), jnp.int32),
            jnp.zeros(0, jnp.int32),
        )

    def flat(c):
        inside = (c[:, 0] >= 0) & (c[:, 0] < h) & (c[:, 1] >= 0) & (c[:, 1] < w)
        f = jnp.where(inside, c[:, 0] * w + c[:, 1], 0)
        return f, inside & ~graph.occ.reshape(-1)[f]

    sf, s_ok = flat(starts)
    gf, g_ok = flat(goals)
    valid = s_ok & g_ok
    trivial = valid & (sf == gf)
    queued = valid & ~trivial & (graph.label[sf] == graph.label[gf])
    order = jnp.argsort(~queued, stable=True)  # the queries to search first
    nq = jnp.sum(queued).astype(jnp.int32)

    status, cost, jp, njp = search(
        graph,
        sf[order],
        gf[order],
        nq,
        lanes=nl,
        cap=int(open_capacity),
        max_jp=jmax,
        trace_steps=int(trace_steps),
    )
    inv = jnp.argsort(order)
    status, cost, jp, njp = status[inv], cost[inv], jp[inv], njp[inv]
    status = jnp.where(
        queued,
        status,
        jnp.where(
            ~valid, PlanStatus.INVALID, jnp.where(trivial, PlanStatus.SOLVED, PlanStatus.NO_PATH)
        ),
    )
    cost = jnp.where(trivial, 0.0, cost)
    jp = jnp.where(trivial[:, None] & (jnp.arange(jmax) == 0)[None, :], sf[:, None], jp)
    njp = jnp.where(trivial, 1, njp)
    wps, path, plen = cells_from_jump_points(jp, njp, w, max_len)
    status = jnp.where(
        (status == PlanStatus.SOLVED) & (plen > max_len), PlanStatus.TIMEOUT, status
    ).astype(jnp.int8)
    ok = status == PlanStatus.SOLVED
    return AStarResult(
        status=status,
        cost=jnp.where(ok, cost, jnp.inf).astype(jnp.float32),
        path=jnp.where(ok[:, None, None], path, -1),
        path_len=jnp.where(ok, plen, 0).astype(jnp.int32),
        waypoints=jnp.where(ok[:, None, None], wps, -1),
        num_waypoints=jnp.where(ok, njp, 0).astype(jnp.int32),
    )


_STATIC_ARGS = ("max_path_len", "max_waypoints", "lanes", "open_capacity", "trace_steps")
_search_batch = jax.jit(_astar, static_argnames=_STATIC_ARGS)


def astar_chunked(occ, starts, goals, *, chunk_size: int = 1024, **options) -> AStarResult:
    """Runs :func:`astar` over a batch of any size in fixed-size chunks (one compiled program).

    The batch is split into chunks of ``chunk_size`` queries; the last one is
    padded with invalid queries, so every call has the same shapes and the
    program compiles once per grid shape, chunk size and options. All chunks
    are dispatched before the results are gathered.

    Args:
        occ: ``(H, W)`` bool occupancy grid or a :class:`GridGraph`.
        starts: ``(N, 2)`` int start cells ``(row, col)``; any ``N >= 0``.
        goals: ``(N, 2)`` int goal cells ``(row, col)``.
        chunk_size: queries per call (at most ``MAX_QUERIES_PER_CALL``).
        **options: passed to :func:`astar` (``max_path_len``, ``lanes``, ...).

    Returns:
        An :class:`AStarResult` of NumPy arrays with ``N`` rows.
    """
    if not 1 <= int(chunk_size) <= MAX_QUERIES_PER_CALL:
        raise ValueError(f"chunk_size must be in [1, {MAX_QUERIES_PER_CALL}], got {chunk_size}")
    chunk = int(chunk_size)
    graph = occ if isinstance(occ, GridGraph) else prepare_grid(occ)
    starts = np.asarray(starts, np.int64).reshape(-1, 2)
    goals = np.asarray(goals, np.int64).reshape(-1, 2)
    if starts.shape != goals.shape:
        raise ValueError(
            f"starts and goals must have the same shape, got {starts.shape} and {goals.shape}"
        )
    n = starts.shape[0]
    # the clipping keeps far-away cells invalid (outside the grid) and inside int32;
    # an empty batch runs one chunk of invalid queries, for the result's shapes
    cells = [
        pad_rows(np.clip(c, -1, np.iinfo(np.int32).max).astype(np.int32), max(n, 1), -1)
        for c in (starts, goals)
    ]
    pending = [
        (m, astar(graph, s, g, **options))
        for _, m, (s, g), _ in padded_chunks(cells, chunk, fill=-1)
    ]
    parts = [jax.tree.map(lambda x, m=m: np.asarray(x)[:m], r) for m, r in pending]
    return AStarResult(*(np.concatenate(xs)[:n] for xs in zip(*parts)))


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
    check_option_names("astar", plan_astar, astar_options, extra=_STATIC_ARGS)
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
