"""The jitted steps of the neural planner (:mod:`ntq_jax.neural.driver`).

Every function here runs inside ``jax.jit`` on row-major ``(N, ...)`` arrays of
fixed shape, with per-row masks: the coarse plan of a batch of queries with its
contraction and feasibility check (:func:`coarse_core`), the validity of path
states (:func:`valid_core`), the bidirectional neural connection of a batch of
windows (:func:`connect_core`), the contraction and re-check of repaired paths
(:func:`check_core`) and the costs of the successful paths (:data:`cost_jit`,
float32 in the robot's metric). Wherever a step asks the PNet for a next state
it goes through :func:`~ntq_jax.neural.proposals.propose`: one PNet's prediction, or,
for an :class:`~ntq_jax.neural.proposals.EnsemblePNet`, every member's prediction and the
:func:`~ntq_jax.neural.proposals.choose` rule (:mod:`ntq_jax.neural.proposals`). The
stages take ``(robot, opts, world, ...)``:
the robot and ``opts`` (a :class:`ntq_jax.neural.options.PlannerOptions`, whose
paddings are numbers) are static, the world is traced. :class:`Stages` runs
them through a bounded cache of compiled programs keyed by the static settings
(``opts.for_stage``: only the fields the stage reads) and the input shapes.
"""

from __future__ import annotations

import collections
import time

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.neural import host_stages
from ntq_jax.neural.motions import feasible_rows
from ntq_jax.neural.motions import segments as _segments
from ntq_jax.neural.motions import steer as _steer
from ntq_jax.neural.proposals import fold_in, proposals_per_call, propose
from ntq_jax.planners.smoothing import shortcut_batch
from ntq_jax.robots.batch import is_valid_cm

Array = jax.Array

COMPILED_CACHE_SIZE = 64  # compiled stages kept (the least recently used is dropped first)
# Paths per call of the check stage (contraction and feasibility), whatever the batch size:
# the stage holding the motion check, the slowest to compile, compiles once per robot,
# options and map instead of once per batch size. Masked padding rows cost little (their
# motions are never swept).
CHECK_ROWS = 256


# ---------------------------------------------------------------------------
# Building blocks (inside jit)
# ---------------------------------------------------------------------------


def _count(mask: Array, k: int) -> Array:
    """``mask`` counted ``k`` times (the mask itself for ``k = 1``)."""
    return mask if k == 1 else mask.astype(jnp.int32) * k


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
    out = jnp.where(
        (t < na[:, None])[..., None],
        ga,
        jnp.where((t < (na + nb)[:, None])[..., None], gb, jnp.nan),
    )
    return out, na + nb


def contract(robot, world, p: Array, n: Array, padding: float, mask: Array):
    """Lazy states contraction of the masked paths (the others are returned unchanged).

    The rule (keep the start, then greedily the farthest later state reachable
    by one steerTo) is the package's path shortcutting,
    :func:`ntq_jax.planners.smoothing.shortcut_batch`, written once.
    """
    keep = mask & (n >= 2)
    q, m, _ = shortcut_batch(robot, world, p, jnp.where(keep, n, 0), padding)
    return jnp.where(keep[:, None, None], q, p), jnp.where(keep, m, n)


def _connect(
    robot, world, pnet, key, a: Array, b: Array, active: Array, steps: int, padding: float
):
    """Bidirectional neural connection of ``a`` and ``b`` (MPNet), at most ``steps`` predictions.

    Returns ``(A, nA, B, nB, connected, calls)``: the two growing paths (``A[0] = a``,
    ``B[0] = b``) with their lengths; ``A[:nA] + reversed(B[:nB])`` joins them.
    """
    num, d = a.shape
    k = proposals_per_call(pnet)
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
        new = propose(robot, world, pnet, fold_in(key, s), cur, tgt, grow, padding)
        pa = pa.at[rows, jnp.where(grow & from_a, na, steps + 1)].set(new, mode="drop")
        pb = pb.at[rows, jnp.where(grow & ~from_a, nb, steps + 1)].set(new, mode="drop")
        na = na + (grow & from_a)
        nb = nb + (grow & ~from_a)
        return s + 1, act, conn, pa, na, pb, nb, calls + _count(grow, k)

    one = jnp.ones(num, jnp.int32)
    init = (
        jnp.int32(0),
        active,
        jnp.zeros(num, bool),
        buf.at[:, 0].set(a),
        one,
        buf.at[:, 0].set(b),
        one,
        jnp.zeros(num, jnp.int32),
    )
    _, _, conn, pa, na, pb, nb, calls = jax.lax.while_loop(cond, body, init)
    return pa, na, pb, nb, conn & active, calls


def _forward(robot, world, pnet, key, starts, goals, active, opts, length):
    """Alg. 1's coarse plan (with or without steerTo), all queries stepping together.

    Without steerTo a query is reached once its path's end (the start included)
    is within ``opts.delta`` of the goal in the robot's metric (``robot.distance``;
    ``opts.delta_norm == "l2"``: the raw state vector's Euclidean norm);
    the goal is not appended (``opts.nosteer_check == "replan"``: it is, as with steerTo),
    so a start already that close keeps a path of one state.
    """
    num, d = starts.shape
    rows = jnp.arange(num)
    k = proposals_per_call(pnet)
    p = jnp.full((num, length, d), jnp.nan, starts.dtype).at[:, 0].set(starts)

    def near(x):  # within delta of the goal: robot metric (angles wrap) or raw-vector L2
        if opts.delta_norm == "l2":
            return jnp.sqrt(jnp.sum((x - goals) ** 2, axis=-1)) <= opts.delta
        return jax.vmap(robot.distance)(x, goals) <= opts.delta

    def cond(c):
        return (c[0] < opts.n_plan) & jnp.any(~c[4])

    def body(c):
        i, p, n, end, done, reached, calls = c
        live = ~done
        if opts.steer:
            hit = _steer(robot, world, end, goals, opts.plan_padding, live)
        else:
            hit = live & near(end)
        nxt = propose(
            robot,
            world,
            pnet,
            fold_in(key, i),
            end,
            goals,
            live & ~hit,
            opts.plan_padding,
            opts.steer,
        )
        new = jnp.where(hit[:, None], goals, nxt) if opts.repairs else nxt
        append = live & (~hit | opts.repairs)
        p = p.at[rows, jnp.where(append, n, length)].set(new, mode="drop")
        n = n + append
        end = jnp.where(append[:, None], new, end)
        reached = reached | hit
        done = done | hit
        calls = calls + _count(live & ~hit, k)
        return i + 1, p, n, end, done, reached, calls

    init = (
        jnp.int32(0),
        p,
        jnp.ones(num, jnp.int32),
        starts,
        ~active,
        jnp.zeros(num, bool),
        jnp.zeros(num, jnp.int32),
    )
    _, p, n, end, done, reached, calls = jax.lax.while_loop(cond, body, init)
    if not opts.steer:  # the state appended last is checked too (with repairs: goal appended)
        last = active & ~done & near(end)
        reached = reached | last
        if opts.repairs:
            p = p.at[rows, jnp.where(last, n, length)].set(goals, mode="drop")
            n = n + last
    return p, n, reached, calls


def _contract_and_check(robot, world, opts, p, n, mask, do_contract: bool):
    """Contraction (if ``do_contract``) and the feasibility check of the rows ``mask``.

    Returns ``(p, n, feasible, blocked)``: ``blocked (N, L-1)`` are the segments in
    collision at ``eval_padding``; ``feasible`` rows have none (without steerTo and
    ``opts.nosteer_check`` False: every row with a state; ``"states"``: every row whose
    states are all valid at ``eval_padding``). A path of one state
    (without steerTo, a start within ``delta`` of the goal) has no segment and is
    feasible: its state is the query's start, already checked valid.
    """
    if do_contract:
        p, n = contract(robot, world, p, n, opts.plan_padding, mask)
    free, seg = _segments(robot, world, p, n, opts.eval_padding, mask, opts.eval_check)
    blocked = seg & ~free
    feasible = feasible_rows(
        opts, mask, n, blocked, lambda: valid_core(robot, opts, world, p, n)[0]
    )
    return p, n, feasible, blocked


# ---------------------------------------------------------------------------
# The stages (one jitted call each)
# ---------------------------------------------------------------------------


def coarse_core(robot, opts, world, pnet, key, starts, goals, active):
    """Coarse plan of a batch (one jitted call): ``(p, n, valid, reached, calls)``.

    ``valid``: the ``active`` rows whose start and goal are valid at ``opts.eval_padding``;
    only they are planned (:func:`coarse_plan_core`). Its contraction and feasibility
    check are :func:`check_core`'s, a separate stage of a fixed shape
    (:data:`CHECK_ROWS` paths) compiled once per process.
    """
    valid = (
        active
        & is_valid_cm(robot, world, starts.T, opts.eval_padding)
        & is_valid_cm(robot, world, goals.T, opts.eval_padding)
    )
    return coarse_plan_core(robot, opts, world, pnet, key, starts, goals, valid)


def coarse_plan_core(robot, opts, world, pnet, key, starts, goals, valid):
    """:func:`coarse_core` with the rows to plan given (``valid``: their ends already
    checked, e.g. on the host by :mod:`ntq_jax.neural.host_stages`), so the program holds
    no validity check of its own: ``(p, n, valid, reached, calls)``."""
    length = opts.max_len
    if opts.bidirectional:
        pa, na, pb, nb, reached, calls = _connect(
            robot, world, pnet, key, starts, goals, valid, opts.n_plan, opts.plan_padding
        )
        p, n = _join(pa, na, pb, nb, length)
    else:
        p, n, reached, calls = _forward(robot, world, pnet, key, starts, goals, valid, opts, length)
    return p, n, valid, reached, calls


def valid_core(robot, opts, world, p, n):
    """Validity ``(N, L)`` of every path state on the evaluation geometry (one jitted call)."""
    num, length, d = p.shape
    t = jnp.arange(length)[None, :]
    ok = is_valid_cm(robot, world, p.reshape(-1, d).T, opts.eval_padding).reshape(num, length)
    return (ok & (t < n[:, None]),)


def connect_core(robot, opts, world, pnet, key, a, b, active):
    """Neural connection of a batch of windows ``a -> b`` (one jitted call).

    Returns ``(sub (N, replan_steps + 2, d), ns, connected, calls)``: ``sub[:ns]``
    runs from ``a`` to ``b``.
    """
    steps = opts.replan_steps
    pa, na, pb, nb, conn, calls = _connect(
        robot, world, pnet, key, a, b, active, steps, opts.plan_padding
    )
    sub, ns = _join(pa, na, pb, nb, steps + 2)
    return sub, ns, conn, calls


def check_core(robot, opts, world, p, n, todo):
    """Contraction (if on, where lines 10-14 run: ``opts.repairs``) and the feasibility check
    of the rows ``todo`` (one jitted call on :data:`CHECK_ROWS` paths at a time).

    Returns ``(p, n, feasible, blocked)``.
    """
    return _contract_and_check(robot, world, opts, p, n, todo, opts.repairs and opts.contract)


def cost_core(robot, p, n):
    """``(N,)`` cost of the paths ``p[:n]`` in the robot's metric (0 for a single state)."""
    num, length, d = p.shape
    seg_cost = jax.vmap(robot.distance, in_axes=(1, 1))(
        p[:, :-1].reshape(-1, d).T, p[:, 1:].reshape(-1, d).T
    ).reshape(num, length - 1)
    seg = jnp.arange(length - 1)[None, :] < (n - 1)[:, None]
    return jnp.sum(jnp.where(seg, seg_cost, 0.0), axis=1)


# ---------------------------------------------------------------------------
# Compiled stages (bounded cache) and their timed runner
# ---------------------------------------------------------------------------

_JITS = {
    "coarse": jax.jit(coarse_core, static_argnames=("robot", "opts")),
    "coarse_plan": jax.jit(coarse_plan_core, static_argnames=("robot", "opts")),
    "valid": jax.jit(valid_core, static_argnames=("robot", "opts")),
    "connect": jax.jit(connect_core, static_argnames=("robot", "opts")),
    "check": jax.jit(check_core, static_argnames=("robot", "opts")),
}
cost_jit = jax.jit(cost_core, static_argnames=("robot",))
_COMPILED: collections.OrderedDict = collections.OrderedDict()  # LRU of COMPILED_CACHE_SIZE


def _signature(name, args) -> tuple:
    robot, opts = args[:2]
    leaves, tree = jax.tree_util.tree_flatten(args[2:])
    return (
        name,
        robot,
        opts,
        tree,
        tuple((x.shape, str(x.dtype)) for x in map(jnp.asarray, leaves)),
    )


def _compiled(name, args):
    """The compiled stage ``name`` for these static settings and shapes (bounded LRU cache)."""
    sig = _signature(name, args)
    fn = _COMPILED.pop(sig, None)
    if fn is None:
        fn = _JITS[name].lower(*args).compile()
    _COMPILED[sig] = fn
    while len(_COMPILED) > COMPILED_CACHE_SIZE:
        _COMPILED.popitem(last=False)
    return fn


class Stages:
    """The compiled stages for one robot, options, world and PNet, timed.

    ``stages(name, *args)`` runs stage ``name`` (``"coarse"``, ``"valid"``,
    ``"connect"``, ``"check"``; see the ``*_core`` functions) on ``args`` (what
    follows ``robot, opts, world``) and returns host arrays; ``run`` and
    ``compile`` accumulate the seconds spent running and compiling.

    For a robot whose ``shared_check_programs`` is True the checks run on the host
    through the shared batched programs (:mod:`ntq_jax.neural.host_stages`: the
    ``"valid"`` and ``"check"`` stages, and the validity of the ends before the coarse
    plan, :func:`coarse_plan_core`), with the same answers; their time counts as run time.
    ``on_host`` says whether they do (set it False to run the fused stages instead, e.g.
    to compare the two).
    """

    def __init__(self, robot, opts, world, pnet):
        self.robot, self.opts, self.world, self.pnet = robot, opts, world, pnet
        self.run = 0.0
        self.compile = 0.0
        self.on_host = bool(getattr(robot, "shared_check_programs", False))

    def __call__(self, name: str, *args) -> list[np.ndarray]:
        if not self.on_host or name == "connect":
            return self._jitted(name, args)
        opts = self.opts.for_stage(name)
        t0 = time.perf_counter()
        if name == "coarse":
            pnet, key, starts, goals, active = args
            valid = host_stages.ends_valid(self.robot, opts, self.world, starts, goals, active)
            self.run += time.perf_counter() - t0
            return self._jitted("coarse_plan", (pnet, key, starts, goals, jnp.asarray(valid)))
        host = {"valid": host_stages.valid_host, "check": host_stages.check_host}[name]
        out = host(self.robot, opts, self.world, *args)
        self.run += time.perf_counter() - t0
        return out

    def _jitted(self, name: str, args: tuple) -> list[np.ndarray]:
        """Stage ``name``'s compiled program on ``args``, timed."""
        args = (self.robot, self.opts.for_stage(name), self.world) + args
        t0 = time.perf_counter()
        fn = _compiled(name, args)
        t1 = time.perf_counter()
        out = jax.block_until_ready(fn(*args[2:]))
        self.compile += t1 - t0
        self.run += time.perf_counter() - t1
        return [np.asarray(o) for o in out]
