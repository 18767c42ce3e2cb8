"""The neural planner of the paper (Alg. 1, after MPNet), batched over queries.

Contract: :func:`plan_batch` plans ``queries`` ``(K, 2, d)`` in an
:class:`ntq_jax.Env` with a planning network
``pnet(key, current (N, d), goal (N, d)) -> next (N, d)`` (pure and jittable;
``key`` drives dropout, MPNet's source of randomness) and returns a
:class:`NeuralPlanResult`: per query a NaN-padded path, its cost in the robot's
metric and a :class:`ntq_jax.types.PlanCause` (names in
:data:`ntq_jax.types.CAUSE_NAMES`):

* ``SUCCESS``: the path runs from the start to the goal (without steerTo: to
  within ``delta`` of it in the robot's metric) and every segment passes
  ``steer_to`` on the evaluation geometry (``eval_padding``);
* ``NO_PATH``: the goal was not reached within ``n_plan`` PNet steps (Alg. 1's
  empty path);
* ``INFEASIBLE``: reached, but still in collision after replanning;
* ``INVALID_QUERY``: start or goal is not a valid state on the evaluation
  geometry, or not finite.

**The ensemble planner.** ``pnet`` may also be a sequence of PNets (e.g.
:func:`ntq_jax.models.member_pnets` of a trained ensemble): wherever the
planner asks for a next state (every coarse-plan step, every step of a
bidirectional connection, so also neural replanning) every member predicts
from the same key, current state and target, in one jitted call, and
:func:`ntq_jax.neural.proposals.choose` picks one by a fixed rule: a candidate
whose steerTo to the target is free first (the cheapest path ``current ->
candidate -> target`` among them, those also reachable from the current state
first), else the one that most reduces the remaining cost-to-go in the
robot's metric among those reachable from the current state by a free
steerTo, else the lowest cost-to-go; ties go to the first member. Everything
else (contraction, feasibility check, replanning rounds, costs) is the single
planner's. With identical members (same function and parameters) every
candidate is the same and the ensemble planner returns exactly the single
member's result, except that ``pnet_calls`` counts every member's prediction.

The result is deterministic given the key. One implementation serves every
robot: it only uses the robot's kernels (:mod:`ntq_jax.robots.batch`) and the
package's path shortcutting (:mod:`ntq_jax.planners.smoothing`). The
algorithm (coarse plan, lazy states contraction, feasibility check, neural
replanning; the variant without steerTo) is described step by step in
:func:`plan_batch`; its jitted steps are in :mod:`ntq_jax.neural.steps`, this
module and :mod:`ntq_jax.neural.repair` (neural replanning's windows and splices, the
per-query state of a batch) drive them over chunks of queries (throughput:
``benchmarks/bench_plan.py``).
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial

from ntq_jax.batching import bucket_size, group_chunks, pad_rows
from ntq_jax.geometry import World
from ntq_jax.neural.options import NeuralPlanResult, PlannerOptions
from ntq_jax.neural.proposals import EnsemblePNet, MemberBlocks, fold_in, is_key_stack, split2
from ntq_jax.neural.repair import _Batch, _recheck, _replan_round
from ntq_jax.neural.steps import Stages, cost_jit
from ntq_jax.types import CAUSE_RANK, PlanCause
from ntq_jax.validation import check_count

Array = jax.Array


# ---------------------------------------------------------------------------
# The stages of plan_batch
# ---------------------------------------------------------------------------


def _coarse(stages: Stages, b: _Batch, q: np.ndarray, key, size: int) -> None:
    """Steps 1-3 (coarse plan, contraction, feasibility) of every query: the coarse plans in
    chunks of ``size`` (per member: ``size`` rows of each member side by side), then the
    paths that reached their goal contracted and checked (:func:`_recheck`)."""
    k = len(q)
    for lo, idx, act in group_chunks([np.arange(k)] * b.members, size):
        rows = idx + np.repeat(np.arange(b.members) * k, size)
        out = stages(
            "coarse",
            stages.pnet,
            fold_in(key, lo // size),
            jnp.asarray(q[idx, 0]),
            jnp.asarray(q[idx, 1]),
            jnp.asarray(act),
        )
        for dst, src in zip((b.paths, b.lengths, b.valid, b.reached, b.calls), out):
            dst[rows[act]] = src[act]
    _recheck(stages, b, np.flatnonzero(b.reached))


def _costs(robot, b: _Batch, success: np.ndarray) -> np.ndarray:
    """``(K,)`` float64 cost of the successful paths, inf elsewhere."""
    costs = np.full(len(success), np.inf)
    ok = np.flatnonzero(success)
    if len(ok):
        sel = pad_rows(ok, bucket_size(len(ok)))
        costs[ok] = np.asarray(
            cost_jit(robot, jnp.asarray(b.paths[sel]), jnp.asarray(b.lengths[sel]))
        )[: len(ok)]
    return costs


# ---------------------------------------------------------------------------
# Public entry points
# ---------------------------------------------------------------------------


def as_pnet(pnet) -> Partial | EnsemblePNet:
    """Wraps a ``pnet(key, current, goal)`` callable as a pytree for the jitted planner.

    A :class:`jax.tree_util.Partial` is passed through unchanged (its bound
    arguments, e.g. the parameters, are traced; only the function is part of the
    compile key), so build PNets as ``Partial(apply_fn, params)`` to share one
    compilation across ensemble members. A list or tuple of PNets becomes an
    :class:`ntq_jax.neural.proposals.EnsemblePNet` (the ensemble planner; one PNet
    alone is that PNet).

    Raises:
        ValueError: an empty sequence.
    """
    if isinstance(pnet, EnsemblePNet):
        return pnet
    if isinstance(pnet, (list, tuple)):
        if not pnet:
            raise ValueError("the ensemble planner needs at least one PNet")
        members = tuple(as_pnet(p) for p in pnet)
        return members[0] if len(members) == 1 else EnsemblePNet(members)
    return pnet if isinstance(pnet, Partial) else Partial(pnet)


def padded_world(world: World, multiple: int = 16) -> World:
    """``world`` with its box and disc lists padded to a multiple of ``multiple``.

    The extra obstacles are tiny and far outside any workspace (at ``1e6``), so
    no state or motion inside the bounds can touch them; maps with similar
    obstacle counts then share one compilation of the planner. The kernels
    unroll over obstacles, so padding also lengthens every compilation: worth it
    only when many maps share one obstacle-count bucket.
    """

    def pad(a, row):
        n = a.shape[0]
        m = max(multiple, -(-n // multiple) * multiple)
        extra = jnp.tile(jnp.asarray(row, a.dtype)[None], (m - n, 1))
        return jnp.concatenate([a, extra]) if m > n else a

    # a broad-phase index stays valid: it holds its own copies of the real boxes
    return World(
        world.bounds,
        pad(world.boxes, [1e6, 1e6, 1.0, 1.0]),
        pad(world.discs, [1e6, 1e6, 1.0]),
        world.index,
    )


def plan_batch(
    env,
    pnet: Callable,
    queries,
    key: Array,
    opts: PlannerOptions = PlannerOptions(),
    *,
    chunk: int = 1024,
    repair_width: int = 256,
    pad_obstacles: int = 0,
    rows: int | None = None,
) -> NeuralPlanResult:
    """Plans every query with the neural planner (all of a chunk in one jitted call).

    1. **Coarse plan** (Alg. 1, lines 2-9): for ``n_plan`` iterations, if
       ``steerTo(pi_end, goal)`` append the goal and stop, else append
       ``PNet(pi_end, goal)``. With ``bidirectional`` (MPNet's variant) two paths
       grow alternately from the start and from the goal, each predicting towards
       the other's end, until their ends connect (``n_plan`` predictions in all).
       **Without steerTo** (``steer=False``, Section V): only PNet steps, stopping
       once ``distance(pi_end, goal) <= delta`` in the robot's metric (the start
       is tested first); the goal is not appended, so the path ends within
       ``delta`` of it and its cost is that of its own segments. A start already
       within ``delta`` is reached with a path of one state (no segment, cost 0).
       No contraction and no replanning (both need the steering function),
       except with ``nosteer_check="replan"``: the goal is appended once the
       test passes and steps 2-4 run as with steerTo.
    2. **Lazy states contraction** (MPNet): from each kept state jump to the
       farthest later state it can ``steerTo``.
    3. **Feasibility** at ``eval_padding``: every segment checked by ``steer_to``.
    4. **Neural replanning** (MPNet), at most ``replan_rounds`` rounds on the
       infeasible paths only (:func:`_replan_round`): each blocked segment, widened
       to the nearest states not in collision, is reconnected by the bidirectional
       neural connection (at most ``replan_steps`` predictions), spliced in, and
       the path contracted and re-checked. Unlike MPNet, a failed connection
       leaves its segment as it was; the next round retries with new dropout masks.

    The planner's own ``steerTo`` calls use ``plan_padding``. With a sequence of
    PNets (the ensemble planner, see the module docstring) every prediction
    above is every member's, chosen by :func:`ntq_jax.neural.proposals.choose`.

    Args:
        env: a :class:`ntq_jax.Env` (any robot).
        pnet: ``pnet(key, current (N, d), goal (N, d)) -> next (N, d)`` (see :func:`as_pnet`),
            or a list/tuple of them for the ensemble planner.
        queries: ``(K, 2, d)`` start and goal states.
        key: PRNG key (dropout); the result is deterministic given the key.
        opts: :class:`PlannerOptions`.
        chunk: largest batch per jitted call (batches are padded to a power of two).
        repair_width: batch width of the replanning calls (rounded to a power of two).
        pad_obstacles: if > 0, pad the obstacle lists to a multiple of it
            (:func:`padded_world`) so maps with similar counts share one compilation.
        rows: plan with the compiled shapes of a batch of ``max(rows, K)`` queries
            (default ``K``; they also lay out the dropout masks): subsets of one batch
            planned with its size reuse its programs.

    Returns:
        A :class:`NeuralPlanResult` with paths trimmed to the longest one.

    Raises:
        ValueError: ``queries`` has the wrong shape, ``chunk < 1``, or the
            bidirectional planner without steerTo.
    """
    q = _check_inputs(env, queries, opts, chunk)
    world = padded_world(env.world, pad_obstacles) if pad_obstacles > 0 else env.world
    stages = Stages(env.robot, opts, world, as_pnet(pnet))
    rows = 0 if rows is None else check_count("rows", rows, 1)
    b = _plan(stages, q, key, chunk, repair_width, members=1, rows=rows)
    return _result(env.robot, b, stages, slice(None))


def plan_members(
    env,
    pnets,
    queries,
    key: Array,
    opts: PlannerOptions = PlannerOptions(),
    *,
    chunk: int = 1024,
    repair_width: int = 256,
) -> list[NeuralPlanResult]:
    """Every PNet of ``pnets`` plans every query on its own, all members in one batch.

    The result of member ``m`` is the one :func:`plan_batch` returns for
    ``pnets[m]`` with key ``key[m]`` (or ``key``, when one key is given for all):
    the members' rows are planned side by side (:class:`ntq_jax.neural.proposals.
    MemberBlocks`: each jitted call carries ``chunk`` rows of every member and
    each member predicts for its own rows), which only changes how the work is
    batched, not what is computed. This is what a best-of-N planner runs
    (:func:`ntq_jax.experiment.evaluate.best_of` then keeps each query's cheapest success).

    Args:
        env, queries, opts, chunk, repair_width: as in :func:`plan_batch`
            (``chunk`` and ``repair_width`` are rows per member).
        pnets: a sequence of ``M >= 1`` PNets (see :func:`as_pnet`; not ensemble planners).
        key: one PRNG key, or ``M`` keys stacked (one per member, e.g. the keys of
            the members' own evaluations).

    Returns:
        ``M`` :class:`NeuralPlanResult`, one per member. Each carries the wall and
        compile time of the whole batched call (all members together) in
        ``seconds`` and ``compile_seconds``.

    Raises:
        ValueError: as :func:`plan_batch`; no PNet; ``key`` a stack of the wrong length.
    """
    q = _check_inputs(env, queries, opts, chunk)
    members = tuple(as_pnet(p) for p in pnets)
    if not members or any(isinstance(p, EnsemblePNet) for p in members):
        raise ValueError("plan_members needs one or more PNets (not ensemble planners)")
    if is_key_stack(key) and key.shape[0] != len(members):
        raise ValueError(f"got {key.shape[0]} keys for {len(members)} PNets")
    stages = Stages(env.robot, opts, env.world, MemberBlocks(members))
    b = _plan(stages, q, key, chunk, repair_width, members=len(members))
    k = len(q)
    return [_result(env.robot, b, stages, slice(m * k, (m + 1) * k)) for m in range(len(members))]


def plan_cascade(
    env,
    pnets,
    queries,
    key: Array,
    opts: PlannerOptions = PlannerOptions(),
    *,
    order=None,
    chunk: int = 1024,
    repair_width: int = 256,
) -> NeuralPlanResult:
    """The PNets as fallbacks: the first plans every query, the next the queries still
    unsolved, and so on; each query keeps its first success.

    Attempt ``j`` is :func:`plan_batch` with ``pnets[order[j]]``, key
    ``fold_in(key, j)`` and ``rows=K`` on the queries no earlier attempt solved (the
    shapes of all ``K``: the member's own programs, nothing more compiles). A query
    succeeds iff one of its attempts succeeds; its path, cost and cause are that
    attempt's. A query no attempt solves keeps the failure closest to a success
    (:data:`ntq_jax.types.CAUSE_RANK`; ties: the earliest attempt). The work
    falls with every solved query, so the cascade costs one member's planning
    plus the fallbacks' on the failures, against ``M`` members' for best-of-M
    (:func:`ntq_jax.experiment.evaluate.best_of`), and reaches the same successes (any
    member's) at the cost of the first member that solves a query instead of
    the cheapest. Order the members best first (e.g. by success on validation
    queries, as :func:`ntq_jax.experiment.evaluate.evaluate_env` does).

    Args:
        env, queries, key, opts, chunk, repair_width: as in :func:`plan_batch`.
        pnets: ``M >= 1`` PNets (see :func:`as_pnet`).
        order: the member order (a permutation of ``range(M)``, or a prefix of
            one); default ``0..M-1``.

    Returns:
        A :class:`NeuralPlanResult` with ``member`` set; ``pnet_calls``,
        ``replans``, ``seconds`` and ``compile_seconds`` are summed over the attempts.

    Raises:
        ValueError: as :func:`plan_batch`; no PNet; ``order`` not distinct member indices.
    """
    q = _check_inputs(env, queries, opts, chunk)
    order = list(range(len(pnets)) if order is None else order)
    if not order or len(set(order)) != len(order) or not all(0 <= m < len(pnets) for m in order):
        raise ValueError(
            f"order must list distinct member indices of 0..{len(pnets) - 1}, got {order}"
        )
    k = len(q)
    paths = np.full((k, opts.max_len, env.dim), np.nan, np.float32)
    lengths = np.zeros(k, np.int32)
    costs = np.full(k, np.inf)
    cause = np.full(k, PlanCause.INVALID_QUERY, np.int8)
    rank = np.full(k, len(CAUSE_RANK))
    calls = np.zeros(k, np.int32)
    replans = np.zeros(k, np.int32)
    member = np.zeros(k, np.int8)
    seconds = compile_seconds = 0.0
    left = np.arange(k)
    for j, m in enumerate(order):
        if not len(left):
            break
        res = plan_batch(
            env,
            pnets[m],
            q[left],
            fold_in(key, j),
            opts,
            chunk=chunk,
            repair_width=repair_width,
            rows=k,
        )
        seconds, compile_seconds = seconds + res.seconds, compile_seconds + res.compile_seconds
        calls[left] += res.pnet_calls
        replans[left] += res.replans
        r = np.array([CAUSE_RANK[PlanCause(int(c))] for c in res.cause])
        better = r < rank[left]
        rows = left[better]
        paths[rows] = np.nan
        paths[rows, : res.paths.shape[1]] = res.paths[better]
        lengths[rows], costs[rows] = res.lengths[better], res.costs[better]
        cause[rows], rank[rows], member[rows] = res.cause[better], r[better], m
        left = left[~res.success]
    success = cause == PlanCause.SUCCESS
    top = max(1, int(lengths.max(initial=0)))
    return NeuralPlanResult(
        paths[:, :top],
        lengths,
        success,
        costs,
        cause,
        calls,
        replans,
        seconds,
        compile_seconds,
        member,
    )


def _check_inputs(env, queries, opts: PlannerOptions, chunk: int) -> np.ndarray:
    q = np.asarray(queries, np.float32)
    if q.ndim != 3 or q.shape[1:] != (2, env.dim):
        raise ValueError(f"queries must have shape (K, 2, {env.dim}), got {q.shape}")
    if opts.bidirectional and not opts.steer:
        raise ValueError("the bidirectional planner needs steerTo (steer=True)")
    check_count("chunk", chunk, 1)
    return q


def _plan(
    stages: Stages, q: np.ndarray, key, chunk: int, repair_width: int, members: int, rows: int = 0
) -> _Batch:
    """Steps 1-4 of :func:`plan_batch` for ``members`` planners side by side, with the
    compiled shapes of ``max(len(q), rows)`` queries."""
    opts = stages.opts
    size = bucket_size(min(max(len(q), rows), chunk))
    width = bucket_size(min(repair_width, size))
    b = _Batch.empty(members * len(q), opts.max_len, q.shape[2], members)
    k_coarse, k_rep = split2(key)
    _coarse(stages, b, q, k_coarse, size)
    for r in range(opts.replan_rounds if opts.repairs else 0):
        todo = np.flatnonzero(b.reached & ~b.feasible)
        if not len(todo):
            break
        _replan_round(stages, b, todo, fold_in(k_rep, r), width)
    return b


def _result(robot, b: _Batch, stages: Stages, rows: slice) -> NeuralPlanResult:
    """The :class:`NeuralPlanResult` of the batch rows ``rows`` (trimmed to their longest path)."""
    success = (b.reached & b.feasible)[rows]
    lengths = b.lengths[rows]
    top = max(1, int(lengths.max(initial=0)))
    sub = _Batch(
        b.paths[rows],
        lengths,
        b.valid[rows],
        b.reached[rows],
        b.feasible[rows],
        b.blocked[rows],
        b.calls[rows],
        b.replans[rows],
    )
    return NeuralPlanResult(
        sub.paths[:, :top],
        lengths,
        success,
        _costs(robot, sub, success),
        sub.cause(),
        sub.calls,
        sub.replans,
        stages.run,
        stages.compile,
    )
