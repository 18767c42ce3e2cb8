"""OMPL's RRT-Connect on the package's own JAX checks: :func:`plan_rrtconnect`, the ``"rrtconnect"`` planner.

The in-CI peer of the package's own planners on robots whose geometry exists only in
JAX (the Panda): OMPL's RRT-Connect and path simplifier (PyPI ``ompl`` 2.x), run in
this process by :class:`ntq_jax.planners.ompl_worker.OmplProblem` (the bridge's
problem class, with ``planner="rrtconnect"``), with

* a state validity checker calling the package's ``robot.is_valid`` and
* a motion validator calling the package's discretised ``robot.steer_to`` (states
  ``resolution`` apart, in the travelled direction: OMPL's motions are checked exactly
  like the package's),

both through :class:`ntq_jax.planners.ompl_checker_jax.JaxChecker` (one compiled call
per callback). RRT-Connect returns at its first solution; with ``simplify`` the path
then goes through ``PathSimplifier.simplifyMax`` (vertex reduction, shortcutting,
B-spline smoothing), whose every new motion is checked the same way. Each path is
verified by :func:`ntq_jax.planners.verify.finalize` with ``check`` (e.g. the
certified check, which OMPL's discretised motions need not pass).

Queries run one after another in this process (OMPL's callbacks hold the GIL); query
``i`` re-seeds OMPL with ``query_seeds(seed, K)[i]``
(:func:`ntq_jax.planners.ompl_bridge.query_seeds`), so results do not depend on the
batch. RRT-Connect is not anytime: no solution within ``time_budget`` is a TIMEOUT.
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

__all__ = ["plan_rrtconnect", "ARM_RANGE"]

#: RRT-Connect's range for a 3-D serial arm: 1 rad, VAMP's for the Panda
#: (``vamp.ROBOT_RRT_RANGES``), so the two RRT-Connects extend alike.
ARM_RANGE = 1.0


def plan_rrtconnect(env, queries, *, padding: float | None = None, seed: int = 0,
                    time_budget: float = 10.0, simplify: bool = True,
                    range_: float | None = None, check: str = "discretized",
                    ompl_log_level: str = "error") -> PlanResult:
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
        and ``n_motion_calls`` (callbacks, summed), ``setup_time`` (compiling the
        checker), ``rejected`` (paths that failed ``check``).

    Raises:
        ImportError: ``ompl`` is not installed; ValueError: a rigid body (use
            ``"bitstar"``) or a bad option.
    """
    time_budget = float_option("rrtconnect", "time_budget", time_budget)
    simplify = bool_option("rrtconnect", "simplify", simplify)
    range_ = float_option("rrtconnect", "range_", range_, none_ok=True)
    check = motion_check_option("rrtconnect", check)
    if ompl_log_level not in LOG_LEVELS:
        raise ValueError(f"rrtconnect: ompl_log_level must be one of {LOG_LEVELS}, "
                         f"got {ompl_log_level!r}")
    if importlib.util.find_spec("ompl") is None:
        raise ImportError("plan_rrtconnect needs OMPL's Python bindings: pip install 'ompl>=2.0.1'")
    if range_ is None and env.robot.kind == "serial_arm":
        range_ = ARM_RANGE
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
    info = {"planner": "rrtconnect", "range": range_, "simplify": simplify,
            "time_budget": time_budget, "n_valid_calls": 0, "n_motion_calls": 0,
            "setup_time": 0.0}
    if ok.any():
        checker = JaxChecker(env, pad)
        problem = OmplProblem(checker, time_budget, planner="rrtconnect", simplify=simplify,
                              range_=range_, log_level=ompl_log_level)
        info["setup_time"] = time.perf_counter() - t0
        seeds = query_seeds(seed, nq)
        found = {}
        for i in np.flatnonzero(ok):
            r = problem.solve(q[i, 0], q[i, 1], int(seeds[i]))
            outcome[i] = r["outcome"]
            solve_t[i], simp_t[i], own[i] = r["solve_time"], r["simplify_time"], r["planner_cost"]
            info["n_valid_calls"] += r["n_valid"]
            info["n_motion_calls"] += r["n_motion"]
            if r["path"] is not None:
                found[int(i)] = r["path"]
        if found:
            width = max(len(p) for p in found.values())
            paths = np.full((nq, width, d), np.nan, np.float32)
            for i, p in found.items():
                paths[i, :len(p)], lengths[i] = p, len(p)
    status = np.array([PLAN_STATUS[BridgeOutcome(o)] for o in outcome], np.int8)
    info.update(ompl_status=outcome, solve_times=solve_t, simplify_times=simp_t,
                planner_costs=own)
    res = finalize(q, paths, lengths, status, info, env, pad, check)
    info["time"] = time.perf_counter() - t0
    return res
