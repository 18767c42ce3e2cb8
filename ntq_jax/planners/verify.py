"""The one path checker: every planned path is verified here, with the package's steer_to.

:func:`check_paths` verifies NaN-padded paths segment by segment with the
batched ``steer_to`` (the discretised or the certified motion check) and computes their costs; :func:`finalize` turns a
planner's raw output into the :class:`ntq_jax.types.PlanResult` contract
(exact endpoints, verified SOLVED rows, NaN padding). Both return new arrays;
neither mutates its inputs.
"""

from __future__ import annotations

import numpy as np

from ntq_jax.robots.batch import distances, steer_to_pairs, valid_states
from ntq_jax.types import PlanResult, PlanStatus

__all__ = ["valid_queries", "check_paths", "finalize"]


def valid_queries(env, q: np.ndarray, padding: float) -> np.ndarray:
    """``(K,)`` bool: start and goal finite and valid at ``padding``."""
    k, d = q.shape[0], q.shape[2]
    flat = q.reshape(2 * k, d)
    ok = valid_states(env.robot, env.world, flat, padding)
    return ok.reshape(k, 2).all(axis=1) & np.isfinite(flat).all(axis=1).reshape(k, 2).all(axis=1)


def check_paths(env, paths: np.ndarray, lengths: np.ndarray, padding: float,
                check: str = "discretized"):
    """Verifies NaN-padded paths with the exact kernel and computes their costs.

    Args:
        env: the environment.
        paths: ``(K, L, d)`` float32; lengths ``(K,)`` waypoint counts.
        padding: planning clearance.
        check: the motion check of every segment, ``"discretized"`` (the paper's)
            or ``"certified"`` (every configuration proven clear); see
            :func:`ntq_jax.robots.batch.motion_check`.

    Returns:
        ``(ok (K,) bool, costs (K,) float64)``: ``ok`` where the path has at least 2
        waypoints, all finite, and every segment passes ``env.steer_to`` in the
        travelled direction; costs are float64 sums of segment lengths in the
        robot's metric (exact float64 Euclidean for the point robot), inf where not ok.
    """
    k, l, d = paths.shape
    lengths = np.asarray(lengths)
    seg = np.arange(max(l - 1, 0))[None, :] < (lengths[:, None] - 1)  # (K, L-1)
    rows, cols = np.nonzero(seg)
    a = paths[rows, cols]
    b = paths[rows, cols + 1]
    finite = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    free = steer_to_pairs(env.robot, env.world, a, b, padding, check=check)
    if env.robot.kind == "point":
        dist = np.linalg.norm(b.astype(np.float64) - a.astype(np.float64), axis=1)
    else:
        dist = distances(env.robot, a, b).astype(np.float64)
    bad = np.zeros(k, bool)
    np.logical_or.at(bad, rows, ~(free & finite))
    costs = np.zeros(k)
    np.add.at(costs, rows, dist)
    ok = (lengths >= 2) & ~bad
    return ok, np.where(ok, costs, np.inf)


def finalize(q: np.ndarray, paths: np.ndarray, lengths: np.ndarray, status: np.ndarray,
             info: dict, env, padding: float, check: str = "discretized") -> PlanResult:
    """A planner's raw output as a verified :class:`PlanResult`.

    Rows with ``status == SOLVED`` get the query's exact endpoints and are checked
    with :func:`check_paths` (motion check ``check``); a path that fails becomes NO_PATH (counted in
    ``info["rejected"]``). Non-solved rows are NaN with length 0 and cost inf.
    """
    k, d = q.shape[0], q.shape[2]
    solved_in = status == PlanStatus.SOLVED
    lengths = np.where(solved_in, lengths, 0).astype(np.int32)
    width = max(2, int(lengths.max(initial=0)))
    out = np.full((k, width, d), np.nan, np.float32)
    w = min(width, paths.shape[1])
    out[:, :w] = paths[:, :w]
    keep = np.arange(width)[None, :] < lengths[:, None]
    out = np.where(keep[:, :, None], out, np.nan).astype(np.float32)
    rows = np.flatnonzero(lengths >= 2)
    out[rows, 0] = q[rows, 0]  # planners must return the exact states; enforce it
    out[rows, lengths[rows] - 1] = q[rows, 1]
    ok, costs = check_paths(env, out, lengths, padding, check)
    status = status.astype(np.int8).copy()
    rejected = (status == PlanStatus.SOLVED) & ~ok
    status[rejected] = PlanStatus.NO_PATH
    info["rejected"] = int(rejected.sum())
    solved = status == PlanStatus.SOLVED
    lengths = np.where(solved, lengths, 0).astype(np.int32)
    out[~solved] = np.nan
    costs = np.where(solved, costs, np.inf)
    return PlanResult(out, lengths, costs, status, info)
