"""Metrics of a neural planner's results on test queries, and an independent re-check of its paths.

Pure functions over the arrays of a paths file (:mod:`ntq_jax.experiment.evaluate`):

* :func:`metrics`: success ratio with its 95 % Wilson interval, cost ratios
  against the reference (and the optimum) over the queries both solve, failures
  by cause;
* :func:`best_of`: per query the cheapest successful path among several models;
* :func:`in_band` and :func:`band_metrics`: the success of the test queries whose
  endpoints are valid at the training padding, and of the others;
* :func:`recheck_paths`: the successes of a saved paths file checked again on
  the evaluation geometry.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ntq_jax import artifacts
from ntq_jax.planners.verify import check_paths
from ntq_jax.robots.batch import distances, valid_states
from ntq_jax.stats import wilson_interval
from ntq_jax.types import CAUSE_NAMES, CAUSE_RANK, PlanCause, PlanStatus

__all__ = ["metrics", "best_of", "in_band", "band_metrics", "recheck_paths"]


def metrics(
    success: np.ndarray,
    costs: np.ndarray,
    cause: np.ndarray,
    ref_costs: np.ndarray,
    ref_status: np.ndarray,
    opt_costs: np.ndarray | None = None,
) -> dict:
    """Success ratio with its Wilson interval, cost ratios and failure counts."""
    k = int(len(success))
    s = int(np.sum(success))
    lo, hi = wilson_interval(s, k)
    ref_solved = ref_status == PlanStatus.SOLVED
    ref_ok = ref_solved & np.isfinite(ref_costs) & (ref_costs > 0)
    both = success & ref_ok
    out = {
        "k_test": k,
        "successes": s,
        "success_ratio": s / k if k else float("nan"),
        "success_ci95": [lo, hi],
        "cost_ratio": float(np.mean(costs[both] / ref_costs[both])) if both.any() else None,
        "cost_ratio_n": int(both.sum()),
        "failures": {
            CAUSE_NAMES[c]: int(np.sum(cause == c)) for c in PlanCause if c != PlanCause.SUCCESS
        },
        "reference_failed": int(np.sum(~ref_solved)),
        "reference_success_ratio": float(np.mean(ref_solved)) if k else float("nan"),
    }
    if opt_costs is not None:
        ok = success & np.isfinite(opt_costs) & (opt_costs > 0)
        out["cost_ratio_opt"] = float(np.mean(costs[ok] / opt_costs[ok])) if ok.any() else None
        rk = ref_ok & np.isfinite(opt_costs) & (opt_costs > 0)
        out["reference_cost_ratio_opt"] = (
            float(np.mean(ref_costs[rk] / opt_costs[rk])) if rk.any() else None
        )
    return out


def best_of(results: Sequence[dict]) -> dict:
    """Best-of-N: per query, the cheapest successful path among N planners' results.

    Args:
        results: N saved paths files' arrays (:func:`_plan_cell`'s dicts) of the
            same queries (e.g. the members' ``PNet_<m>`` files).

    Returns:
        The same arrays for the best-of-N planner: a query succeeds iff some
        member succeeds, with the lowest cost among the successes (ties: the
        first member); a failed query keeps the failure closest to a success
        (infeasible, then no path, then invalid query; ties: the first member).
        ``member`` is the index of the member whose path, length, cost and cause
        are kept; ``paths`` are NaN padded to the longest member buffer.
        ``pnet_calls`` and ``replans`` are summed over the members (the work
        spent on the query), and so are ``seconds`` and ``compile_seconds``: the
        members are planned one after the other, so the best-of-N planner's time
        is the sum of their planning times (run in parallel it would be their
        maximum). ``queries``, ``ref_costs``, ``ref_status`` and ``opt_costs``
        are the first member's.

    Raises:
        ValueError: no results.
    """
    if not results:
        raise ValueError("best_of needs at least one result")
    success = np.stack([np.asarray(r["success"], bool) for r in results])  # (N, K)
    costs = np.where(
        success, np.stack([np.asarray(r["costs"], np.float64) for r in results]), np.inf
    )
    cause = np.stack([np.asarray(r["cause"]) for r in results])
    rank = np.vectorize(lambda c: CAUSE_RANK[PlanCause(int(c))], otypes=[np.int64])(cause)
    any_ok = success.any(axis=0)
    pick = np.where(any_ok, np.argmin(costs, axis=0), np.argmin(rank, axis=0))
    k = success.shape[1]
    rows = np.arange(k)
    length = max(r["paths"].shape[1] for r in results)
    d = results[0]["paths"].shape[2]
    paths = np.full((k, length, d), np.nan, np.float32)
    for j, r in enumerate(results):
        sel = pick == j
        paths[sel, : r["paths"].shape[1]] = r["paths"][sel]
    lengths = np.stack([np.asarray(r["lengths"]) for r in results])[pick, rows]
    out = dict(
        queries=results[0]["queries"],
        paths=paths,
        lengths=lengths.astype(np.int32),
        success=any_ok,
        costs=costs[pick, rows],
        cause=cause[pick, rows].astype(np.int8),
        pnet_calls=np.sum([np.asarray(r["pnet_calls"], np.int64) for r in results], axis=0).astype(
            np.int32
        ),
        replans=np.sum([np.asarray(r["replans"], np.int64) for r in results], axis=0).astype(
            np.int32
        ),
        member=pick.astype(np.int8),
        ref_costs=results[0]["ref_costs"],
        ref_status=results[0]["ref_status"],
        seconds=float(sum(float(r["seconds"]) for r in results)),
        compile_seconds=float(sum(float(r["compile_seconds"]) for r in results)),
    )
    if "opt_costs" in results[0]:
        out["opt_costs"] = results[0]["opt_costs"]
    return out


def in_band(env, queries: np.ndarray) -> np.ndarray:
    """``(K,)`` bool: both endpoints of ``queries (K, 2, d)`` valid at the environment's padding.

    These are the test queries whose states lie where training data can lie
    (the data is generated at ``env.padding``); the others have an endpoint
    inside the padding band around the obstacles (or are invalid anyway).
    """
    q = np.asarray(queries, np.float32)
    k, d = q.shape[0], q.shape[2]
    ok = valid_states(env.robot, env.world, q.reshape(2 * k, d), env.padding)
    return ok.reshape(k, 2).all(axis=1)


def band_metrics(success: np.ndarray, band: np.ndarray) -> dict:
    """Success of the in-band and out-of-band queries apart, with 95% Wilson intervals.

    Args:
        success: ``(K,)`` bool per query.
        band: ``(K,)`` bool, True for the in-band queries (:func:`in_band`).

    Returns:
        ``n_in_band``, ``n_out_band``, ``successes_in_band``, ``successes_out_band``,
        ``success_in_band``, ``success_out_band`` (ratios, NaN for an empty part)
        and ``success_in_band_ci95``, ``success_out_band_ci95``.
    """
    success, band = np.asarray(success, bool), np.asarray(band, bool)
    out: dict = {}
    for name, part in (("in_band", band), ("out_band", ~band)):
        n, s = int(part.sum()), int((success & part).sum())
        lo, hi = wilson_interval(s, n)
        out.update(
            {
                f"n_{name}": n,
                f"successes_{name}": s,
                f"success_{name}": s / n if n else float("nan"),
                f"success_{name}_ci95": [lo, hi],
            }
        )
    return out


def recheck_paths(
    env, npz_path, *, delta: float | None = None, atol: float = 1e-5, check: str = "certified"
) -> np.ndarray:
    """Independent re-check of the successes of a saved paths file, on the evaluation geometry.

    A success passes when its path has at least 2 states, all finite, every
    segment passes the motion check ``check`` at padding 0 (default: the
    certified one; :func:`ntq_jax.planners.verify.check_paths`), it starts at the query's start
    and ends at the query's goal (every coordinate within ``atol``). A file of the
    variant without steerTo (``*_nosteer.npz``) records a success when the path's
    last state is within ``delta`` of the goal in the robot's cost metric
    (``env.robot.distance``; the rigid body's angle wraps), which it does not
    reach: its goal check is ``distance(end, goal) <= delta + atol``, ``delta``
    (the run's ``eval.delta``) is then required, and a path of one state (a start
    already within ``delta`` of the goal) passes when that state is finite and
    valid at padding 0.

    Returns:
        ``(K,)`` bool: False for the successes that fail the check, True elsewhere.

    Raises:
        FileNotFoundError: ``npz_path`` is not a complete ``.npz``.
        ValueError: a file without steerTo and no ``delta``.
    """
    z = artifacts.load_npz(npz_path)
    if z is None:
        raise FileNotFoundError(f"{npz_path} is not a complete .npz file")
    nosteer = Path(npz_path).stem.endswith("_nosteer")
    if nosteer and delta is None:
        raise ValueError(f"{npz_path} is of the variant without steerTo: pass its delta")
    rows = np.flatnonzero(z["success"])
    paths, n, q = z["paths"][rows], z["lengths"][rows], z["queries"][rows].astype(np.float64)
    free, _ = check_paths(env, paths, n, 0.0, check)
    start = paths[:, 0].astype(np.float64)
    end = paths[np.arange(len(rows)), np.maximum(n - 1, 0)].astype(np.float64)
    at_start = np.all(np.abs(start - q[:, 0]) <= atol, axis=1)
    if nosteer:
        single = np.flatnonzero(n == 1)  # one state: no segment, the state itself is checked
        free[single] = np.isfinite(start[single]).all(axis=1) & valid_states(
            env.robot, env.world, start[single], 0.0
        )
        at_goal = distances(env.robot, end, q[:, 1]) <= delta + atol
    else:
        at_goal = np.all(np.abs(end - q[:, 1]) <= atol, axis=1)
    ok = np.ones(len(z["success"]), bool)
    ok[rows] = free & at_start & at_goal
    return ok
