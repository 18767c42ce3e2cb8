"""Batched exact grid A*: cell-to-cell queries on an occupancy grid, one compiled program.

Grid level: :func:`astar` solves a batch of cell-to-cell queries on an
occupancy grid exactly (the graph of :mod:`ntq_jax.planners.grid_graph`: 8
neighbours, step costs 1 and sqrt(2), no corner cutting; the JPS search of
:mod:`ntq_jax.planners.jps`), one compiled program per grid shape, batch size
and options; :func:`astar_chunked` takes batches of any size. Statuses are
:class:`ntq_jax.types.PlanStatus` values; unsolved queries have ``cost = inf``
and an empty path.

Planner level (the ``"astar"`` planner on a robot's configuration space):
:mod:`ntq_jax.planners.astar_planner`. Measurements: BENCHMARKS.md
("Classical planners").
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.batching import pad_rows, padded_chunks
from ntq_jax.planners.grid_graph import MAX_GRID_SIDE, GridGraph, prepare_grid
from ntq_jax.planners.jps import (
    MAX_OPEN_CAPACITY,
    MAX_QUERIES_PER_CALL,
    cells_from_jump_points,
    search,
)
from ntq_jax.types import PlanStatus

Array = jax.Array

__all__ = [
    "AStarResult",
    "astar",
    "astar_chunked",
    "default_lanes",
    "default_max_path_len",
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


STATIC_ARGS = ("max_path_len", "max_waypoints", "lanes", "open_capacity", "trace_steps")
_search_batch = jax.jit(_astar, static_argnames=STATIC_ARGS)


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
