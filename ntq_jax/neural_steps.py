"""The jitted steps of the neural planner (:mod:`ntq_jax.neural_planner`).

Every function here runs inside ``jax.jit`` on row-major ``(N, ...)`` arrays of
fixed shape, with per-row masks: the coarse plan of a batch of queries with its
contraction and feasibility check (:func:`coarse_core`), the validity of path
states (:func:`valid_core`), the bidirectional neural connection of a batch of
windows (:func:`connect_core`), the contraction and re-check of repaired paths
(:func:`check_core`) and the costs of the successful paths (:data:`cost_jit`,
float32 in the robot's metric). Wherever a step asks the PNet for a next state
it goes through :func:`propose`: one PNet's prediction, or, for an
:class:`EnsemblePNet`, every member's prediction and the :func:`choose` rule. The stages take
``(robot, opts, world, ...)``:
the robot and ``opts`` (a :class:`ntq_jax.neural_planner.PlannerOptions`, whose
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
from jax.tree_util import Partial

from ntq_jax.neural_motions import segments as _segments
from ntq_jax.neural_motions import steer as _steer
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
# The ensemble planner's proposals
# ---------------------------------------------------------------------------


@jax.tree_util.register_pytree_node_class
class EnsemblePNet:
    """Several PNets planning together (the ensemble planner; a pytree of its members).

    Each member is a ``pnet(key, current, goal)`` (e.g. a
    :class:`jax.tree_util.Partial`); at every step where the planner asks for a
    next state, every member predicts from the same ``(key, current, goal)``
    (each member's own dropout stream comes from its function, e.g.
    :func:`ntq_jax.models.member_pnets` folds in the member index, as in the
    members' own evaluation) and :func:`choose` picks one of the predictions.
    The members are called in a Python loop inside the jitted step: one
    compiled call predicts for every member and every query of a batch.
    """

    def __init__(self, members):
        self.members = tuple(members)

    def __len__(self) -> int:
        return len(self.members)

    def tree_flatten(self):
        return self.members, None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children)


@jax.tree_util.register_pytree_node_class
class MemberBlocks:
    """Several PNets planning side by side in one batch, each on its own block of rows.

    Called as ``pnet(key, current (M*W, d), goal (M*W, d))``: the rows are ``M``
    blocks of ``W`` (member-major), member ``m`` predicts for block ``m`` only
    (``M`` predictions of ``W`` rows: the members' work, not ``M`` times it), and
    the blocks are concatenated back. ``key`` is one key (every member gets it)
    or ``M`` keys, one per member (:func:`fold_in` folds a stack of keys row by
    row). Each block sees exactly what the member sees when it plans alone on
    the same rows with that key, so :func:`ntq_jax.neural_planner.plan_members`
    reproduces the members' own plans (a pytree of its members, like
    :class:`EnsemblePNet`).
    """

    def __init__(self, members):
        self.members = tuple(members)

    def __len__(self) -> int:
        return len(self.members)

    def __call__(self, key, current: Array, goal: Array) -> Array:
        m = len(self.members)
        w = current.shape[0] // m
        batched = is_key_stack(key)
        stacked = _stacked_partials(self.members)
        if stacked is not None:  # one function: vmapped over the members' bound arguments
            func, args = stacked
            keys = key if batched else jnp.broadcast_to(key, (m,) + key.shape)
            out = jax.vmap(lambda a, k, c, g: func(*a, k, c, g))(
                args, keys, current.reshape(m, w, -1), goal.reshape(m, w, -1)
            )
            return out.reshape(m * w, -1)
        return jnp.concatenate(
            [
                p(
                    key[i] if batched else key,
                    current[i * w : (i + 1) * w],
                    goal[i * w : (i + 1) * w],
                )
                for i, p in enumerate(self.members)
            ]
        )

    def tree_flatten(self):
        return self.members, None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children)


def _stacked_partials(members):
    """``(func, stacked args)`` when every member is a ``Partial`` of one function with
    arguments of one structure and shape (e.g. an ensemble's members), else None."""
    first = members[0]
    if not all(isinstance(p, Partial) and p.func is first.func and not p.keywords for p in members):
        return None
    trees = [jax.tree_util.tree_structure(p.args) for p in members]
    shapes = [[jnp.shape(x) for x in jax.tree_util.tree_leaves(p.args)] for p in members]
    if any(t != trees[0] for t in trees) or any(s != shapes[0] for s in shapes):
        return None
    return first.func, jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *[p.args for p in members])


def is_key_stack(key) -> bool:
    """True for a stack of PRNG keys (one per member), False for a single key (typed
    keys of shape ``()`` or raw ``uint32`` keys of shape ``(2,)``)."""
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    return key.ndim > (0 if typed else 1)


def fold_in(key, data) -> Array:
    """:func:`jax.random.fold_in` of one key, or of each key of a stack (:func:`is_key_stack`)."""
    if is_key_stack(key):
        return jax.vmap(jax.random.fold_in, in_axes=(0, None))(key, data)
    return jax.random.fold_in(key, data)


def split2(key) -> tuple[Array, Array]:
    """:func:`jax.random.split` into two, of one key or of each key of a stack."""
    if is_key_stack(key):
        ks = jax.vmap(jax.random.split)(key)
        return ks[:, 0], ks[:, 1]
    k0, k1 = jax.random.split(key)
    return k0, k1


def proposals_per_call(pnet) -> int:
    """PNet predictions per :func:`propose` call (the member count of an ensemble, else 1)."""
    return len(pnet) if isinstance(pnet, EnsemblePNet) else 1


def _count(mask: Array, k: int) -> Array:
    """``mask`` counted ``k`` times (the mask itself for ``k = 1``)."""
    return mask if k == 1 else mask.astype(jnp.int32) * k


def choose(
    robot,
    world,
    cands: Array,
    cur: Array,
    tgt: Array,
    live: Array,
    padding: float,
    steer: bool = True,
) -> Array:
    """The ensemble's rule: the index ``(N,)`` of the candidate to append, per row.

    ``cands (M, N, d)`` are the members' proposals from ``cur (N, d)`` towards
    ``tgt (N, d)`` (the goal of the coarse plan, or the other tree's end in a
    bidirectional connection and in neural replanning). With ``c`` a candidate,
    ``dist`` the robot's metric (``robot.distance``) and steerTo the planner's
    own (discretised) check at ``padding``, candidates are ranked by tier, then
    by a score, then by member index (the first member wins a tie):

    0. ``steerTo(c, tgt)`` and ``steerTo(cur, c)`` free (``cur -> c -> tgt`` is a
       free path): score ``dist(cur, c) + dist(c, tgt)``, the cheapest such path;
    1. ``steerTo(c, tgt)`` free only: same score;
    2. ``steerTo(cur, c)`` free only: score ``dist(c, tgt)``, the remaining
       cost-to-go (the candidate that reduces it most);
    3. the others: score ``dist(c, tgt)`` (the lowest cost-to-go).

    Without steerTo (``steer=False``, the paper's variant without the steering
    function) only the cost-to-go is used (every candidate in tier 3). A
    non-finite score counts as infinite. Rows not ``live`` are not checked
    (their choice is irrelevant). The rule is deterministic, so the ensemble
    planner stays deterministic given its key, and ``M`` identical candidates
    give candidate 0, the single member's prediction.
    """
    m, n, d = cands.shape
    flat = cands.reshape(m * n, d)
    tgt_m, cur_m = jnp.tile(tgt, (m, 1)), jnp.tile(cur, (m, 1))
    dist = jax.vmap(robot.distance)
    ctg = dist(flat, tgt_m).reshape(m, n)
    if steer:
        live_m = jnp.tile(live, m)
        to_tgt = _steer(robot, world, flat, tgt_m, padding, live_m).reshape(m, n)
        from_cur = _steer(robot, world, cur_m, flat, padding, live_m).reshape(m, n)
        tier = jnp.where(to_tgt, jnp.where(from_cur, 0, 1), jnp.where(from_cur, 2, 3))
        score = jnp.where(to_tgt, dist(cur_m, flat).reshape(m, n) + ctg, ctg)
    else:
        tier = jnp.zeros((m, n), jnp.int32)
        score = ctg
    score = jnp.where(jnp.isnan(score), jnp.inf, score)
    best = jnp.min(tier, axis=0)
    return jnp.argmin(jnp.where(tier == best[None], score, jnp.inf), axis=0)


def propose(
    robot, world, pnet, key, cur: Array, tgt: Array, live: Array, padding: float, steer: bool = True
) -> Array:
    """The next state ``(N, d)`` from ``cur`` towards ``tgt``: the PNet's prediction, or
    for an :class:`EnsemblePNet` every member's and the one :func:`choose` picks."""
    if not isinstance(pnet, EnsemblePNet):
        return pnet(key, cur, tgt)
    if len(pnet) == 1:
        return pnet.members[0](key, cur, tgt)
    cands = jnp.stack([p(key, cur, tgt) for p in pnet.members])
    idx = choose(robot, world, cands, cur, tgt, live, padding, steer)
    return jnp.take_along_axis(cands, idx[None, :, None], axis=0)[0]


# ---------------------------------------------------------------------------
# Building blocks (inside jit)
# ---------------------------------------------------------------------------


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
            p, n = p.at[rows, jnp.where(last, n, length)].set(goals, mode="drop"), n + last
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
    feasible = mask & (n >= 1)
    if opts.steer or opts.nosteer_check not in (False, "states"):
        feasible = feasible & ~jnp.any(blocked, axis=1)
    elif opts.nosteer_check == "states":  # the waypoints only
        (ok,) = valid_core(robot, opts, world, p, n)
        feasible = feasible & jnp.all(ok | (jnp.arange(p.shape[1])[None, :] >= n[:, None]), axis=1)
    return p, n, feasible, blocked  # nosteer_check False: the paper's variant, unchecked


# ---------------------------------------------------------------------------
# The stages (one jitted call each)
# ---------------------------------------------------------------------------


def coarse_core(robot, opts, world, pnet, key, starts, goals, active):
    """Coarse plan of a batch (one jitted call): ``(p, n, valid, reached, calls)``.

    Its contraction and feasibility check are :func:`check_core`'s, a separate
    stage of a fixed shape (:data:`CHECK_ROWS` paths) compiled once per process.
    """
    length = opts.max_len
    valid = (
        active
        & is_valid_cm(robot, world, starts.T, opts.eval_padding)
        & is_valid_cm(robot, world, goals.T, opts.eval_padding)
    )
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
    """

    def __init__(self, robot, opts, world, pnet):
        self.robot, self.opts, self.world, self.pnet = robot, opts, world, pnet
        self.run = 0.0
        self.compile = 0.0

    def __call__(self, name: str, *args) -> list[np.ndarray]:
        args = (self.robot, self.opts.for_stage(name), self.world) + args
        t0 = time.perf_counter()
        fn = _compiled(name, args)
        t1 = time.perf_counter()
        out = jax.block_until_ready(fn(*args[2:]))
        self.compile += t1 - t0
        self.run += time.perf_counter() - t1
        return [np.asarray(o) for o in out]
