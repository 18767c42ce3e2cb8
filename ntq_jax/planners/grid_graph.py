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
from jax import lax

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
# Per-grid preprocessing
# ---------------------------------------------------------------------------

def _shift(a: Array, dr: int, dc: int, fill) -> Array:
    """``out[i, j] = a[i + dr, j + dc]``, ``fill`` outside the grid."""
    h, w = a.shape
    p = jnp.pad(a, 1, constant_values=fill)
    return lax.dynamic_slice(p, (1 + dr, 1 + dc), (h, w))


def _ext(v: Array) -> Array:
    """One more step before the same event: ``n > 0 -> n + 1``, ``n <= 0 -> n - 1``."""
    return jnp.where(v > 0, v + 1, v - 1)


def _scan_lines(can_move: Array, event: Array, dr: int, dc: int) -> Array:
    """Solves ``T = where(~can_move, 0, where(event, 1, ext(T shifted by (dr, dc))))``.

    ``T[i, j]`` depends on ``T[i + dr, j + dc]``; the recurrence is solved by a
    scan over rows (``dr != 0``) or over columns (``dr == 0``).
    """
    if dr == 0:  # transpose so that the scan runs over the moving axis
        return _scan_lines(can_move.T, event.T, dc, 0).T
    forward = dr < 0  # row i depends on row i - 1: process rows in increasing order

    def step(prev, xs):
        cm, ev = xs
        nxt = _shift(prev[None], 0, dc, 0)[0] if dc else prev
        row = jnp.where(cm, jnp.where(ev, 1, _ext(nxt)), 0)
        return row, row

    zero = jnp.zeros(can_move.shape[1], jnp.int32)
    if forward:
        _, out = lax.scan(step, zero, (can_move, event))
        return out
    _, out = lax.scan(step, zero, (can_move[::-1], event[::-1]))
    return out[::-1]


def _jump_tables(free: Array) -> Array:
    """JPS+ jump distances ``(8, H, W)`` int32 for the no-corner-cutting 8-grid."""
    tables = [None] * 8
    for k in range(4):  # straight moves
        dr, dc = (int(x) for x in DIRS[k])
        pr, pc = dc, dr  # a perpendicular
        can = _shift(free, dr, dc, False)
        # Moving (dr, dc) into y = x + d: y is a jump point when a side cell of y
        # is free while the same side cell of x (behind it) is blocked.
        forced = ((_shift(free, dr + pr, dc + pc, False) & ~_shift(free, pr, pc, False))
                  | (_shift(free, dr - pr, dc - pc, False) & ~_shift(free, -pr, -pc, False)))
        tables[k] = _scan_lines(can, forced, dr, dc)
    for k in range(4, 8):  # diagonal moves: y is a jump point when a straight scan from it finds one
        dr, dc = (int(x) for x in DIRS[k])
        kv, kh = direction_index(dr, 0), direction_index(0, dc)
        can = _shift(free, dr, dc, False) & _shift(free, dr, 0, False) & _shift(free, 0, dc, False)
        event = _shift((tables[kv] > 0) | (tables[kh] > 0), dr, dc, False)
        tables[k] = _scan_lines(can, event, dr, dc)
    t = jnp.stack(tables)
    return jnp.where(free[None], t, 0)


def _components(free: Array) -> Array:
    """4-connected component labels (min flat index per component; ``H*W`` when occupied)."""
    h, w = free.shape
    hw = h * w
    big = jnp.int32(hw)
    lab0 = jnp.where(free, jnp.arange(hw, dtype=jnp.int32).reshape(h, w), big)

    def body(state):
        lab, _ = state
        m = lab
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            m = jnp.minimum(m, _shift(lab, dr, dc, big))
        m = jnp.where(free, m, big).reshape(-1)
        # pointer jumping: the label of a free cell is a free cell of the same component
        m = jnp.where(m < big, jnp.minimum(m, m[jnp.minimum(m, hw - 1)]), big).reshape(h, w)
        return m, jnp.any(m != lab)

    lab, _ = lax.while_loop(lambda s: s[1], body, (lab0, jnp.bool_(True)))
    return lab.reshape(-1)


@jax.jit
def prepare_grid(occ) -> GridGraph:
    """Builds the per-grid tables (jump distances, components), once for many searches.

    Args:
        occ: ``(H, W)`` bool occupancy grid (NumPy or JAX), True = occupied.

    Returns:
        A :class:`GridGraph`; pass it to :func:`ntq_jax.planners.jps.astar`
        instead of ``occ`` to skip the preprocessing.
    """
    occ = jnp.asarray(occ, bool)
    if occ.ndim != 2:
        raise ValueError(f"occ must be a 2D (H, W) bool array, got shape {occ.shape}")
    free = ~occ
    if max(occ.shape) > MAX_GRID_SIDE:
        raise ValueError(f"grid sides must be <= {MAX_GRID_SIDE}, got {occ.shape}")
    # (cell, direction) layout in int16: the 8 entries of a cell share one cache line
    jump = _jump_tables(free).reshape(8, -1).T.astype(jnp.int16)
    return GridGraph(occ=occ, jump=jump, label=_components(free))
