"""The 8-connected grid graph of the A* planner and its per-grid tables (JPS+ jump distances, components).

``occ`` is an occupancy grid, a bool array ``(H, W)`` with ``True`` = occupied.
Cell ``(i, j)`` is row ``i`` (the ``y`` cell) and column ``j`` (the ``x`` cell),
the convention of :func:`ntq_jax.geometry.rasterize`. Every free cell is a node
joined to its 8 neighbours: a straight move costs 1, a diagonal move
``sqrt(2)`` (costs are in cells), cells outside the grid are occupied, and
there is **no corner cutting**: a diagonal move needs both orthogonally adjacent
cells it passes to be free. Two cells are therefore connected exactly when they
are 4-connected.

:func:`prepare_grid` computes, once per grid, the tables the search
(:mod:`ntq_jax.planners.jps`) reads: for every cell and direction the distance to
the next jump point or wall (``jump``), and the connected components (``label``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy import ndimage

from ntq_jax.progress import open_bar

Array = jax.Array

SQRT2 = math.sqrt(2.0)

# Move k is (d_row, d_col) = DIRS[k]: 4 straight moves, then 4 diagonal moves.
DIRS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)], np.int32)
STEP_COST = np.array([1.0] * 4 + [SQRT2] * 4, np.float32)


def direction_index(dr: int, dc: int) -> int:
    """The index ``k`` of the move ``DIRS[k] == (dr, dc)``."""
    return int(np.nonzero((DIRS[:, 0] == dr) & (DIRS[:, 1] == dc))[0][0])


class GridGraph(NamedTuple):
    """Per-grid tables of the search (a pytree; build it with :func:`prepare_grid`).

    Attributes:
        occ: ``(H, W)`` bool, True = occupied.
        jump: ``(H * W, 8)`` int16. For a free cell and direction k: ``n > 0``
            means the next jump point along k is ``n`` steps away; ``n <= 0``
            means there is none and ``-n`` steps are free before a wall.
        label: ``(H * W,)`` int32 connected-component label (the smallest flat
            index of the component) of free cells, ``H * W`` for occupied cells.
    """

    occ: Array
    jump: Array
    label: Array


#: Jump lengths are stored in this many bits of the search's cell words, which bounds the grid.
JUMP_BITS = 13
MAX_GRID_SIDE = (1 << JUMP_BITS) - 1


# ---------------------------------------------------------------------------
# Per-grid preprocessing (host NumPy: integer tables, computed once per grid)
# ---------------------------------------------------------------------------


def _shift(a: np.ndarray, dr: int, dc: int, fill) -> np.ndarray:
    """``out[i, j] = a[i + dr, j + dc]``, ``fill`` outside the grid."""
    h, w = a.shape
    p = np.pad(a, 1, constant_values=fill)
    return p[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w]


def _scan_lines(can_move: np.ndarray, event: np.ndarray, dr: int, dc: int) -> np.ndarray:
    """Solves ``T = where(~can_move, 0, where(event, 1, ext(T shifted by (dr, dc))))``.

    ``ext`` is one more step before the same event (``n > 0 -> n + 1``,
    ``n <= 0 -> n - 1``). ``T[i, j]`` depends on ``T[i + dr, j + dc]``; the
    recurrence is solved line by line over rows (``dr != 0``) or over columns
    (``dr == 0``), each line one vector operation over the other axis.
    """
    if dr == 0:  # transpose so that the scan runs over the moving axis
        return _scan_lines(can_move.T, event.T, dc, 0).T
    h, w = can_move.shape
    out = np.zeros((h, w), np.int32)
    nxt = np.zeros(w, np.int32)  # T of the line before, shifted by dc (0 outside the grid)
    for i in range(h) if dr < 0 else range(h - 1, -1, -1):  # row i depends on row i + dr
        row = np.where(event[i], 1, nxt + np.where(nxt > 0, 1, -1)).astype(np.int32)
        row[~can_move[i]] = 0
        out[i] = row
        if dc > 0:  # the next line reads row[j + dc]: a slice per line, not _shift's pad
            nxt = np.concatenate([row[1:], np.zeros(1, np.int32)])
        elif dc < 0:
            nxt = np.concatenate([np.zeros(1, np.int32), row[:-1]])
        else:
            nxt = row
    return out


def _jump_tables(free: np.ndarray, bar=None) -> np.ndarray:
    """JPS+ jump distances ``(8, H, W)`` int32 for the no-corner-cutting 8-grid.

    ``bar`` (a :class:`ntq_jax.progress.Bar`, optional) advances by one per direction.
    """
    tables = [None] * 8
    for k in range(4):  # straight moves
        dr, dc = (int(x) for x in DIRS[k])
        pr, pc = dc, dr  # a perpendicular
        can = _shift(free, dr, dc, False)
        # Moving (dr, dc) into y = x + d: y is a jump point when a side cell of y
        # is free while the same side cell of x (behind it) is blocked.
        forced = (_shift(free, dr + pr, dc + pc, False) & ~_shift(free, pr, pc, False)) | (
            _shift(free, dr - pr, dc - pc, False) & ~_shift(free, -pr, -pc, False)
        )
        tables[k] = _scan_lines(can, forced, dr, dc)
        if bar is not None:
            bar.update(1)
    for k in range(
        4, 8
    ):  # diagonal moves: y is a jump point when a straight scan from it finds one
        dr, dc = (int(x) for x in DIRS[k])
        kv, kh = direction_index(dr, 0), direction_index(0, dc)
        can = _shift(free, dr, dc, False) & _shift(free, dr, 0, False) & _shift(free, 0, dc, False)
        event = _shift((tables[kv] > 0) | (tables[kh] > 0), dr, dc, False)
        tables[k] = _scan_lines(can, event, dr, dc)
        if bar is not None:
            bar.update(1)
    return np.where(free[None], np.stack(tables), 0).astype(np.int32)


def _components(free: np.ndarray) -> np.ndarray:
    """4-connected component labels (min flat index per component; ``H*W`` when occupied)."""
    hw = free.size
    lab, n = ndimage.label(free)  # 4-connectivity (the default cross); 0 = occupied
    lab = lab.reshape(-1)
    first = np.full(n + 1, hw, np.int64)
    np.minimum.at(first, lab, np.arange(hw))
    first[0] = hw
    return first[lab].astype(np.int32)


def _as_occupancy(occ) -> np.ndarray:
    """``occ`` as a bool NumPy array; refuses any other dtype with the fix (no silent cast)."""
    arr = np.asarray(occ)
    if arr.dtype != np.bool_:
        raise ValueError(
            f"occ must be a bool occupancy grid (True = occupied), got dtype {arr.dtype}: "
            "prepare_grid does not guess a convention (a uint8 image with 255 = free, "
            "probabilities or NaN would all read as occupied); convert it explicitly, e.g. "
            "occ = image < 128 for a lightness image, occ = p > 0.65 for occupancy "
            "probabilities, or load the map with ntq_jax.grid_maps (ROS map.yaml, MovingAI "
            ".map), which applies the documented conventions"
        )
    return arr


#: Seconds and peak bytes per cell of :func:`prepare_grid` (measured on a 2-core CPU:
#: 1.5 us/cell at 1024 and 2048 squared, about 1.8 us/cell and 6.5 GB at 8191 squared).
PREPARE_SECONDS_PER_CELL = 2e-6
PREPARE_BYTES_PER_CELL = 100


def prepare_grid(occ, *, progress=None) -> GridGraph:
    """Builds the per-grid tables (jump distances, components), once for many searches.

    Host-side NumPy (integer tables, no compiled program), so a new grid shape costs
    no compilation here; the arrays are returned on the default device.

    Cost: about 2 microseconds and 100 bytes of peak memory per cell
    (:data:`PREPARE_SECONDS_PER_CELL`, :data:`PREPARE_BYTES_PER_CELL`): a
    256 x 256 grid takes tens of milliseconds, 4096 x 4096 about 30 s and 1.7 GB,
    the largest grid (8191 x 8191) about 2 minutes and 6.5 GB. Pass ``progress``
    to see it advance.

    Args:
        occ: ``(H, W)`` **bool** occupancy grid (NumPy or a concrete JAX array),
            True = occupied. Other dtypes (integers, floats, images, strings) are
            refused, not converted: threshold them yourself (``occ = image < 128``)
            or load the map with :mod:`ntq_jax.grid_maps`.
        progress: ``None``/``False`` (silent, the default), ``True`` (a tqdm bar)
            or a bar factory (see :mod:`ntq_jax.progress`); the bar counts the 9
            tables (8 jump directions and the components).

    Returns:
        A :class:`GridGraph`; pass it to :func:`ntq_jax.planners.astar.astar`
        instead of ``occ`` to skip the preprocessing.

    Raises:
        TypeError: if ``occ`` is traced (inside ``jax.jit``): build the graph outside.
        ValueError: if ``occ`` is not bool, not 2D, has no cell (a side of 0) or a
            side exceeds :data:`MAX_GRID_SIDE`.
    """
    if isinstance(occ, jax.core.Tracer):
        raise TypeError(
            "prepare_grid builds the grid tables on the host and cannot take a traced "
            "grid: call prepare_grid(occ) outside jax.jit and pass the GridGraph to astar"
        )
    occ = _as_occupancy(occ)
    if occ.ndim != 2:
        raise ValueError(f"occ must be a 2D (H, W) bool array, got shape {occ.shape}")
    if min(occ.shape) < 1:
        raise ValueError(
            f"occ has no cell: an empty grid of shape {occ.shape} has nothing to "
            "plan on; pass a grid with at least 1 row and 1 column"
        )
    if max(occ.shape) > MAX_GRID_SIDE:
        raise ValueError(f"grid sides must be <= {MAX_GRID_SIDE}, got {occ.shape}")
    free = ~occ
    with open_bar(
        progress, desc=f"grid tables {occ.shape[0]}x{occ.shape[1]}", total=9, unit="table"
    ) as bar:
        # (cell, direction) layout in int16: the 8 entries of a cell share one cache line
        jump = np.ascontiguousarray(_jump_tables(free, bar).reshape(8, -1).T.astype(np.int16))
        label = _components(free)
        bar.update(1)
    return GridGraph(occ=jnp.asarray(occ), jump=jnp.asarray(jump), label=jnp.asarray(label))
