"""OMPL in this process on the package's own JAX checks: ``"rrtconnect"`` and ``"bitstar_jax"``.

The in-CI peers of the package's own planners on robots whose geometry exists only in
JAX (the Panda): OMPL's planners (PyPI ``ompl`` 2.x), run in this process by
:class:`ntq_jax.planners.ompl_worker.OmplProblem` (the bridge's problem class), with

* a state validity checker calling the package's ``robot.is_valid`` and
* a motion validator calling the package's discretised ``robot.steer_to`` (states
  ``resolution`` apart, in the travelled direction: OMPL's motions are checked exactly
  like the package's),

both through :class:`ntq_jax.planners.ompl_checker_jax.JaxChecker` (one compiled call
per callback). Two planners share that route (:func:`_plan_in_process`):

* :func:`plan_rrtconnect` (``"rrtconnect"``): RRT-Connect returns at its first
  solution; with ``simplify`` the path then goes through
  ``PathSimplifier.simplifyMax`` (vertex reduction, shortcutting, B-spline smoothing),
  whose every new motion is checked the same way. Not anytime: no solution within
  ``time_budget`` is a TIMEOUT.
* :func:`plan_bitstar_jax` (``"bitstar_jax"``): OMPL's BIT* with its default
  parameters (the paper's data planner; the paper gives only the time budget), the
  same problem as the ``"bitstar"`` bridge's workers solve, but on the JAX checks.
  Anytime: it uses the whole budget (unless ``stop_on_first``); no solution within it
  is a TIMEOUT. ``"bitstar"`` on a 3-D serial arm (which has no NumPy checker for the
  bridge's worker processes) is this planner
  (:func:`ntq_jax.planners.ompl_bridge.plan_bitstar` hands it over), so a config
  naming ``bitstar`` runs on the Panda; on the planar robots ``"bitstar"`` is the
  bridge, unchanged.

Each path is verified by :func:`ntq_jax.planners.verify.finalize` with ``check`` (e.g.
the certified check, which OMPL's discretised motions need not pass).

Cost of the route: every callback is one compiled JAX call (on the Panda, inside BIT*:
~57 us a state, ~270 us a motion, against a few us of a native checker), so in a given
budget OMPL explores fewer states and motions than it would with a native checker. For
BIT* at 6 s on the Panda the callbacks take 19 % of the budget (BIT*'s own search the
rest): ~11,500 states and ~1,500 motions checked per query, at most ~1.2x that with
free checks (``results/data_paths/README.md``, "The Panda"). ``info`` counts the
callbacks per query (``n_valid_per_query``, ``n_motion_per_query``).

Queries run one after another in this process (OMPL's callbacks hold the GIL); query
``i`` re-seeds OMPL with ``query_seeds(seed, K)[i]``
(:func:`ntq_jax.planners.ompl_bridge.query_seeds`), so results do not depend on the
batch.
"""

from __future__ import annotations

import importlib.util
import time

import numpy as np

from ntq_jax.planners.ompl_bridge import PLAN_STATUS, query_seeds
from ntq_jax.planners.ompl_checker_jax import JaxChecker
from ntq_jax.planners.ompl_worker import LOG_LEVELS, BridgeOutcome, OmplProblem
from ntq_jax.planners.options import bool_option, float_option, motion_check_option
from ntq_jax.planners.verify import finalize, valid_queries
from ntq_jax.types import PlanResult

__all__ = ["plan_rrtconnect", "plan_bitstar_jax", "ARM_RANGE"]

#: RRT-Connect's range for a 3-D serial arm: 1 rad, VAMP's for the Panda
#: (``vamp.ROBOT_RRT_RANGES``), so the two RRT-Connects extend alike.
ARM_RANGE = 1.0


def plan_rrtconnect(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    time_budget: float = 10.0,
    simplify: bool = True,
    range_: float | None = None,
    check: str = "discretized",
    ompl_log_level: str = "error",
) -> PlanResult:
    """Plans each query with OMPL's RRT-Connect (+ simplification) on the package's checks.

    Args:
        env: the environment (point robot, n-link arm or serial arm).
        queries: ``(K, 2, d)`` (start, goal) states.
        padding: planning clearance (None: the environment's).
        seed: base seed; query ``i`` uses ``query_seeds(seed, K)[i]``.
        time_budget: seconds of RRT-Connect per query.
        simplify: simplify each path with ``PathSimplifier.simplifyMax``.
        range_: RRT-Connect's longest extension (None: :data:`ARM_RANGE` for a serial
            arm, OMPL's default otherwise).
        check: the motion check of the final verification.
        ompl_log_level: OMPL's log level.

    Returns:
        A verified :class:`PlanResult`. ``info``: ``solve_times`` and
        ``simplify_times`` ``(K,)`` seconds, ``planner_costs`` ``(K,)`` OMPL's own path
        lengths, ``ompl_status`` ``(K,)`` int8 :class:`BridgeOutcome`, ``n_valid_calls``
        and ``n_motion_calls`` (callbacks, summed), ``n_valid_per_query`` and
        ``n_motion_per_query`` ``(K,)`` int64, ``setup_time`` (compiling the
        checker, before any query's budget starts), ``rejected`` (paths that failed ``check``).

    Raises:
        ImportError: ``ompl`` is not installed; ValueError: a rigid body (use
            ``"bitstar"``) or a bad option.
    """
    time_budget = float_option("rrtconnect", "time_budget", time_budget)
    simplify = bool_option("rrtconnect", "simplify", simplify)
    range_ = float_option("rrtconnect", "range_", range_, none_ok=True)
    if range_ is None and env.robot.kind == "serial_arm":
        range_ = ARM_RANGE
    info = {
        "planner": "rrtconnect",
        "range": range_,
        "simplify": simplify,
        "time_budget": time_budget,
    }
    return _plan_in_process(
        env,
        queries,
        padding,
        seed,
        check,
        ompl_log_level,
        info,
        {"planner": "rrtconnect", "simplify": simplify, "range_": range_},
    )


def plan_bitstar_jax(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    time_budget: float = 1.0,
    stop_on_first: bool = False,
    check: str = "discretized",
    ompl_log_level: str = "error",
) -> PlanResult:
    """Plans each query with OMPL's BIT* (default parameters) on the package's JAX checks.

    Args:
        env: the environment (point robot, n-link arm or serial arm).
        queries: ``(K, 2, d)`` (start, goal) states.
        padding: planning clearance (None: the environment's).
        seed: base seed; query ``i`` uses ``query_seeds(seed, K)[i]``.
        time_budget: seconds of BIT* per query (the paper's data generation: 6 s for
            its 6-link arm, its largest).
        stop_on_first: return at BIT*'s first solution instead of using the whole budget.
        check: the motion check of the final verification.
        ompl_log_level: OMPL's log level.

    Returns:
        A verified :class:`PlanResult`; ``info`` as :func:`plan_rrtconnect`'s
        (``simplify_times`` all 0), with ``stop_on_first``.

    Raises:
        ImportError: ``ompl`` is not installed; ValueError: a rigid body (use
            ``"bitstar"``) or a bad option.
    """
    time_budget = float_option("bitstar_jax", "time_budget", time_budget)
    stop_on_first = bool_option("bitstar_jax", "stop_on_first", stop_on_first)
    info = {"planner": "bitstar_jax", "stop_on_first": stop_on_first, "time_budget": time_budget}
    return _plan_in_process(
        env,
        queries,
        padding,
        seed,
        check,
        ompl_log_level,
        info,
        {"planner": "bitstar", "stop_on_first": stop_on_first},
    )


def _plan_in_process(
    env, queries, padding, seed, check, ompl_log_level, info: dict, problem_options: dict
) -> PlanResult:
    """The shared route: each valid query solved by one in-process :class:`OmplProblem`
    (``problem_options``: its planner and settings) on a :class:`JaxChecker`, then
    verified; ``info`` (the planner's own entries) is completed and returned in the result."""
    name = info["planner"]
    check = motion_check_option(name, check)
    if ompl_log_level not in LOG_LEVELS:
        raise ValueError(
            f"{name}: ompl_log_level must be one of {LOG_LEVELS}, got {ompl_log_level!r}"
        )
    if importlib.util.find_spec("ompl") is None:
        raise ImportError(f"{name} needs OMPL's Python bindings: pip install 'ompl>=2.0.1'")
    pad = env.resolve_padding(padding)
    q = np.asarray(queries, np.float32)
    nq, d = q.shape[0], q.shape[2]
    t0 = time.perf_counter()
    outcome = np.full(nq, BridgeOutcome.NOT_FOUND, np.int8)
    ok = valid_queries(env, q, pad)
    outcome[~ok] = BridgeOutcome.BAD_QUERY
    paths = np.full((nq, 2, d), np.nan, np.float32)
    lengths = np.zeros(nq, np.int32)
    solve_t, simp_t, own = np.zeros(nq), np.zeros(nq), np.full(nq, np.inf)
    n_valid, n_motion = np.zeros(nq, np.int64), np.zeros(nq, np.int64)
    info.update(setup_time=0.0)
    if ok.any():
        checker = JaxChecker(env, pad)
        checker.compile(q[np.flatnonzero(ok)[0], 0])  # not in the first query's budget
        problem = OmplProblem(
            checker, info["time_budget"], log_level=ompl_log_level, **problem_options
        )
        info["setup_time"] = time.perf_counter() - t0
        seeds = query_seeds(seed, nq)
        found = {}
        for i in np.flatnonzero(ok):
            r = problem.solve(q[i, 0], q[i, 1], int(seeds[i]))
            outcome[i] = r["outcome"]
            solve_t[i], simp_t[i], own[i] = r["solve_time"], r["simplify_time"], r["planner_cost"]
            n_valid[i], n_motion[i] = r["n_valid"], r["n_motion"]
            if r["path"] is not None:
                found[int(i)] = r["path"]
        if found:
            width = max(len(p) for p in found.values())
            paths = np.full((nq, width, d), np.nan, np.float32)
            for i, p in found.items():
                paths[i, : len(p)], lengths[i] = p, len(p)
    status = np.array([PLAN_STATUS[BridgeOutcome(o)] for o in outcome], np.int8)
    info.update(
        ompl_status=outcome,
        solve_times=solve_t,
        simplify_times=simp_t,
        planner_costs=own,
        n_valid_calls=int(n_valid.sum()),
        n_motion_calls=int(n_motion.sum()),
        n_valid_per_query=n_valid,
        n_motion_per_query=n_motion,
    )
    res = finalize(q, paths, lengths, status, info, env, pad, check)
    info["time"] = time.perf_counter() - t0
    return res
