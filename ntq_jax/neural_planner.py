"""The neural planner of the paper (Alg. 1, after MPNet), batched over queries.

One implementation serves every robot: it only needs the robot's kernels
(:func:`ntq_jax.robots.batch.steer_to_cm`, ``is_valid_cm``, ``distance``) and a
generic planning network::

    pnet(key, current (N, d), goal (N, d)) -> next (N, d)

(pure and jittable; ``key`` drives dropout, MPNet's source of randomness).

Usage::

    opts = PlannerOptions(n_plan=50, replan_rounds=5)
    res = plan_batch(env, pnet, queries, jax.random.key(0), opts)
    res.paths, res.lengths, res.success, res.costs, res.cause

How a batch is planned
----------------------
All N queries step together inside one jitted call (``lax.while_loop`` over
steps with per-query masks, fixed shapes; the loop exits early once every query
is decided): coarse plan, contraction and feasibility check (steps 1-3 below).
Each replanning round (step 4) works on the infeasible paths only: the windows
to reconnect are found on the host (:func:`repair_windows`), then the blocked
segments of *all* those paths are reconnected together, gathered into
fixed-width chunks (``repair_width``) of one jitted neural connection each, and
spliced back; a last jitted call contracts and re-checks the repaired paths. A
round thus costs in proportion to the segments that need it, and a path with
many blocked segments does not keep its chunk busy one segment after another
(a masked full-width loop would run every query's PNet as long as the
slowest repair). Batches are padded to a power of two so repeated calls reuse
the compiled code; ``pnet`` is passed as a pytree
(:class:`jax.tree_util.Partial`), so two PNets that share the same apply
function and parameter shapes share one compilation.

1. **Coarse plan** (Alg. 1, lines 2-9): for ``n_plan`` iterations, if
   ``steerTo(pi_end, goal)`` append the goal and stop, else append
   ``PNet(pi_end, goal)``. With ``bidirectional=True`` (MPNet's variant) two
   paths grow alternately from the start and from the goal, each predicting
   towards the other's end, until their ends connect by ``steerTo``
   (``n_plan`` predictions in all).
   **Without steerTo** (``steer=False``, Section V): only PNet steps; stop as
   soon as ``||pi_end - goal||_2 <= delta``. The goal is not appended (no
   steering function to connect it), so the path ends within ``delta`` of it.
2. **Lazy states contraction** (MPNet): from each kept state jump to the
   farthest later state it can ``steerTo``; greedy farthest-first, which is
   what MPNet's recursive contraction computes.
3. **Feasibility** on the evaluation geometry (``eval_padding``, 0 by
   default): every segment checked by the exact / discretised ``steer_to``.
4. **Neural replanning** (MPNet), at most ``replan_rounds`` rounds while a path
   is infeasible: every blocked segment ``(p_k, p_k+1)``, widened to the nearest
   states that are not in collision (MPNet drops the states in collision
   first), is reconnected by the bidirectional neural connection (at most
   ``replan_steps`` predictions) and the new states are spliced in; then the
   path is contracted and re-checked. The windows of one path never overlap and
   are spliced last first, so a splice never moves a window still to splice and
   all connections of a round run at once. Unlike MPNet, which abandons the query
   at the first connection that fails, a failed connection leaves its segment
   as it was and the other segments are still repaired; the next round
   retries with new dropout masks. A splice that would overflow the path
   buffer (``max_len`` rows) is skipped.

The variant without steerTo has no contraction and no replanning (both need
the steering function); its paths are still checked for collisions, and only
collision-free ones count as successes.

The ``plan_padding`` (default 0) is the clearance of the planner's own
``steerTo`` calls; feasibility is always judged at ``eval_padding``.

Failure causes (:data:`CAUSES`): ``SUCCESS`` 0; ``NO_PATH`` 1 (goal not
reached within ``n_plan``; Alg. 1 returns the empty path); ``INFEASIBLE`` 2
(reached but still in collision after replanning); ``INVALID_QUERY`` 3 (start
or goal not a valid state on the evaluation geometry, or not finite).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial

from ntq_jax.planners.smoothing import shortcut_batch
from ntq_jax.robots.batch import is_valid_cm, steer_to_cm

Array = jax.Array

ALGORITHM_VERSION = 3  # bump when planning results change (saved evaluations are then redone)
SUCCESS, NO_PATH, INFEASIBLE, INVALID_QUERY = 0, 1, 2, 3
CAUSES = {SUCCESS: "success", NO_PATH: "no_path", INFEASIBLE: "infeasible",
          INVALID_QUERY: "invalid_query"}


@dataclasses.dataclass(frozen=True)
class PlannerOptions:
    """Static settings of the neural planner (hashable: part of the compile key).

    Attributes:
        n_plan: PNet iterations of the coarse plan (``N_plan`` of Alg. 1).
        steer: use ``steerTo`` (Alg. 1); False is the paper's variant without it.
        delta: goal tolerance of the variant without steerTo (``||.||_2`` in state space).
        replan_rounds: neural replanning rounds (0 disables replanning).
        replan_steps: PNet predictions per repaired segment.
        bidirectional: MPNet's bidirectional coarse plan instead of Alg. 1's forward one.
        contract: lazy states contraction after the coarse plan and after each repair.
        plan_padding: clearance of the planner's own steerTo calls.
        eval_padding: clearance of the feasibility check (0 = the evaluation geometry).
    """

    n_plan: int = 50
    steer: bool = True
    delta: float = 1.0
    replan_rounds: int = 5
    replan_steps: int = 20
    bidirectional: bool = False
    contract: bool = True
    plan_padding: float = 0.0
    eval_padding: float = 0.0

    def __post_init__(self):
        if self.n_plan < 1:
            raise ValueError(f"n_plan must be >= 1, got {self.n_plan}")
        if not (self.delta > 0 and math.isfinite(self.delta)):
            raise ValueError(f"delta must be > 0, got {self.delta}")
        if self.replan_rounds < 0 or self.replan_steps < 1:
            raise ValueError("replan_rounds must be >= 0 and replan_steps >= 1, got "
                             f"{self.replan_rounds}, {self.replan_steps}")
        for name in ("plan_padding", "eval_padding"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")

    @property
    def max_len(self) -> int:
        """Rows of the path buffer: coarse plan plus what replanning can add."""
        rounds = self.replan_rounds if self.steer else 0
        return self.n_plan + 2 + rounds * self.replan_steps

    @staticmethod
    def from_config(ev, steer: bool | None = None) -> "PlannerOptions":
        """Options from an :class:`ntq_jax.config.EvalConfig` (``steer`` overrides its first entry)."""
        return PlannerOptions(
            n_plan=ev.n_plan, steer=ev.steer[0] if steer is None else bool(steer),
            delta=ev.delta, replan_rounds=ev.replan_rounds,
            replan_steps=getattr(ev, "replan_steps", 20),
            bidirectional=getattr(ev, "bidirectional", False))


@dataclasses.dataclass(frozen=True)
class NeuralPlanResult:
    """Per-query results of :func:`plan_batch` (N queries, host NumPy arrays).

    Attributes:
        paths: ``(N, L, d)`` float32 states, start first; NaN after ``lengths[i]`` rows.
            Failed queries keep their last (coarse or partly repaired) path for inspection.
        lengths: ``(N,)`` int32 number of states.
        success: ``(N,)`` bool: reached the goal and collision-free on the evaluation geometry.
        costs: ``(N,)`` float64 path cost (the robot's metric); ``inf`` unless success.
        cause: ``(N,)`` int8 failure cause (:data:`CAUSES`).
        pnet_calls: ``(N,)`` int32 PNet predictions spent on the query.
        replans: ``(N,)`` int32 replanning rounds the query went through.
        seconds: wall time of the batch (compiled call only); ``compile_seconds``:
            time spent compiling for this call (0 when the compiled code was reused).
    """

    paths: np.ndarray
    lengths: np.ndarray
    success: np.ndarray
    costs: np.ndarray
    cause: np.ndarray
    pnet_calls: np.ndarray
    replans: np.ndarray
    seconds: float = 0.0
    compile_seconds: float = 0.0

    def path(self, i: int) -> np.ndarray:
        """Query ``i``'s path ``(lengths[i], d)``."""
        return self.paths[i, : self.lengths[i]]


# ---------------------------------------------------------------------------
# Building blocks (all inside jit; row-major (N, ...) arrays)
# ---------------------------------------------------------------------------

def _steer(robot, world, a: Array, b: Array, padding: float, mask: Array) -> Array:
    """``(M, d), (M, d) -> (M,)`` via the package's one steer_to kernel; unmasked = False."""
    return steer_to_cm(robot, world, a.T, b.T, padding, mask)


def _rows(x: Array, idx: Array) -> Array:
    """``x[n, idx[n]]`` for ``x (N, L, d)``, ``idx (N,)``."""
    return jnp.take_along_axis(x, idx[:, None, None], axis=1)[:, 0]


def _join(a: Array, na: Array, b: Array, nb: Array, length: int) -> tuple[Array, Array]:
    """``a[:na] + reversed(b[:nb])`` into ``(N, length, d)`` (NaN padded), and its length."""
    t = jnp.arange(length)[None, :]
    ia = jnp.clip(t, 0, a.shape[1] - 1)
    ib = jnp.clip(na[:, None] + nb[:, None] - 1 - t, 0, b.shape[1] - 1)
    ga = jnp.take_along_axis(a, ia[..., None], axis=1)
    gb = jnp.take_along_axis(b, ib[..., None], axis=1)
    out = jnp.where((t < na[:, None])[..., None], ga,
                    jnp.where((t < (na + nb)[:, None])[..., None], gb, jnp.nan))
    return out, na + nb


def _segments(robot, world, p: Array, n: Array, padding: float, mask: Array):
    """Per-segment freedom ``(N, L-1)`` and the segment mask (existing segments of masked rows)."""
    num, length, d = p.shape
    seg = (jnp.arange(length - 1)[None, :] < (n - 1)[:, None]) & mask[:, None]
    free = _steer(robot, world, p[:, :-1].reshape(-1, d), p[:, 1:].reshape(-1, d), padding,
                  seg.reshape(-1)).reshape(num, length - 1)
    return free, seg


def _contract(robot, world, p: Array, n: Array, padding: float, mask: Array):
    """Lazy states contraction of the masked paths (the others are returned unchanged).

    The rule (keep the start, then greedily the farthest later state reachable
    by one steerTo) is the package's path shortcutting,
    :func:`ntq_jax.planners.smoothing.shortcut_batch`, written once.
    """
    keep = mask & (n >= 2)
    q, m, _ = shortcut_batch(robot, world, p, jnp.where(keep, n, 0), padding)
    return jnp.where(keep[:, None, None], q, p), jnp.where(keep, m, n)


def _connect(robot, world, pnet, key, a: Array, b: Array, active: Array, steps: int,
             padding: float):
    """Bidirectional neural connection of ``a`` and ``b`` (MPNet), at most ``steps`` predictions.

    Returns ``(A, nA, B, nB, connected, calls)``: the two growing paths (``A[0] = a``,
    ``B[0] = b``) with their lengths; ``A[:nA] + reversed(B[:nB])`` joins them.
    """
    num, d = a.shape
    buf = jnp.full((num, steps + 1, d), jnp.nan, a.dtype)
    rows = jnp.arange(num)

    def cond(c):
        return (c[0] <= steps) & jnp.any(c[1] & ~c[2])

    def body(c):
        s, act, conn, pa, na, pb, nb, calls = c
        ea, eb = _rows(pa, na - 1), _rows(pb, nb - 1)
        live = act & ~conn
        joined = _steer(robot, world, ea, eb, padding, live)
        conn = conn | joined
        grow = live & ~joined & (s < steps)
        from_a = (s % 2) == 0
        cur, tgt = jnp.where(from_a, ea, eb), jnp.where(from_a, eb, ea)
        new = pnet(jax.random.fold_in(key, s), cur, tgt)
        pa = pa.at[rows, jnp.where(grow & from_a, na, steps + 1)].set(new, mode="drop")
        pb = pb.at[rows, jnp.where(grow & ~from_a, nb, steps + 1)].set(new, mode="drop")
        na = na + (grow & from_a)
        nb = nb + (grow & ~from_a)
        return s + 1, act, conn, pa, na, pb, nb, calls + grow

    one = jnp.ones(num, jnp.int32)
    init = (jnp.int32(0), active, jnp.zeros(num, bool), buf.at[:, 0].set(a), one,
            buf.at[:, 0].set(b), one, jnp.zeros(num, jnp.int32))
    _, _, conn, pa, na, pb, nb, calls = jax.lax.while_loop(cond, body, init)
    return pa, na, pb, nb, conn & active, calls


def _forward(pnet, key, starts, goals, active, opts: PlannerOptions, robot, world, length):
    """Alg. 1's coarse plan (with or without steerTo), all queries stepping together."""
    num, d = starts.shape
    rows = jnp.arange(num)
    p = jnp.full((num, length, d), jnp.nan, starts.dtype).at[:, 0].set(starts)

    def near(x):
        return jnp.sqrt(jnp.sum((x - goals) ** 2, axis=1)) <= opts.delta

    def cond(c):
        return (c[0] < opts.n_plan) & jnp.any(~c[4])

    def body(c):
        i, p, n, end, done, reached, calls = c
        live = ~done
        if opts.steer:
            hit = _steer(robot, world, end, goals, opts.plan_padding, live)
        else:
            hit = live & near(end)
        nxt = pnet(jax.random.fold_in(key, i), end, goals)
        new = jnp.where(hit[:, None], goals, nxt) if opts.steer else nxt
        append = live & (~hit | opts.steer)
        p = p.at[rows, jnp.where(append, n, length)].set(new, mode="drop")
        n = n + append
        end = jnp.where(append[:, None], new, end)
        reached = reached | hit
        done = done | hit
        calls = calls + (live & ~hit)
        return i + 1, p, n, end, done, reached, calls

    init = (jnp.int32(0), p, jnp.ones(num, jnp.int32), starts, ~active, jnp.zeros(num, bool),
            jnp.zeros(num, jnp.int32))
    _, p, n, end, done, reached, calls = jax.lax.while_loop(cond, body, init)
    if not opts.steer:  # the state appended last is checked too
        reached = reached | (active & ~done & near(end))
    return p, n, reached, calls


def _coarse_core(robot, opts: PlannerOptions, world, pnet, key, starts, goals, active):
    """Coarse plan, contraction and feasibility check of a batch (one jitted call)."""
    length = opts.max_len
    valid = (active & is_valid_cm(robot, world, starts.T, opts.eval_padding)
             & is_valid_cm(robot, world, goals.T, opts.eval_padding))
    if opts.bidirectional:
        pa, na, pb, nb, reached, calls = _connect(robot, world, pnet, key, starts, goals, valid,
                                                  opts.n_plan, opts.plan_padding)
        p, n = _join(pa, na, pb, nb, length)
    else:
        p, n, reached, calls = _forward(pnet, key, starts, goals, valid, opts, robot, world,
                                        length)
    if opts.steer and opts.contract:
        p, n = _contract(robot, world, p, n, opts.plan_padding, reached)
    free, seg = _segments(robot, world, p, n, opts.eval_padding, reached)
    blocked = seg & ~free
    feasible = reached & (n >= 2) & ~jnp.any(blocked, axis=1)
    return p, n, valid, reached, feasible, blocked, calls


def _valid_core(robot, opts: PlannerOptions, world, p, n):
    """Validity ``(N, L)`` of every path state on the evaluation geometry (one jitted call)."""
    num, length, d = p.shape
    t = jnp.arange(length)[None, :]
    ok = is_valid_cm(robot, world, p.reshape(-1, d).T, opts.eval_padding).reshape(num, length)
    return (ok & (t < n[:, None]),)


def _connect_core(robot, opts: PlannerOptions, world, pnet, key, a, b, active):
    """Neural connection of a batch of windows ``a -> b`` (one jitted call).

    Returns ``(sub (N, replan_steps + 2, d), ns, connected, calls)``: ``sub[:ns]``
    runs from ``a`` to ``b``.
    """
    steps = opts.replan_steps
    pa, na, pb, nb, conn, calls = _connect(robot, world, pnet, key, a, b, active, steps,
                                           opts.plan_padding)
    sub, ns = _join(pa, na, pb, nb, steps + 2)
    return sub, ns, conn, calls


def _check_core(robot, opts: PlannerOptions, world, p, n, todo):
    """Contraction (if on) and the feasibility check of the rows ``todo`` (one jitted call).

    Returns ``(p, n, feasible, blocked)``.
    """
    if opts.contract:
        p, n = _contract(robot, world, p, n, opts.plan_padding, todo)
    free, seg = _segments(robot, world, p, n, opts.eval_padding, todo)
    blocked = seg & ~free
    feasible = todo & (n >= 2) & ~jnp.any(blocked, axis=1)
    return p, n, feasible, blocked


def repair_windows(blocked: np.ndarray, ok: np.ndarray, n: int) -> list[tuple[int, int]]:
    """The windows ``(ia, ib)`` one replanning round reconnects in a path, last first.

    Step 4 of the module docstring: take the last blocked segment ``(k, k+1)`` not
    yet covered, widen it to the nearest states not in collision (``ia <= k`` and
    ``ib > k``; the start and the goal are always valid), and continue left of
    ``min(ia, k)``. Windows never overlap (neighbours may share an end state), so
    splicing them right to left never moves a window still to splice, and all of
    them can be connected at once.

    Args:
        blocked: ``(L-1,)`` blocked segments of the path.
        ok: ``(L,)`` validity of its states (False beyond its end).
        n: its length.
    """
    length = ok.shape[0]
    segs = np.flatnonzero(blocked[: max(n - 1, 0)])
    good = np.flatnonzero(ok[:n])
    out, cursor = [], length
    for k in segs[::-1]:
        if k >= cursor:
            continue
        left = good[good <= k]
        right = good[good > k]
        ia = int(left[-1]) if len(left) else 0
        ib = min(int(right[0]) if len(right) else length, n - 1)
        out.append((ia, ib))
        cursor = min(ia, int(k))
    return out


def _cost_core(robot, p, n):
    num, length, d = p.shape
    seg_cost = jax.vmap(robot.distance, in_axes=(1, 1))(
        p[:, :-1].reshape(-1, d).T, p[:, 1:].reshape(-1, d).T).reshape(num, length - 1)
    seg = jnp.arange(length - 1)[None, :] < (n - 1)[:, None]
    return jnp.sum(jnp.where(seg, seg_cost, 0.0), axis=1)


_JITS = {
    "coarse": jax.jit(_coarse_core, static_argnames=("robot", "opts")),
    "valid": jax.jit(_valid_core, static_argnames=("robot", "opts")),
    "connect": jax.jit(_connect_core, static_argnames=("robot", "opts")),
    "check": jax.jit(_check_core, static_argnames=("robot", "opts")),
}
_jit_cost = jax.jit(_cost_core, static_argnames=("robot",))
_COMPILED: dict = {}


def _signature(name, args) -> tuple:
    robot, opts = args[:2]
    leaves, tree = jax.tree_util.tree_flatten(args[2:])
    return (name, robot, opts, tree,
            tuple((x.shape, str(x.dtype)) for x in map(jnp.asarray, leaves)))


def _compiled(name, args):
    """The compiled stage ``name`` for these static settings and shapes (once per process)."""
    sig = _signature(name, args)
    if sig not in _COMPILED:
        _COMPILED[sig] = _JITS[name].lower(*args).compile()
    return _COMPILED[sig]


class _Timer:
    def __init__(self):
        self.run = 0.0
        self.compile = 0.0

    def call(self, name, args):
        t0 = time.perf_counter()
        fn = _compiled(name, args)
        t1 = time.perf_counter()
        out = jax.block_until_ready(fn(*args[2:]))
        self.compile += t1 - t0
        self.run += time.perf_counter() - t1
        return [np.asarray(o) for o in out]


# ---------------------------------------------------------------------------
# Public entry points
# ---------------------------------------------------------------------------

def as_pnet(pnet: Callable) -> Partial:
    """Wraps a ``pnet(key, current, goal)`` callable as a pytree for the jitted planner.

    A :class:`jax.tree_util.Partial` is passed through unchanged (its bound
    arguments, e.g. the parameters, are traced; only the function is part of the
    compile key), so build PNets as ``Partial(apply_fn, params)`` to share one
    compilation across ensemble members.
    """
    return pnet if isinstance(pnet, Partial) else Partial(pnet)


def padded_world(world, multiple: int = 16):
    """``world`` with its box and disc lists padded to a multiple of ``multiple``.

    The extra obstacles are tiny and far outside any workspace (at ``1e6``), so
    no state or motion inside the bounds can touch them; maps with similar
    obstacle counts then share one compilation of the planner. The kernels
    unroll over obstacles, so padding also lengthens every compilation (a
    5-box map padded to 16 compiles about 4x slower): worth it only when many
    maps share one obstacle-count bucket.
    """
    from ntq_jax.geometry import World

    def pad(a, row):
        n = a.shape[0]
        m = max(multiple, -(-n // multiple) * multiple)
        extra = jnp.tile(jnp.asarray(row, a.dtype)[None], (m - n, 1))
        return jnp.concatenate([a, extra]) if m > n else a

    return World(world.bounds, pad(world.boxes, [1e6, 1e6, 1.0, 1.0]),
                 pad(world.discs, [1e6, 1e6, 1.0]))


def bucket_size(n: int) -> int:
    """The padded batch size for ``n`` queries (next power of two)."""
    return 1 << max(0, (int(n) - 1).bit_length())


def _chunks(items: np.ndarray, width: int):
    """``(chunk index, part, sel, mask)`` for ``items`` in chunks of ``width``: ``sel`` is
    ``part`` padded to ``width`` with ``items[0]`` (ignored rows, ``mask`` False)."""
    for ci, lo in enumerate(range(0, len(items), width)):
        part = items[lo:lo + width]
        sel = np.full(width, items[0], items.dtype)
        sel[: len(part)] = part
        mask = np.zeros(width, bool)
        mask[: len(part)] = True
        yield ci, part, sel, mask


def _replan_round(robot, opts: PlannerOptions, world, fn, key, todo: np.ndarray, width: int,
                  timer: "_Timer", paths, lengths, feasible, blocked, calls) -> None:
    """One neural replanning round of the paths ``todo``, updating the arrays in place.

    The windows of every blocked segment of every path in ``todo``
    (:func:`repair_windows`) are reconnected in one batch of neural connections
    (chunks of ``width``), spliced in right to left, and the paths contracted and
    checked again.
    """
    length, d = paths.shape[1:]
    ok = np.zeros((len(todo), length), bool)
    for _, part, sel, _ in _chunks(np.arange(len(todo)), width):
        (o,) = timer.call("valid", (robot, opts, world, jnp.asarray(paths[todo[sel]]),
                                    jnp.asarray(lengths[todo[sel]])))
        ok[part] = o[: len(part)]
    wins = [(i, ia, ib) for j, i in enumerate(todo)
            for ia, ib in repair_windows(blocked[i], ok[j], int(lengths[i]))]
    rows, wa, wb = np.array(wins, np.int64).reshape(-1, 3).T
    ends = paths[rows, wa], paths[rows, wb]
    sub = np.zeros((len(wins), opts.replan_steps + 2, d), np.float32)
    ns = np.zeros(len(wins), np.int64)
    conn = np.zeros(len(wins), bool)
    for ci, part, sel, mask in _chunks(np.arange(len(wins)), width):
        o = timer.call("connect", (robot, opts, world, fn, jax.random.fold_in(key, ci),
                                   jnp.asarray(ends[0][sel]), jnp.asarray(ends[1][sel]),
                                   jnp.asarray(mask)))
        m = len(part)
        sub[part], ns[part], conn[part] = o[0][:m], o[1][:m], o[2][:m]
        np.add.at(calls, rows[part], o[3][:m])
    # splice p[:ia] + sub[:ns] + p[ib+1:n], right to left within a path (``wins`` lists
    # each path's windows last first, so no splice moves a window still to do)
    for w in np.flatnonzero(conn):
        i, ia, ib, s = rows[w], wa[w], wb[w], ns[w]
        n_old = int(lengths[i])
        nn = n_old - (ib - ia + 1) + s
        if nn > length:  # would overflow the path buffer: skipped
            continue
        tail = paths[i, ib + 1:n_old].copy()
        paths[i, ia:ia + s] = sub[w, :s]
        paths[i, ia + s:nn] = tail
        paths[i, nn:] = np.nan
        lengths[i] = nn
    for _, part, sel, mask in _chunks(np.arange(len(todo)), width):
        o = timer.call("check", (robot, opts, world, jnp.asarray(paths[todo[sel]]),
                                 jnp.asarray(lengths[todo[sel]]), jnp.asarray(mask)))
        m, idx = len(part), todo[part]
        paths[idx], lengths[idx], feasible[idx], blocked[idx] = (x[:m] for x in o)


def plan_batch(env, pnet: Callable, queries, key: Array,
               opts: PlannerOptions = PlannerOptions(), *, chunk: int = 1024,
               repair_width: int = 256, pad_obstacles: int = 0) -> NeuralPlanResult:
    """Plans every query with the neural planner (all of a chunk in one jitted call).

    Args:
        env: a :class:`ntq_jax.Env` (any robot).
        pnet: ``pnet(key, current (N, d), goal (N, d)) -> next (N, d)`` (see :func:`as_pnet`).
        queries: ``(K, 2, d)`` start and goal states.
        key: PRNG key (dropout); the result is deterministic given the key.
        opts: :class:`PlannerOptions`.
        chunk: largest batch per jitted call (batches are padded to a power of two).
        repair_width: batch width of the replanning calls: the infeasible paths of a
            round, and the windows they reconnect, are gathered into chunks of this
            many (power of two), so the rounds cost in proportion to what needs
            repair, not to the batch.
        pad_obstacles: if > 0, pad the obstacle lists to a multiple of it
            (:func:`padded_world`) so maps with similar counts share one compilation.

    Returns:
        A :class:`NeuralPlanResult` with paths trimmed to the longest one.

    Raises:
        ValueError: ``queries`` has the wrong shape.
    """
    q = np.asarray(queries, np.float32)
    if q.ndim != 3 or q.shape[1:] != (2, env.dim):
        raise ValueError(f"queries must have shape (K, 2, {env.dim}), got {q.shape}")
    if opts.bidirectional and not opts.steer:
        raise ValueError("the bidirectional planner needs steerTo (steer=True)")
    k = q.shape[0]
    fn = as_pnet(pnet)
    world = padded_world(env.world, pad_obstacles) if pad_obstacles > 0 else env.world
    size = bucket_size(min(max(k, 1), chunk))
    width = bucket_size(min(max(repair_width, 1), size))
    timer = _Timer()
    length, d = opts.max_len, env.dim
    paths = np.full((k, length, d), np.nan, np.float32)
    lengths = np.zeros(k, np.int32)
    valid = np.zeros(k, bool)
    reached = np.zeros(k, bool)
    feasible = np.zeros(k, bool)
    blocked = np.zeros((k, length - 1), bool)
    calls = np.zeros(k, np.int32)
    replans = np.zeros(k, np.int32)
    k_coarse, k_rep = jax.random.split(key)
    # 1. coarse plans, contraction, feasibility: all queries, chunks of ``size``
    for ci, lo in enumerate(range(0, k, size)):
        hi = min(lo + size, k)
        part = np.zeros((size, 2, d), np.float32)
        part[: hi - lo] = q[lo:hi]
        act = np.zeros(size, bool)
        act[: hi - lo] = True
        out = timer.call("coarse", (env.robot, opts, world, fn, jax.random.fold_in(k_coarse, ci),
                                    jnp.asarray(part[:, 0]), jnp.asarray(part[:, 1]),
                                    jnp.asarray(act)))
        for dst, src in zip((paths, lengths, valid, reached, feasible, blocked, calls), out):
            dst[lo:hi] = src[: hi - lo]
    # 2. replanning rounds, only on the infeasible paths (see :func:`_replan_round`)
    rounds = opts.replan_rounds if opts.steer else 0
    for r in range(rounds):
        todo = np.flatnonzero(reached & ~feasible)
        if not len(todo):
            break
        _replan_round(env.robot, opts, world, fn, jax.random.fold_in(k_rep, r), todo, width,
                      timer, paths, lengths, feasible, blocked, calls)
        replans[todo] += 1
    success = reached & feasible
    costs = np.full(k, np.inf)
    if success.any():
        ok = np.flatnonzero(success)
        cw = bucket_size(len(ok))
        sel = np.zeros(cw, np.int64)
        sel[: len(ok)] = ok
        costs[ok] = np.asarray(_jit_cost(env.robot, jnp.asarray(paths[sel]),
                                         jnp.asarray(lengths[sel])))[: len(ok)]
    cause = np.where(~valid, INVALID_QUERY,
                     np.where(~reached, NO_PATH, np.where(success, SUCCESS, INFEASIBLE)))
    top = max(1, int(lengths.max())) if k else 1
    return NeuralPlanResult(paths[:, :top], lengths, success, costs.astype(np.float64),
                            cause.astype(np.int8), calls, replans, timer.run, timer.compile)


def path_costs(env, paths: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Float64 cost of NaN-padded paths under the robot's metric (host side, for re-checks)."""
    paths = np.asarray(paths, np.float64)
    out = np.zeros(len(paths))
    for i, (p, n) in enumerate(zip(paths, lengths)):
        if n >= 2:
            out[i] = float(np.sum(np.asarray(env.distance(p[: n - 1], p[1:n]), np.float64)))
    return out
