"""Batched, exact grid A* in JAX (8-connected, octile heuristic, jump point search).

The graph
---------
``occ`` is an occupancy grid, a bool array ``(H, W)`` with ``True`` = occupied.
Cell ``(i, j)`` is row ``i`` (the ``y`` cell) and column ``j`` (the ``x`` cell),
the convention of :func:`ntq_jax.geometry.rasterize`. Every free cell is a node
and is joined to its 8 neighbours:

* a straight move (one row or one column) costs 1;
* a diagonal move costs ``sqrt(2)``;
* **no corner cutting**: a diagonal move is allowed only when both orthogonally
  adjacent cells it passes (same row / same column as the start of the move) are
  free, so a path never squeezes between two diagonally touching occupied cells
  or clips the corner of an obstacle;
* cells outside the grid are occupied.

Costs are in cells; multiply by the grid resolution for workspace units. As a
consequence of the no-corner-cutting rule two cells are connected exactly when
they are 4-connected.

The search
----------
The returned costs are those of an exact A* with the octile heuristic (which
is consistent on this graph). The search itself is A* with *jump point search*
(JPS, Harabor & Grastien 2011, in its no-corner-cutting form, with the
pre-computed jump tables of JPS+): it expands only "jump points" and travels
along straight and diagonal lines in one step. Optimality is preserved;
``tests/test_astar.py`` checks every cost against Dijkstra on the explicit
graph. Moving straight, a cell is a jump point when one of its side cells is
free while the side cell behind it is blocked; moving diagonally, when a
straight scan along either component direction reaches a jump point. From a
node entered straight the search continues forward, to both sides and along
both forward diagonals; entered diagonally, along the diagonal and its two
components (a superset of the natural and forced neighbours). The goal is
caught by the JPS+ "target" rules: on a straight ray before the next wall or
jump point, or as the cell of a diagonal ray in the goal's row or column.

Per grid, :func:`prepare_grid` computes once:

* ``jump``: for every cell and each of the 8 directions, how far one can travel
  before the next jump point (positive value) or before a wall (``-steps``);
* ``label``: connected components, so unreachable queries are answered without
  any search.

On maps of boxes JPS expands 10-40 jump points per query where plain A*
expands ~1500 cells. Salt-and-pepper noise is its worst case (jump points
everywhere, open lists of ~1000 on 200x200): correct but slower.

Batching
--------
The search step is written for one query (``_lane_step``) and ``jax.vmap``-ed
over ``lanes`` search lanes inside one ``lax.while_loop``. A lane that reaches
its goal follows the parent links back (a few links per iteration) and then
immediately picks up the next query of the batch, so the loop runs about
``total work / lanes`` iterations instead of waiting for the slowest query of
each group; it stops when every query is done. Per lane:

* one dense ``(H*W,)`` uint32 array of cell words stamped with the query's
  token (seen / closed, the open-list slot of an open cell, the arrival
  direction and jump length of a closed cell), so nothing is cleared between
  queries;
* a fixed-capacity open list (``open_capacity`` slots with a free-slot stack):
  the pop is two plain reductions over the slots (smallest f, lowest slot on
  ties), decrease-key is in place, every other update is one gather or scatter
  of at most 9 items.

XLA:CPU runs each gather, scatter or reduction as its own kernel, so the step
is arranged to need few of them (packed open-list rows, small tables as packed
integer constants, one scatter per array per step); the cost per step is then
mostly memory access, and 32-64 lanes amortise the fixed cost of an iteration.

Shapes are static: a call compiles once per (grid shape, batch size, options)
and never again. Use :func:`astar_chunked` for large or varying batch sizes: it
pads and splits them into fixed-size chunks.

Statuses: ``SOLVED = 0``, ``NO_PATH = 1`` (start and goal in different
components), ``INVALID = 2`` (start or goal outside the grid or occupied),
``CAPACITY = 3`` (the open list, ``max_waypoints`` or ``max_path_len`` was too
small; raise them). Unsolved queries have ``cost = inf`` and an empty path.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

Array = jax.Array

SOLVED, NO_PATH, INVALID, CAPACITY = 0, 1, 2, 3

SQRT2 = math.sqrt(2.0)

# Move k is (d_row, d_col) = DIRS[k]: 4 straight moves, then 4 diagonal moves.
DIRS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)], np.int32)
STEP_COST = np.array([1.0] * 4 + [SQRT2] * 4, np.float32)
_START_CODE = 8  # arrival "direction" of the start node: every direction is a successor


def _dir_index(dr: int, dc: int) -> int:
    return int(np.nonzero((DIRS[:, 0] == dr) & (DIRS[:, 1] == dc))[0][0])


def _successor_masks() -> np.ndarray:
    """Bit k of ``mask[a]`` says whether direction k is searched from a node entered moving along a.

    JPS pruning (no corner cutting): entered diagonally (dr, dc) -> (0, dc),
    (dr, 0) and (dr, dc); entered straight -> forward, both sides and both
    forward diagonals (a superset of the natural and forced neighbours, so it
    is safe); the start -> all 8.
    """
    masks = np.zeros(9, np.int32)
    for k, (dr, dc) in enumerate(DIRS):
        if dr and dc:
            succ = [_dir_index(0, dc), _dir_index(dr, 0), k]
        else:
            sides = [(dc, dr), (-dc, -dr)]
            succ = [k] + [_dir_index(*s) for s in sides] + [_dir_index(dr + s[0], dc + s[1]) for s in sides]
        masks[k] = sum(1 << s for s in succ)
    masks[_START_CODE] = 255
    return masks


_SUCC_MASK = _successor_masks()


class GridGraph(NamedTuple):
    """Per-grid tables for :func:`astar` (a pytree; build it with :func:`prepare_grid`).

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


class AStarResult(NamedTuple):
    """Per-query results of :func:`astar` (N queries).

    Attributes:
        status: ``(N,)`` int8: 0 solved, 1 no path (unreachable), 2 invalid
            query (start or goal out of the grid or occupied), 3 capacity
            exceeded (``open_capacity``, ``max_waypoints`` or ``max_path_len``).
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
        kv, kh = _dir_index(dr, 0), _dir_index(0, dc)
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
    """Builds the per-grid tables (jump distances, components) once for many :func:`astar` calls.

    Args:
        occ: ``(H, W)`` bool occupancy grid (NumPy or JAX), True = occupied.

    Returns:
        A :class:`GridGraph`; pass it to :func:`astar` instead of ``occ`` to skip
        the preprocessing (a few ms on a 200x200 grid).
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


# ---------------------------------------------------------------------------
# The search
# ---------------------------------------------------------------------------

def _octile(dr: Array, dc: Array) -> Array:
    a = jnp.abs(dr).astype(jnp.float32)
    b = jnp.abs(dc).astype(jnp.float32)
    return jnp.maximum(a, b) + (SQRT2 - 1.0) * jnp.minimum(a, b)


# Per-lane cell word (uint32): query token (15 bits) | closed (1 bit) | payload (16 bits).
# A cell is "seen" by the current query when its token matches. The payload of an
# open cell is its slot in the open list; a closed cell stores how it was entered,
# arrival direction (3 bits) and jump length (13 bits): its parent is
# ``cell - DIRS[dir] * length``.
_TOK_SHIFT, _CLOSED_BIT, _DIR_SHIFT, _DIST_BITS = 17, 1 << 16, 13, 13
_SLOT_MASK = (1 << 16) - 1
_DIST_MASK = (1 << _DIST_BITS) - 1
MAX_QUERIES_PER_CALL = (1 << 15) - 1
MAX_GRID_SIDE = _DIST_MASK
MAX_OPEN_CAPACITY = 1 << 16

# Small per-direction tables packed into integer constants, so that looking them up
# is elementwise arithmetic (fused) rather than a gather (a separate kernel on CPU).
_DR_PACK = sum(int(d + 1) << (2 * k) for k, d in enumerate(DIRS[:, 0]))
_DC_PACK = sum(int(d + 1) << (2 * k) for k, d in enumerate(DIRS[:, 1]))
_SUCC_LO = sum(int(_SUCC_MASK[k]) << (8 * k) for k in range(4))
_SUCC_HI = sum(int(_SUCC_MASK[k + 4]) << (8 * k) for k in range(4))


def _dir_offset(k: Array, width: int) -> Array:
    """Flat cell offset of move ``k`` (elementwise)."""
    k2 = (2 * k).astype(jnp.uint32)
    dr = ((jnp.uint32(_DR_PACK) >> k2) & 3).astype(jnp.int32) - 1
    dc = ((jnp.uint32(_DC_PACK) >> k2) & 3).astype(jnp.int32) - 1
    return dr * width + dc


def _successors(code: Array) -> Array:
    """8-bit mask of the directions searched from a node entered along ``code`` (elementwise)."""
    sh = (8 * (code & 3)).astype(jnp.uint32)
    m = jnp.where(code < 4, jnp.uint32(_SUCC_LO) >> sh, jnp.uint32(_SUCC_HI) >> sh) & 255
    return jnp.where(code >= _START_CODE, 255, m).astype(jnp.int32)


def _prefix_count(x: Array) -> Array:
    """Exclusive prefix count of a short bool vector (a triangular compare, fused; no scan)."""
    n = x.shape[-1]
    lower = jnp.arange(n)[None, :] < jnp.arange(n)[:, None]
    return jnp.sum(lower & x[..., None, :], axis=-1, dtype=jnp.int32)


def _lane_step(jump, word, of, orow, stack, top, used, fresh, tok, start, goal, active, *, width):
    """One A*/JPS iteration of ONE query (vmapped over the lanes).

    Args:
        jump: the ``(H * W, 8)`` int16 jump table (shared by all lanes), split
            by directions into flat parts (see ``_split_jump_table``).
        word: ``(H * W,)`` uint32 cell words of this lane (see ``_TOK_SHIFT``).
        of: ``(C,)`` float32 f of the open-list slots (``inf`` = free).
        orow: ``(C, 3)`` int32 open-list rows: cell, g (float32 bits), and
            ``code << 13 | length`` (how the cell is entered from its parent).
        stack, top, used: slots ``>= used`` were never used by this query;
            below it, the free slots are ``stack[:top]`` (the others are live).
        fresh: the query starts now: its start is expanded without a pop.
        tok: query token (uint32, query index + 1).
        start, goal: start and goal cells (flat indices).
        active: whether this lane is searching.

    Returns:
        ``(word, of, orow, stack, top, used)`` updated, and ``(reached, g,
        exhausted, overflow)``: the goal was popped (with cost ``g``), the open
        list is empty (no path), the open list overflowed.

    The open list costs two plain reductions over its ``C`` slots per step; all
    other work is one gather or scatter of at most 9 items per array: no sort,
    no heap, and the small tables are packed constants (elementwise lookups).
    """
    hw = word.shape[0]
    cap = of.shape[0]
    inf = jnp.float32(jnp.inf)
    dirs = jnp.asarray(DIRS)
    dr_k, dc_k = dirs[:, 0], dirs[:, 1]
    is_diag = (dr_k != 0) & (dc_k != 0)
    offs = dr_k * width + dc_k
    seen_word = tok << _TOK_SHIFT
    ks = jnp.arange(8, dtype=jnp.int32)

    # -- pop the entry with the smallest f (lowest slot on ties); a new query pops its start
    live_f = jnp.where(jnp.arange(cap) < used, of, inf)
    fmin = jnp.min(live_f)
    i = jnp.minimum(jnp.min(jnp.where(live_f == fmin, jnp.arange(cap), cap)), cap - 1)
    row = orow[i]
    u = jnp.where(fresh, start, row[0])
    gu = jnp.where(fresh, 0.0, lax.bitcast_convert_type(row[1], jnp.float32))
    how = jnp.where(fresh, _START_CODE << _DIR_SHIFT, row[2])
    popped = active & ~fresh & (fmin < inf)  # an open-list slot is freed
    act = active & (fresh | (fmin < inf))
    reached = act & (u == goal)
    expand = act & ~reached
    closed_word = seen_word | _CLOSED_BIT | (how & _SLOT_MASK).astype(jnp.uint32)
    # (barriers: materialise intermediate results once; XLA would otherwise recompute
    #  the whole elementwise chain inside every gather/scatter kernel that uses it)
    u, gu, how, act, reached, expand, popped, i, closed_word = lax.optimization_barrier(
        (u, gu, how, act, reached, expand, popped, i, closed_word))

    # -- one jump along each searched direction ----------------------------------------
    per = 8 // len(jump)
    vals = jnp.concatenate([part[u * per + jnp.arange(per)] for part in jump]).astype(jnp.int32)
    reach = jnp.abs(vals)
    is_jp = vals > 0
    ur, uc = lax.div(u, width), lax.rem(u, width)
    gr, gc = lax.div(goal, width), lax.rem(goal, width)
    pr = (gr - ur) * dr_k  # goal offset projected on each direction
    pc = (gc - uc) * dc_k
    along = pr + pc  # distance along a straight direction (one of dr_k, dc_k is 0)
    st_goal = jnp.where(dr_k == 0, pr == 0, pc == 0) & (along > 0) & (along <= reach)
    m = jnp.minimum(pr, pc)  # diagonal: steps to the goal's row or column
    dg_goal = (pr > 0) & (pc > 0) & (m <= reach)
    to_goal = jnp.where(is_diag, dg_goal, st_goal)
    steps = jnp.where(to_goal, jnp.where(is_diag, m, along), reach)
    searched = ((_successors(how >> _DIR_SHIFT) >> ks) & 1) == 1
    has = expand & searched & (to_goal | is_jp) & (steps > 0)
    s = jnp.where(has, u + offs * steps, u)
    gs = gu + steps.astype(jnp.float32) * jnp.asarray(STEP_COST)
    fs = gs + _octile(gr - (ur + dr_k * steps), gc - (uc + dc_k * steps))
    s, gs, fs, steps, has = lax.optimization_barrier((s, gs, fs, steps, has))

    # -- relax: new cells take free slots (the popped one first), better ones update in place
    ws = word[s]
    seen = (ws >> _TOK_SHIFT) == tok
    closed = seen & ((ws & _CLOSED_BIT) != 0)
    slot_in = jnp.minimum((ws & _SLOT_MASK).astype(jnp.int32), cap - 1)
    g_old = lax.bitcast_convert_type(orow[slot_in, 1], jnp.float32)
    new = has & ~seen
    better = has & seen & ~closed & (gs < g_old)
    rank = _prefix_count(new) - popped  # -1: takes the popped slot
    k = top - 1 - rank  # then stack[top - 1], stack[top - 2], ..., then never-used slots
    fresh_slot = used - 1 - k
    overflow = jnp.any(new & (fresh_slot >= cap))
    slot = jnp.where(rank < 0, i, jnp.where(k >= 0, stack[jnp.clip(k, 0, cap - 1)], fresh_slot))
    slot = jnp.where(new, slot, slot_in)
    n_new = jnp.sum(new)
    spare = popped & (n_new == 0)  # the popped slot is not reused: free it
    n_stack = jnp.maximum(n_new - popped, 0)  # new cells served by the stack or fresh slots
    used = used + jnp.maximum(n_stack - top, 0)
    stack = stack.at[jnp.where(spare, top, cap)].set(i, mode="drop")
    top = jnp.maximum(top - n_stack, 0) + spare
    slot = jnp.where((new | better) & ~overflow, slot, cap)
    slot, new, overflow, spare, top, used = lax.optimization_barrier(
        (slot, new, overflow, spare, top, used))
    of = of.at[jnp.concatenate([jnp.where(spare, i, cap)[None], slot])].set(
        jnp.concatenate([inf[None], fs]), mode="drop")
    rows = jnp.stack([s, lax.bitcast_convert_type(gs, jnp.int32), (ks << _DIR_SHIFT) | steps], -1)
    orow = orow.at[slot].set(rows, mode="drop")
    cells = jnp.concatenate([jnp.where(act, u, hw)[None], jnp.where(new & ~overflow, s, hw)])
    words = jnp.concatenate([closed_word[None], seen_word | slot.astype(jnp.uint32)])
    word = word.at[cells].set(words, mode="drop")
    exhausted = active & ~act
    return (word, of, orow, stack, top, used), (reached, gu, exhausted, overflow)


_IDLE, _SEARCH, _TRACE = 0, 1, 2

# XLA:CPU splits a gather whose operand exceeds ~512 KB over two threads; inside a
# loop of small steps the synchronisation costs more than the gather itself.
_NO_SPLIT_BYTES = 480 << 10


def _split_jump_table(jump: Array) -> tuple[Array, ...]:
    """``(H*W, 8)`` -> 1, 2, 4 or 8 flat parts by direction, each below ``_NO_SPLIT_BYTES`` if possible."""
    parts = 1
    while parts < 8 and jump.size * jump.dtype.itemsize // parts > _NO_SPLIT_BYTES:
        parts *= 2
    per = 8 // parts
    return tuple(jump[:, p * per:(p + 1) * per].reshape(-1) for p in range(parts))


def _search(graph: GridGraph, start: Array, goal: Array, nq: Array, *, lanes: int, cap: int,
            max_jp: int, trace_steps: int):
    """Solves queries ``0..nq-1`` of ``start``/``goal`` (flat cells ``(N,)``, valid, reachable, distinct).

    Returns per query ``(status, cost, jump points goal-first (N, max_jp), count (N,))``.
    """
    h, w = graph.occ.shape
    hw = h * w
    n = start.shape[0]
    b = lanes
    inf = jnp.float32(jnp.inf)
    jump = _split_jump_table(graph.jump)
    lane_ids = jnp.arange(b)
    ends = jnp.stack([start, goal], -1)
    vstep = jax.vmap(functools.partial(_lane_step, width=w), in_axes=(None,) + (0,) * 11)

    def cond(st):
        return jnp.any(st["mode"] != _IDLE) | (st["next"] < nq)

    def body(st):
        # -- idle lanes take the next queued queries (nothing to clear: cells are stamped
        #    with the query's token and the open-list slots count as never used) ---------
        idle = st["mode"] == _IDLE
        qn = st["next"] + _prefix_count(idle)
        take = idle & (qn < nq)
        nxt = jnp.minimum(st["next"] + jnp.sum(idle), nq)
        q = jnp.where(take, qn, st["q"])
        tok = (q + 1).astype(jnp.uint32)
        se = ends[q]
        s0, g0 = se[:, 0], se[:, 1]
        top = jnp.where(take, 0, st["top"])
        used = jnp.where(take, 0, st["used"])
        mode = jnp.where(take, _SEARCH, st["mode"])

        # -- one search step in every lane -------------------------------------------
        (word, of, orow, stack, top, used), (reached, g_goal, exhausted, overflow) = vstep(
            jump, st["word"], st["of"], st["orow"], st["stack"], top, used, take, tok, s0, g0,
            mode == _SEARCH)
        mode = jnp.where(exhausted | overflow, _IDLE, jnp.where(reached, _TRACE, mode))
        cost_l = jnp.where(reached, g_goal, st["cost_l"])
        cur = jnp.where(reached, g0, st["cur"])
        j = jnp.where(reached, 0, st["j"])

        # -- lanes that reached their goal follow the parent links back to the start -----
        tracing = mode == _TRACE
        done = jnp.zeros(b, bool)
        too_long = jnp.zeros(b, bool)
        pts, where_to = [], []
        for _ in range(trace_steps):
            act = tracing & ~done
            fits = j < max_jp
            pts.append(cur)
            where_to.append(jnp.where(act & fits, q * max_jp + j, n * max_jp))
            fin = act & ((cur == s0) | ~fits)
            done = done | fin
            too_long = too_long | (act & ~fits)
            wc = word[lane_ids, cur]
            back = _dir_offset((wc >> _DIR_SHIFT) & 7, w) * (wc & _DIST_MASK).astype(jnp.int32)
            step = act & ~fin
            cur = jnp.where(step, cur - back, cur)
            j = j + step
        jp = st["jp"].at[jnp.stack(where_to, -1).reshape(-1)].set(jnp.stack(pts, -1).reshape(-1),
                                                                    mode="drop")
        # -- record finished queries: one row (status, cost bits, #jump points) each ------
        fin = exhausted | overflow | done
        code = jnp.where(exhausted, NO_PATH, jnp.where(overflow | too_long, CAPACITY, SOLVED))
        res_row = jnp.stack([code, lax.bitcast_convert_type(cost_l, jnp.int32), j + 1], -1)
        res = st["res"].at[jnp.where(fin, q, n)].set(res_row, mode="drop")
        mode = jnp.where(done, _IDLE, mode)
        return dict(mode=mode, q=q, next=nxt, word=word, of=of, orow=orow, stack=stack, top=top,
                    used=used, res=res, cost_l=cost_l, cur=cur, j=j, jp=jp)

    st = dict(
        mode=jnp.zeros(b, jnp.int32), q=jnp.zeros(b, jnp.int32), next=jnp.int32(0),
        word=jnp.zeros((b, hw), jnp.uint32), of=jnp.full((b, cap), inf),
        orow=jnp.zeros((b, cap, 3), jnp.int32), stack=jnp.zeros((b, cap), jnp.int32),
        top=jnp.zeros(b, jnp.int32), used=jnp.zeros(b, jnp.int32),
        res=jnp.zeros((n, 3), jnp.int32), cost_l=jnp.zeros(b),
        cur=jnp.zeros(b, jnp.int32), j=jnp.zeros(b, jnp.int32),
        jp=jnp.zeros(n * max_jp, jnp.int32))
    st = lax.while_loop(cond, body, st)
    res = st["res"]
    return (res[:, 0].astype(jnp.int8), lax.bitcast_convert_type(res[:, 1], jnp.float32),
            st["jp"].reshape(n, max_jp), res[:, 2])


def _cells_from_jump_points(jp: Array, njp: Array, width: int, max_len: int):
    """Goal-first jump points ``(N, J)`` -> start-first waypoints and cell paths.

    Consecutive jump points are joined by straight or diagonal lines. Returns
    the waypoints ``(N, J, 2)``, the cell paths ``(N, max_len, 2)`` (both
    ``(row, col)``, padded with -1) and the paths' numbers of cells ``(N,)``
    (which may exceed ``max_len``). The cells come from one scan over the path
    index that accumulates flat unit steps (the changes of step are scattered
    at the waypoints), so there is no per-cell gather or search.
    """
    n, jmax = jp.shape
    ar = jnp.arange(jmax)
    valid = ar[None, :] < njp[:, None]
    pts = jnp.take_along_axis(jp, jnp.clip(njp[:, None] - 1 - ar[None, :], 0, jmax - 1), axis=1)
    r, c = pts // width, pts % width
    dr, dc = jnp.diff(r, axis=1), jnp.diff(c, axis=1)
    vseg = valid[:, 1:]
    seg = jnp.where(vseg, jnp.maximum(jnp.abs(dr), jnp.abs(dc)), 0)
    pos = jnp.concatenate([jnp.zeros((n, 1), jnp.int32), jnp.cumsum(seg, axis=1)], axis=1)
    total = jnp.where(njp > 0, jnp.take_along_axis(pos, jnp.maximum(njp - 1, 0)[:, None], 1)[:, 0] + 1, 0)
    step = jnp.where(vseg, jnp.sign(dr) * width + jnp.sign(dc), 0)  # flat unit step of each segment
    change = step - jnp.concatenate([jnp.zeros((n, 1), jnp.int32), step[:, :-1]], 1)
    at = pos[:, :-1]
    flat = jnp.where(at < max_len, at * n + jnp.arange(n)[:, None], max_len * n)
    delta = jnp.zeros(max_len * n, jnp.int32).at[flat.reshape(-1)].add(
        change.reshape(-1), mode="drop").reshape(max_len, n)

    def advance(carry, d):
        unit, cell = carry
        unit = unit + d
        return (unit, cell + unit), cell

    _, cells = lax.scan(advance, (jnp.zeros(n, jnp.int32), pts[:, 0]), delta)
    cells = cells.T
    cells = jnp.stack([lax.div(cells, width), lax.rem(cells, width)], -1)
    ok = jnp.arange(max_len)[None, :] < total[:, None]
    path = jnp.where(ok[..., None], cells, -1).astype(jnp.int32)
    wps = jnp.where(valid[..., None], jnp.stack([r, c], -1), -1).astype(jnp.int32)
    return wps, path, total


def default_max_path_len(shape) -> int:
    """Default path buffer: ``2 * (H + W)`` cells (a path may need more in mazes)."""
    h, w = shape
    return 2 * (h + w)


def default_lanes(shape, n: int) -> int:
    """Search lanes: about 6 MB of per-lane state, between 8 and 64, at most ``n``."""
    h, w = shape
    return int(max(1, min(n, max(8, min(64, (6 << 20) // (4 * h * w))))))


def _astar(occ, starts, goals, *, max_path_len: int | None = None, max_waypoints: int = 128,
          lanes: int | None = None, open_capacity: int = 256, trace_steps: int = 4) -> AStarResult:
    """Solves a batch of grid shortest-path queries exactly (8-connected, no corner cutting).

    Cells are ``(row, col)`` integer pairs: ``row`` indexes the first axis of
    ``occ`` (the ``y`` cell), ``col`` the second (the ``x`` cell). See the module
    docstring for the graph (step costs 1 and sqrt(2), no corner cutting) and
    the algorithm (A* with jump point search, lanes refilled from the batch).

    Args:
        occ: ``(H, W)`` bool occupancy grid (True = occupied), or a
            :class:`GridGraph` from :func:`prepare_grid` (faster for repeated calls).
        starts: ``(N, 2)`` int start cells ``(row, col)``.
        goals: ``(N, 2)`` int goal cells ``(row, col)``.
        max_path_len: length ``L`` of the returned cell path buffer. Default
            :func:`default_max_path_len`; a longer path gets status 3.
        max_waypoints: length ``J`` of the returned waypoint buffer (the jump
            points of the path); a path with more gets status 3.
        lanes: number of queries searched simultaneously (default
            :func:`default_lanes`; memory is ``4 * H * W`` bytes per lane).
        open_capacity: open-list entries per lane; a query whose open list
            overflows gets status 3. JPS open lists are small on maps of
            boxes (at most ~25 on the 20x20 maps at 0.1 resolution) but can
            reach ~1000 on 200x200 salt-and-pepper noise. The pop scans the
            open list: 256 costs about the same as 64, 1024 about 30% more.
        trace_steps: parent links followed per loop iteration when tracing a path.

    Returns:
        An :class:`AStarResult`: ``status (N,) int8``, ``cost (N,) float32``
        (cells; ``inf`` unless solved), ``path (N, L, 2) int32`` (start first,
        goal last, padded with -1), ``path_len (N,) int32``, and the same path
        as ``waypoints (N, J, 2)`` / ``num_waypoints (N,)``.

    Raises:
        ValueError: on bad shapes, ``N > MAX_QUERIES_PER_CALL`` (use
            :func:`astar_chunked`) or a grid side above ``MAX_GRID_SIDE``.

    Every call with the same grid shape, batch size and options reuses one
    compiled program (starts, goals and the grid's contents are traced).

    Example:
        >>> occ = np.zeros((50, 80), bool); occ[10:40, 30] = True
        >>> res = astar(occ, [[0, 0], [5, 5]], [[45, 70], [5, 5]])
        >>> res.status.tolist(), float(res.cost[1])
        ([0, 0], 0.0)
    """
    graph = occ if isinstance(occ, GridGraph) else prepare_grid(occ)
    h, w = graph.occ.shape
    starts = jnp.asarray(starts)
    goals = jnp.asarray(goals)
    if starts.ndim != 2 or starts.shape[-1] != 2 or goals.shape != starts.shape:
        raise ValueError(f"starts and goals must both be (N, 2) (row, col) cells, got {starts.shape} "
                         f"and {goals.shape}")
    starts = starts.astype(jnp.int32)
    goals = goals.astype(jnp.int32)
    n = starts.shape[0]
    if n > MAX_QUERIES_PER_CALL:
        raise ValueError(f"at most {MAX_QUERIES_PER_CALL} queries per astar call, got {n}: "
                         "use astar_chunked")
    if max(h, w) > MAX_GRID_SIDE:
        raise ValueError(f"grid sides must be <= {MAX_GRID_SIDE}, got {(h, w)}")
    max_len = int(max_path_len) if max_path_len is not None else default_max_path_len((h, w))
    jmax = int(max_waypoints)
    if not 1 <= int(open_capacity) <= MAX_OPEN_CAPACITY:
        raise ValueError(f"open_capacity must be in [1, {MAX_OPEN_CAPACITY}], got {open_capacity}")
    if max_len < 1 or jmax < 2:
        raise ValueError(f"need max_path_len >= 1 and max_waypoints >= 2, got {max_len}, {jmax}")
    nl = int(lanes) if lanes is not None else default_lanes((h, w), n)
    if n == 0:
        return AStarResult(jnp.zeros(0, jnp.int8), jnp.zeros(0, jnp.float32),
                           jnp.zeros((0, max_len, 2), jnp.int32), jnp.zeros(0, jnp.int32),
                           jnp.zeros((0, jmax, 2), jnp.int32), jnp.zeros(0, jnp.int32))

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

    status, cost, jp, njp = _search(graph, sf[order], gf[order], nq, lanes=nl,
                                    cap=int(open_capacity), max_jp=jmax,
                                    trace_steps=int(trace_steps))
    inv = jnp.argsort(order)
    status, cost, jp, njp = status[inv], cost[inv], jp[inv], njp[inv]
    status = jnp.where(queued, status, jnp.where(~valid, INVALID, jnp.where(trivial, SOLVED, NO_PATH)))
    cost = jnp.where(trivial, 0.0, cost)
    jp = jnp.where(trivial[:, None] & (jnp.arange(jmax) == 0)[None, :], sf[:, None], jp)
    njp = jnp.where(trivial, 1, njp)
    wps, path, plen = _cells_from_jump_points(jp, njp, w, max_len)
    status = jnp.where((status == SOLVED) & (plen > max_len), CAPACITY, status).astype(jnp.int8)
    ok = status == SOLVED
    return AStarResult(
        status=status,
        cost=jnp.where(ok, cost, jnp.inf).astype(jnp.float32),
        path=jnp.where(ok[:, None, None], path, -1),
        path_len=jnp.where(ok, plen, 0).astype(jnp.int32),
        waypoints=jnp.where(ok[:, None, None], wps, -1),
        num_waypoints=jnp.where(ok, njp, 0).astype(jnp.int32))


_STATIC_ARGS = ("max_path_len", "max_waypoints", "lanes", "open_capacity", "trace_steps")
astar = jax.jit(_astar, static_argnames=_STATIC_ARGS)
astar.__doc__ = _astar.__doc__


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
        raise ValueError(f"starts and goals must have the same shape, got {starts.shape} and {goals.shape}")
    n = starts.shape[0]
    # the clipping keeps far-away cells invalid (outside the grid) and inside int32
    starts = np.clip(starts, -1, np.iinfo(np.int32).max).astype(np.int32)
    goals = np.clip(goals, -1, np.iinfo(np.int32).max).astype(np.int32)
    pending = []
    for lo in range(0, max(n, 1), chunk):
        s = np.full((chunk, 2), -1, np.int32)
        g = np.full((chunk, 2), -1, np.int32)
        m = min(chunk, n - lo)
        s[:m], g[:m] = starts[lo:lo + m], goals[lo:lo + m]
        pending.append((m, astar(graph, s, g, **options)))
    parts = [jax.tree.map(lambda x, m=m: np.asarray(x)[:m], r) for m, r in pending]
    return AStarResult(*(np.concatenate(xs) for xs in zip(*parts)))
