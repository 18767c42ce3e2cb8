"""The search of the grid A* planner: batched, exact A* with jump point search, jitted.

The graph is the 8-connected, no-corner-cutting grid of
:mod:`ntq_jax.planners.grid_graph` (step costs 1 and sqrt(2), in cells). The
search is A* with the octile heuristic (consistent on this graph) that expands
only *jump points* (JPS, Harabor & Grastien 2011, in its no-corner-cutting form,
reading the pre-computed jump tables of JPS+) and catches the goal with the JPS+
target rules; the returned costs are those of an exact A*
(``tests/test_astar.py`` checks them against Dijkstra on the explicit graph).

Batching: the step of one query (:func:`_lane_step`: pop, jump, relax) is
vmapped over ``lanes`` search lanes inside one ``lax.while_loop``. A lane that
reaches its goal follows the parent links back and takes the next query of the
batch, so the loop ends when every query is done instead of waiting for the
slowest query of a group. Per lane: a dense ``(H*W,)`` uint32 array of cell
words stamped with the query's token (nothing is cleared between queries) and a
fixed-capacity open list.

Contract: :func:`search` solves valid, reachable, distinct queries and reports
SOLVED, NO_PATH or TIMEOUT (:class:`ntq_jax.types.PlanStatus`; TIMEOUT = a
buffer was too small) with the path's jump points; :func:`cells_from_jump_points`
expands them to cells. The public entry points are
:func:`ntq_jax.planners.astar.astar` and ``astar_chunked``. Measurements:
BENCHMARKS.md ("Classical planners").
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ntq_jax.planners.grid_graph import (
    DIRS,
    JUMP_BITS,
    SQRT2,
    STEP_COST,
    GridGraph,
    direction_index,
)
from ntq_jax.types import PlanStatus

Array = jax.Array

_START_CODE = 8  # arrival "direction" of the start node: every direction is a successor


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
            succ = [direction_index(0, dc), direction_index(dr, 0), k]
        else:
            sides = [(dc, dr), (-dc, -dr)]
            succ = (
                [k]
                + [direction_index(*s) for s in sides]
                + [direction_index(dr + s[0], dc + s[1]) for s in sides]
            )
        masks[k] = sum(1 << s for s in succ)
    masks[_START_CODE] = 255
    return masks


_SUCC_MASK = _successor_masks()


# ---------------------------------------------------------------------------
# One search step
# ---------------------------------------------------------------------------


def _octile(dr: Array, dc: Array) -> Array:
    a = jnp.abs(dr).astype(jnp.float32)
    b = jnp.abs(dc).astype(jnp.float32)
    return jnp.maximum(a, b) + (SQRT2 - 1.0) * jnp.minimum(a, b)


# Per-lane cell word (uint32): query token (15 bits) | closed (1 bit) | payload (16 bits).
# A cell is "seen" by the current query when its token matches. The payload of an
# open cell is its slot in the open list; a closed cell stores how it was entered,
# arrival direction (3 bits) and jump length (JUMP_BITS bits): its parent is
# ``cell - DIRS[dir] * length``.
_TOK_SHIFT, _CLOSED_BIT, _DIR_SHIFT, _DIST_BITS = 17, 1 << 16, JUMP_BITS, JUMP_BITS
_SLOT_MASK = (1 << 16) - 1
_DIST_MASK = (1 << _DIST_BITS) - 1
MAX_QUERIES_PER_CALL = (1 << 15) - 1
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


def _pop(of, orow, used, fresh, tok, start, goal, active):
    """Pops the open-list entry with the smallest f (lowest slot on ties); a new query pops its start.

    Returns ``(u, gu, how, act, reached, expand, popped, i, closed_word)``: the
    node, its g, how it was entered; whether the lane works this step, popped
    its goal, expands ``u``, freed the open-list slot ``i``; and ``u``'s closed word.
    """
    cap = of.shape[0]
    inf = jnp.float32(jnp.inf)
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
    closed_word = (tok << _TOK_SHIFT) | _CLOSED_BIT | (how & _SLOT_MASK).astype(jnp.uint32)
    # (barriers: materialise intermediate results once; XLA would otherwise recompute
    #  the whole elementwise chain inside every gather/scatter kernel that uses it)
    return lax.optimization_barrier((u, gu, how, act, reached, expand, popped, i, closed_word))


def _jumps(jump, u, gu, how, goal, expand, width: int):
    """One jump from ``u`` along each searched direction, stopping early on the goal (JPS+ target rules).

    Returns per direction ``(s, gs, fs, steps, has)``: the cell reached, its g
    and f, the number of steps, and whether it is a successor at all.
    """
    dirs = jnp.asarray(DIRS)
    dr_k, dc_k = dirs[:, 0], dirs[:, 1]
    is_diag = (dr_k != 0) & (dc_k != 0)
    offs = dr_k * width + dc_k
    ks = jnp.arange(8, dtype=jnp.int32)
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
    return lax.optimization_barrier((s, gs, fs, steps, has))


def _relax(
    word, of, orow, stack, top, used, tok, i, popped, act, u, closed_word, s, gs, fs, steps, has
):
    """Closes ``u`` and relaxes its successors: new cells take free slots (the popped one
    first), better ones are updated in place.

    Returns ``(word, of, orow, stack, top, used)`` updated and whether the open list overflowed.
    """
    hw = word.shape[0]
    cap = of.shape[0]
    inf = jnp.float32(jnp.inf)
    seen_word = tok << _TOK_SHIFT
    ks = jnp.arange(8, dtype=jnp.int32)
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
        (slot, new, overflow, spare, top, used)
    )
    of = of.at[jnp.concatenate([jnp.where(spare, i, cap)[None], slot])].set(
        jnp.concatenate([inf[None], fs]), mode="drop"
    )
    rows = jnp.stack([s, lax.bitcast_convert_type(gs, jnp.int32), (ks << _DIR_SHIFT) | steps], -1)
    orow = orow.at[slot].set(rows, mode="drop")
    cells = jnp.concatenate([jnp.where(act, u, hw)[None], jnp.where(new & ~overflow, s, hw)])
    words = jnp.concatenate([closed_word[None], seen_word | slot.astype(jnp.uint32)])
    word = word.at[cells].set(words, mode="drop")
    return (word, of, orow, stack, top, used), overflow


def _lane_step(jump, word, of, orow, stack, top, used, fresh, tok, start, goal, active, *, width):
    """One A*/JPS iteration of ONE query (vmapped over the lanes): pop, jump, relax.

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
    u, gu, how, act, reached, expand, popped, i, closed_word = _pop(
        of, orow, used, fresh, tok, start, goal, active
    )
    s, gs, fs, steps, has = _jumps(jump, u, gu, how, goal, expand, width)
    lane, overflow = _relax(
        word, of, orow, stack, top, used, tok, i, popped, act, u, closed_word, s, gs, fs, steps, has
    )
    exhausted = active & ~act
    return lane, (reached, gu, exhausted, overflow)


# ---------------------------------------------------------------------------
# The batched search
# ---------------------------------------------------------------------------

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
    return tuple(jump[:, p * per : (p + 1) * per].reshape(-1) for p in range(parts))


def _trace_back(
    word, jp, cur, j, s0, q, tracing, *, width: int, n: int, max_jp: int, trace_steps: int
):
    """Follows up to ``trace_steps`` parent links in every tracing lane, writing the jump
    points goal-first into ``jp`` (``(n * max_jp,)``, row ``q`` of each lane).

    Returns ``(jp, cur, j, done, too_long)``: the lane reached its start, or
    its path has more than ``max_jp`` jump points.
    """
    b = cur.shape[0]
    lane_ids = jnp.arange(b)
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
        back = _dir_offset((wc >> _DIR_SHIFT) & 7, width) * (wc & _DIST_MASK).astype(jnp.int32)
        step = act & ~fin
        cur = jnp.where(step, cur - back, cur)
        j = j + step
    jp = jp.at[jnp.stack(where_to, -1).reshape(-1)].set(jnp.stack(pts, -1).reshape(-1), mode="drop")
    return jp, cur, j, done, too_long


def search(
    graph: GridGraph,
    start: Array,
    goal: Array,
    nq: Array,
    *,
    lanes: int,
    cap: int,
    max_jp: int,
    trace_steps: int,
):
    """Solves queries ``0..nq-1`` of ``start``/``goal`` (flat cells ``(N,)``, valid, reachable, distinct).

    Returns per query ``(status, cost, jump points goal-first (N, max_jp), count (N,))``.
    """
    h, w = graph.occ.shape
    hw = h * w
    n = start.shape[0]
    b = lanes
    inf = jnp.float32(jnp.inf)
    jump = _split_jump_table(graph.jump)
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
            jump,
            st["word"],
            st["of"],
            st["orow"],
            st["stack"],
            top,
            used,
            take,
            tok,
            s0,
            g0,
            mode == _SEARCH,
        )
        mode = jnp.where(exhausted | overflow, _IDLE, jnp.where(reached, _TRACE, mode))
        cost_l = jnp.where(reached, g_goal, st["cost_l"])
        cur = jnp.where(reached, g0, st["cur"])
        j = jnp.where(reached, 0, st["j"])

        # -- lanes that reached their goal follow the parent links back to the start -----
        jp, cur, j, done, too_long = _trace_back(
            word,
            st["jp"],
            cur,
            j,
            s0,
            q,
            mode == _TRACE,
            width=w,
            n=n,
            max_jp=max_jp,
            trace_steps=trace_steps,
        )
        # -- record finished queries: one row (status, cost bits, #jump points) each ------
        fin = exhausted | overflow | done
        code = jnp.where(
            exhausted,
            PlanStatus.NO_PATH,
            jnp.where(overflow | too_long, PlanStatus.TIMEOUT, PlanStatus.SOLVED),
        )
        res_row = jnp.stack([code, lax.bitcast_convert_type(cost_l, jnp.int32), j + 1], -1)
        res = st["res"].at[jnp.where(fin, q, n)].set(res_row, mode="drop")
        mode = jnp.where(done, _IDLE, mode)
        return dict(
            mode=mode,
            q=q,
            next=nxt,
            word=word,
            of=of,
            orow=orow,
            stack=stack,
            top=top,
            used=used,
            res=res,
            cost_l=cost_l,
            cur=cur,
            j=j,
            jp=jp,
        )

    st = dict(
        mode=jnp.zeros(b, jnp.int32),
        q=jnp.zeros(b, jnp.int32),
        next=jnp.int32(0),
        word=jnp.zeros((b, hw), jnp.uint32),
        of=jnp.full((b, cap), inf),
        orow=jnp.zeros((b, cap, 3), jnp.int32),
        stack=jnp.zeros((b, cap), jnp.int32),
        top=jnp.zeros(b, jnp.int32),
        used=jnp.zeros(b, jnp.int32),
        res=jnp.zeros((n, 3), jnp.int32),
        cost_l=jnp.zeros(b),
        cur=jnp.zeros(b, jnp.int32),
        j=jnp.zeros(b, jnp.int32),
        jp=jnp.zeros(n * max_jp, jnp.int32),
    )
    st = lax.while_loop(cond, body, st)
    res = st["res"]
    return (
        res[:, 0].astype(jnp.int8),
        lax.bitcast_convert_type(res[:, 1], jnp.float32),
        st["jp"].reshape(n, max_jp),
        res[:, 2],
    )


def cells_from_jump_points(jp: Array, njp: Array, width: int, max_len: int):
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
    total = jnp.where(
        njp > 0, jnp.take_along_axis(pos, jnp.maximum(njp - 1, 0)[:, None], 1)[:, 0] + 1, 0
    )
    step = jnp.where(vseg, jnp.sign(dr) * width + jnp.sign(dc), 0)  # flat unit step of each segment
    change = step - jnp.concatenate([jnp.zeros((n, 1), jnp.int32), step[:, :-1]], 1)
    at = pos[:, :-1]
    flat = jnp.where(at < max_len, at * n + jnp.arange(n)[:, None], max_len * n)
    delta = (
        jnp.zeros(max_len * n, jnp.int32)
        .at[flat.reshape(-1)]
        .add(change.reshape(-1), mode="drop")
        .reshape(max_len, n)
    )

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


__all__ = ["search", "cells_from_jump_points", "MAX_QUERIES_PER_CALL", "MAX_OPEN_CAPACITY"]
