"""The ``"bitree"`` planner: a batched bidirectional tree (RRT-Connect-like), one compiled program.

A roadmap pays off when thousands of queries share a map. A query alone in its own map
(MotionBenchMaker's problems: every problem is its own scene) wants a single-query
planner, and one that makes no host round trip per step: a Python loop calling the
batched check once per RRT step pays the call's dispatch a few hundred times per query.
:func:`grow_bitree` is RRT-Connect's search written as one ``lax.while_loop`` over
fixed-size arrays, batched within each iteration:

* two trees, one rooted at the start and one at the goal, ``capacity`` nodes each;
* an iteration draws ``batch`` uniform targets in the configuration box and extends
  the active tree's nearest node (brute force, Euclidean) towards each by at most
  ``step`` (RRT's extension, ``batch`` of them at once); the new states whose motion
  from their parent is free (the package's discretised check, in the travelled
  direction: away from the start, towards the goal) join the tree;
* every new node then tries the straight motion to the other tree's node nearest to
  it (RRT-Connect's *connect*, which succeeds exactly when that straight motion is
  free); the first free one joins the trees and ends the search;
* the trees swap roles every iteration.

The path (start ... link ... goal) is read off the parent arrays and shortened in the
same program by the package's greedy farthest-visible rule (the rule of
:mod:`ntq_jax.planners.smoothing`) after each segment is split into ``split`` equal
parts, twice: the split lets the shortcut cut corners between waypoints, not only at
them. Its checks run on a work queue of :data:`SHORTCUT_LANES` lanes: a round checks
the motions from the current waypoint to every later one, and the check's default
512 lanes, most of them idle on a handful of live motions, made the two passes cost
~12 ms a query. :func:`plan_bitree` (registered as ``"bitree"``) runs it query by
query and verifies every path with the final check
(:func:`ntq_jax.planners.verify.finalize`, e.g. the certified check), a failing
segment replaced by the pieces of the split path it skipped; a query whose trees did
not meet, or whose path still fails the check, is tried again with the next key (up to
``attempts`` attempts).

The compiled program depends on the robot, the padding, the settings and the
obstacle counts of the world, not on the obstacles' values: every problem of a
MotionBenchMaker scene reuses one program.
"""

from __future__ import annotations

import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.planners.options import float_option, int_option, motion_check_option
from ntq_jax.planners.verify import finalize, valid_queries
from ntq_jax.robots.base import check_queue
from ntq_jax.robots.batch import steer_to_cm
from ntq_jax.types import PlanResult, PlanStatus

__all__ = ["grow_bitree", "plan_bitree", "BITREE_DEFAULTS", "SHORTCUT_LANES"]

#: Lanes of the shortcut's work queue (see the module docstring).
SHORTCUT_LANES = 16
#: States each lane of the checks' work queues tests per step.
STEP_STATES = 4
#: RRT-Connect's CONNECT in pieces of ``step`` (or of a ``CONNECT_PIECES``-th of the
#: connection, when it is longer): the trees meet when the whole straight connection is
#: free, and otherwise the free pieces' ends grow the other tree towards the new state.
CONNECT_PIECES = 1

#: The defaults (the Panda's, measured on MotionBenchMaker in benchmarks/bench_panda_plan.py):
#: ``batch`` extensions per iteration, ``step`` the longest extension (VAMP's and OMPL's
#: RRT-Connect range for the Panda: 1 rad), ``capacity`` nodes per tree, ``iterations``
#: per attempt, ``attempts`` per query, ``path_cap`` waypoints of a raw path, ``split``
#: parts per segment before each of the two shortcut passes. ``attempts`` 12: on
#: MotionBenchMaker's 699 valid problems (certified), 4 attempts solved 684 and 12 solved
#: 693; 601 of the 693 needed one attempt, so the extra ones cost only the hard problems.
BITREE_DEFAULTS = {
    "batch": 16,
    "step": 1.0,
    "capacity": 1024,
    "iterations": 128,
    "attempts": 12,
    "path_cap": 64,
    "split": 4,
}


def _nearest(tree: jax.Array, count: jax.Array, x: jax.Array) -> jax.Array:
    """Index of the node of ``tree (C, d)`` (its first ``count`` rows) nearest to each row
    of ``x (B, d)``."""
    d2 = jnp.sum((x[:, None, :] - tree[None, :, :]) ** 2, axis=-1)
    d2 = jnp.where(jnp.arange(tree.shape[0])[None, :] < count, d2, jnp.inf)
    return jnp.argmin(d2, axis=1).astype(jnp.int32)


def _free(robot, world, padding, a, b, lanes: int, mask=None, queue=None):
    """The discretised check of the row-major motions ``a -> b`` ``(N, d)``: the states of
    :func:`ntq_jax.robots.base.discretized_steer_to` (the same answers), on a work queue of
    ``lanes`` lanes testing :data:`STEP_STATES` states each per step, whose last busy
    lane moves to one lane testing ``lanes`` times as many (one long free motion,
    typically the connection that ends the search, would otherwise keep every lane
    stepping through it). ``queue``: ``(pick, work)`` the motions to check, in that
    order (:func:`ntq_jax.robots.base.check_queue`'s), instead of sorting all ``N``
    (then ``mask`` is not used). The point robot's exact test has no queue."""
    resolution = getattr(robot, "resolution", None)
    if resolution is None:
        return steer_to_cm(robot, world, a.T, b.T, padding, mask=mask)

    def steps(i):
        dist = jax.vmap(robot.distance)(a[i], b[i])
        return jnp.where(
            jnp.isfinite(dist), jnp.maximum(jnp.ceil(dist / resolution), 1.0), 0.0
        ).astype(jnp.int32)

    n = steps if queue is not None else steps(jnp.arange(a.shape[0]))
    interpolate = jax.vmap(
        jax.vmap(robot.interpolate, in_axes=(None, None, 0), out_axes=1),
        in_axes=(1, 1, 1),
        out_axes=2,
    )
    is_valid = jax.vmap(
        jax.vmap(jax.jit(robot.is_valid, static_argnums=2), in_axes=(1, None, None)),
        in_axes=(1, None, None),
    )

    def valid_at(ap, bp, t):
        return is_valid(interpolate(ap, bp, t), world, padding)

    return check_queue(
        a.T,
        b.T,
        n,
        valid_at,
        None if queue is not None else mask,
        lanes,
        STEP_STATES,
        queue=queue,
        tail_lanes=1,
    )


def grow_bitree(
    robot,
    world,
    start,
    goal,
    key,
    padding: float,
    *,
    batch: int,
    step: float,
    capacity: int,
    iterations: int,
    path_cap: int,
    split: int,
):
    """Searches one query with two trees and returns the shortened path (traceable).

    Args:
        robot: the robot (static).
        world: the obstacles (traced).
        start, goal: ``(d,)`` float32 valid states.
        key: a PRNG key.
        padding: the planning clearance (static).
        batch, step, capacity, iterations, path_cap, split: see
            :data:`BITREE_DEFAULTS` (static).

    Returns:
        ``(path, length, fine, fine_length, index, found, iters, nodes)``: the shortened
        path ``(P, d)`` (``P = path_cap * split``, NaN-padded) and its waypoint count
        (0 unless found); the split path its last pass shortened, its count, and
        ``index (P,)`` the waypoint of it each kept waypoint is (the verification's
        fallback); whether the trees met (and the path fitted ``path_cap``); the
        iterations used; the nodes of both trees ``(2,)``.
    """
    d = start.shape[0]
    lo, hi = (x.astype(jnp.float32) for x in robot.config_bounds(world))
    nodes = jnp.zeros((2, capacity, d), jnp.float32).at[0, 0].set(start).at[1, 0].set(goal)
    parent = jnp.full((2, capacity), -1, jnp.int32)
    count = jnp.ones((2,), jnp.int32)
    pieces = CONNECT_PIECES

    def cond(c):
        _, _, count, found, _, it, _ = c
        return ~found & (it < iterations) & jnp.all(count <= capacity - batch * (pieces + 1))

    def body(c):
        nodes, parent, count, found, link, it, key = c
        key, k1 = jax.random.split(key)
        t = it % 2  # the tree extended towards the random targets; 1 - t the other
        o = 1 - t
        mine, other = nodes[t], nodes[o]
        target = lo + jax.random.uniform(k1, (batch, d), jnp.float32) * (hi - lo)
        near = _nearest(mine, count[t], target)
        base = mine[near]
        gap = target - base
        dist = jnp.sqrt(jnp.sum(gap * gap, axis=1, keepdims=True))
        new = base + gap * jnp.minimum(1.0, step / jnp.maximum(dist, 1e-12))
        # CONNECT, speculatively: the other tree's node nearest to each new state steps
        # towards it in pieces of ``step`` (or of a ``pieces``-th of the way, when longer);
        # the ends of the pieces up to the first blocked one join the other tree, and the
        # trees meet when every piece is free (the whole straight motion)
        far = _nearest(other, count[o], new)
        need, ends = _connect_pieces(other[far], new, step, pieces)
        p0, p1 = ends[:, :-1].reshape(-1, d), ends[:, 1:].reshape(-1, d)
        # one check: the extensions, then the pieces, each in the travelled direction
        # (start side first)
        start_side = t == 0
        a = jnp.where(start_side, jnp.concatenate([base, p1]), jnp.concatenate([new, p0]))
        b = jnp.where(start_side, jnp.concatenate([new, p0]), jnp.concatenate([base, p1]))
        free = _free(robot, world, padding, a, b, a.shape[0])
        ok = free[:batch]
        piece_ok = free[batch:].reshape(batch, pieces)
        kp = jnp.arange(pieces)[None, :]
        prefix = jnp.sum(jnp.cumprod(piece_ok | (kp >= need[:, None]), axis=1), axis=1)
        hit_b = ok & (prefix >= pieces)
        # the extensions join their tree
        pos = jnp.where(ok, count[t] + jnp.cumsum(ok, dtype=jnp.int32) - 1, capacity)
        nodes = nodes.at[t].set(mine.at[pos].set(new, mode="drop"))
        parent = parent.at[t].set(parent[t].at[pos].set(near, mode="drop"))
        count = count.at[t].add(jnp.sum(ok, dtype=jnp.int32))
        # the free pieces' far ends short of ``new`` join the other tree, chained
        grow = ok[:, None] & (kp < prefix[:, None]) & (kp + 1 < need[:, None])  # (batch, pieces)
        flat = grow.reshape(-1)
        gpos = jnp.where(flat, count[o] + jnp.cumsum(flat, dtype=jnp.int32) - 1, capacity)
        gpos2 = gpos.reshape(batch, pieces)
        up = jnp.concatenate([far[:, None], gpos2[:, :-1]], axis=1)  # each piece's start node
        nodes = nodes.at[o].set(nodes[o].at[gpos].set(ends[:, 1:].reshape(-1, d), mode="drop"))
        parent = parent.at[o].set(parent[o].at[gpos].set(up.reshape(-1), mode="drop"))
        count = count.at[o].add(jnp.sum(flat, dtype=jnp.int32))
        # the link: ``new`` and the other tree's node the last piece starts from
        first = jnp.argmax(hit_b)
        hit = jnp.any(hit_b)
        last = jnp.maximum(need[first] - 1, 0)
        meet = jnp.where(last == 0, far[first], gpos2[first, jnp.maximum(last - 1, 0)])
        pair = jnp.where(start_side, jnp.stack([pos[first], meet]), jnp.stack([meet, pos[first]]))
        link = jnp.where(hit, pair, link)
        return nodes, parent, count, found | hit, link, it + 1, key

    init = (nodes, parent, count, jnp.bool_(False), jnp.zeros((2,), jnp.int32), jnp.int32(0), key)
    nodes, parent, count, found, link, iters, _ = jax.lax.while_loop(cond, body, init)
    raw, n = _read_path(nodes, parent, link, path_cap)
    found = found & (n <= path_cap)
    n = jnp.where(found, n, 0)
    short, k, fine, m, index = _shorten(robot, world, raw, n, padding, path_cap, split)
    return short, k, fine, m, index, found, iters, count


def _connect_pieces(root, new, step: float, pieces: int):
    """CONNECT's pieces from the other tree's nodes ``root (B, d)`` to the new states
    ``new (B, d)``: ``(need (B,) int32, ends (B, pieces + 1, d))``, the pieces needed to
    reach ``new`` (pieces of ``step``, or of a ``pieces``-th of the way when longer) and
    the pieces' ends, ``new`` from the ``need``-th on."""
    kk = jnp.arange(pieces + 1, dtype=jnp.float32)
    span = new - root
    length = jnp.sqrt(jnp.sum(span * span, axis=1))
    piece = jnp.maximum(step, length / pieces)
    need = jnp.clip(jnp.ceil(length / piece), 1, pieces).astype(jnp.int32)
    frac = jnp.minimum(kk[None, :] * piece[:, None] / jnp.maximum(length, 1e-12)[:, None], 1.0)
    pts = root[:, None, :] + frac[:, :, None] * span[:, None, :]
    return need, jnp.where((kk[None, :] >= need[:, None])[:, :, None], new[:, None, :], pts)


def _shorten(robot, world, raw, n, padding: float, path_cap: int, split: int):
    """The raw path ``(path_cap, d)`` (``n`` waypoints) split into ``split`` parts per
    segment and shortened by the greedy rule, twice: ``(short, k, fine, m, index)`` as
    :func:`grow_bitree` returns them."""
    d = raw.shape[1]
    size = path_cap * split
    path = jnp.concatenate([raw, jnp.full((size - path_cap, d), jnp.nan, jnp.float32)])

    def one_pass(_, carry):
        path, n = carry[:2]
        fine, m = _split(path, n, split)
        short, k, index = _greedy(robot, world, fine, m, padding)
        return short, k, fine, m, index

    empty = (path, n, path, n, jnp.zeros((size,), jnp.int32))
    return jax.lax.fori_loop(0, 2, one_pass, empty)


def _read_path(nodes, parent, link, cap: int):
    """The waypoints start ... goal through ``link`` (``(cap, d)`` NaN-padded) and their
    count (``> cap`` when the path does not fit)."""
    d = nodes.shape[2]

    def chain(tree, i):
        def step(carry, _):
            v, k = carry
            nxt = jnp.where(v >= 0, parent[tree, jnp.maximum(v, 0)], -1)
            return (nxt, k + (v >= 0)), v

        (_, k), vs = jax.lax.scan(step, (i, jnp.int32(0)), None, length=cap + 1)
        return vs, k  # vs: node indices from i back to the root, then -1

    va, ka = chain(0, link[0])  # link ... start
    vb, kb = chain(1, link[1])  # link ... goal
    # start side reversed: position j holds va[ka - 1 - j]
    j = jnp.arange(cap)
    ia = jnp.clip(ka - 1 - j, 0, cap)
    ib = jnp.clip(j - ka, 0, cap)
    pa = nodes[0][jnp.maximum(va[ia], 0)]
    pb = nodes[1][jnp.maximum(vb[ib], 0)]
    pts = jnp.where((j < ka)[:, None], pa, pb)
    n = ka + kb
    pts = jnp.where((j < n)[:, None], pts, jnp.nan)
    return pts.astype(jnp.float32).reshape(cap, d), n


def _split(path, n, parts: int):
    """The ``(P, d)`` path's first ``n`` waypoints with each segment cut into ``parts`` equal
    ones (into 1 when that would not fit ``P``): ``(P, d)`` NaN-padded, the original
    waypoints exact, and the new count."""
    size = path.shape[0]
    s = jnp.where((n - 1) * parts + 1 <= size, parts, 1)
    m = jnp.where(n > 1, (n - 1) * s + 1, n)
    k = jnp.arange(size)
    seg = jnp.minimum(k // s, jnp.maximum(n - 2, 0))
    frac = (k - seg * s).astype(jnp.float32) / s.astype(jnp.float32)
    a, b = path[seg], path[jnp.minimum(seg + 1, size - 1)]
    pts = jnp.where((frac == 0)[:, None], a, a + frac[:, None] * (b - a))
    pts = jnp.where((k == m - 1)[:, None], path[jnp.maximum(n - 1, 0)], pts)
    return jnp.where((k < m)[:, None], pts, jnp.nan), m


def _greedy(robot, world, path, n, padding):
    """The greedy farthest-visible shortcut of the ``(P, d)`` path's first ``n`` waypoints
    (the rule of :mod:`ntq_jax.planners.smoothing`), checked on :data:`SHORTCUT_LANES`
    lanes: ``(path (P, d), count, index (P,))``."""
    size, d = path.shape
    j = jnp.arange(size, dtype=jnp.int32)

    def check(a, b, cur):
        # the queue: the later waypoints cur + 1 .. n - 1, farthest first
        return _free(
            robot,
            world,
            padding,
            a,
            b,
            SHORTCUT_LANES,
            queue=(lambda pos: jnp.clip(n - 1 - pos, 0, size - 1), n - 1 - cur),
        )

    def cond(c):
        return ~c[3]

    def body(c):
        cur, index, count, _ = c
        mask = (j > cur) & (j < n)
        seen = check(jnp.broadcast_to(path[cur], (size, d)), path, cur) & mask
        far = jnp.max(jnp.where(seen, j, -1))
        nxt = jnp.where(far > cur, far, cur + 1)
        index = index.at[count].set(nxt, mode="drop")
        return nxt, index, count + 1, nxt >= n - 1

    index = jnp.full((size,), -1, jnp.int32).at[0].set(0)
    _, index, count, _ = jax.lax.while_loop(cond, body, (jnp.int32(0), index, jnp.int32(1), n <= 1))
    count = jnp.where(n <= 1, n, count)
    keep = j < count
    out = jnp.where(keep[:, None], path[jnp.clip(index, 0, size - 1)], jnp.nan)
    return out, count, jnp.where(keep, index, -1)


@functools.partial(
    jax.jit,
    static_argnames=(
        "robot",
        "padding",
        "batch",
        "step",
        "capacity",
        "iterations",
        "path_cap",
        "split",
    ),
    compiler_options=KERNEL_COMPILER_OPTIONS,
)
def _grow(
    robot, world, start, goal, key, padding, batch, step, capacity, iterations, path_cap, split
):
    return grow_bitree(
        robot,
        world,
        start,
        goal,
        key,
        padding,
        batch=batch,
        step=step,
        capacity=capacity,
        iterations=iterations,
        path_cap=path_cap,
        split=split,
    )


def plan_bitree(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    check: str = "discretized",
    batch: int | None = None,
    step: float | None = None,
    capacity: int | None = None,
    iterations: int | None = None,
    attempts: int | None = None,
    path_cap: int | None = None,
    split: int | None = None,
) -> PlanResult:
    """Plans each query with :func:`grow_bitree` (the registry's ``"bitree"``).

    Args:
        env: the environment (any robot; best for one query per map).
        queries: ``(K, 2, d)`` (start, goal) states.
        padding: planning clearance (None: the environment's).
        seed: query ``i``'s attempt ``a`` uses ``fold_in(fold_in(key(seed), i), a)``.
        check: the motion check every segment of a SOLVED path passes (the search and
            the shortcut use the discretised check; a path failing ``check`` counts as
            a failed attempt).
        batch, step, capacity, iterations, attempts, path_cap, split: see
            :data:`BITREE_DEFAULTS` (None: the default).

    Returns:
        A verified :class:`PlanResult`: NO_PATH when no attempt gave a path passing
        ``check``. ``info``: ``iterations`` ``(K,)`` used in the successful (or last)
        attempt, ``attempts`` ``(K,)``, ``tree_nodes`` ``(K, 2)``, ``plan_times``
        ``(K,)`` seconds per query (search, shortcut and check, all attempts),
        ``rejected`` (paths that failed ``check``) and ``check_time``.
    """
    opts = dict(BITREE_DEFAULTS)
    for name, value, low in (
        ("batch", batch, 1),
        ("capacity", capacity, 2),
        ("iterations", iterations, 1),
        ("attempts", attempts, 1),
        ("path_cap", path_cap, 2),
        ("split", split, 1),
    ):
        v = int_option("bitree", name, value, low, none_ok=True)
        if v is not None:
            opts[name] = v
    if step is not None:
        opts["step"] = float_option("bitree", "step", step)
    check = motion_check_option("bitree", check)
    pad = env.resolve_padding(padding)
    q = np.asarray(queries, np.float32)
    nq, d = q.shape[0], q.shape[2]
    if opts["capacity"] <= opts["batch"]:
        raise ValueError(
            f"bitree: capacity must exceed batch ({opts['batch']}), got {opts['capacity']}"
        )
    t0 = time.perf_counter()
    status = np.full(nq, PlanStatus.NO_PATH, np.int8)
    status[~valid_queries(env, q, pad)] = PlanStatus.INVALID
    rows: dict[int, PlanResult] = {}
    iters, tries = np.zeros(nq, np.int32), np.zeros(nq, np.int32)
    nodes, times = np.zeros((nq, 2), np.int32), np.zeros(nq)
    counts = {"rejected": 0, "check_time": 0.0}
    base = jax.random.key(int(seed))
    static = {k: opts[k] for k in ("batch", "step", "capacity", "iterations", "path_cap", "split")}
    solved = np.array([PlanStatus.SOLVED], np.int8)
    for i in np.flatnonzero(status == PlanStatus.NO_PATH):
        ti = time.perf_counter()
        for attempt in range(opts["attempts"]):
            key = jax.random.fold_in(jax.random.fold_in(base, int(i)), attempt)
            path, n, fine, m, index, found, it, cnt = jax.device_get(
                _grow(env.robot, env.world, q[i, 0], q[i, 1], key, pad, **static)
            )
            tries[i], iters[i], nodes[i] = attempt + 1, it, cnt
            if not found:
                continue
            ts = time.perf_counter()
            fallback = (fine[None], np.array([m]), index[None])
            one = finalize(
                q[i : i + 1],
                path[None, : max(2, int(n))],
                np.array([n]),
                solved,
                {},
                env,
                pad,
                check,
                fallback=None if check == "discretized" else fallback,
            )
            counts["check_time"] += time.perf_counter() - ts
            if one.solved[0]:  # a path failing ``check``: the next attempt's path instead
                rows[int(i)] = one
                break
            counts["rejected"] += 1
        times[i] = time.perf_counter() - ti
    width = max([2] + [int(r.lengths[0]) for r in rows.values()])
    paths = np.full((nq, width, d), np.nan, np.float32)
    lengths, costs = np.zeros(nq, np.int32), np.full(nq, np.inf)
    for i, r in rows.items():
        paths[i, : r.lengths[0]] = r.paths[0, : r.lengths[0]]
        lengths[i], costs[i], status[i] = r.lengths[0], r.costs[0], PlanStatus.SOLVED
    info = {
        "planner": "bitree",
        **opts,
        "check": check,
        "iterations": iters,
        "attempts": tries,
        "tree_nodes": nodes,
        "plan_times": times,
        **counts,
        "time": time.perf_counter() - t0,
    }
    return PlanResult(paths, lengths, costs, status, info)
