"""What the data planner's paths look like before includeData: ``planner.data_paths``.

includeData (Alg. 4) makes one sample per segment ``(pi_i, pi_end) -> pi_i+1``
and, when pruning, drops the samples whose ``steerTo(pi_i, pi_end)`` is free.
So the density of the data paths decides both how many samples a path gives
and what pruning removes:

``"raw"``
    The planner's own waypoints: grid cell centres (``astar``), roadmap nodes
    (``roadmap``), BIT*'s path as OMPL returns it (``bitstar``), the visibility
    graph's corners (``visgraph``). Many short segments; pruning drops every
    waypoint that already sees the goal (the trivial tail of the paper's Fig. 1).
``"shortcut"``
    The greedy farthest-visible shortcut (:mod:`ntq_jax.planners.smoothing`):
    a few corners. Only the second-to-last waypoint sees the goal, so pruning
    drops exactly one sample per path, the step into the goal.
a number ``s > 0``
    The shortcut path resampled so that consecutive waypoints are at most ``s``
    apart in the robot's metric (:mod:`ntq_jax.planners.resample`): the
    shortcut's corners and cost with a BIT*-like density; pruning drops the
    steps of the final straight run into the goal. A direct connection (a
    shortcut of 2 waypoints: the query is trivial at the data padding) is kept
    as its two ends, as BIT* returns it: one sample, the step into the goal.
``None``
    The planner's default: shortcut for ``astar`` and ``roadmap``, raw for
    ``bitstar`` and ``visgraph`` (and a user's planner callable).

The evaluation reference is always the planner's default output.
"""

from __future__ import annotations

import numpy as np

from ntq_jax.planners.resample import resample_paths
from ntq_jax.planners.smoothing import shortcut_paths
from ntq_jax.planners.verify import check_paths
from ntq_jax.types import PlanResult

__all__ = ["SMOOTHING_PLANNERS", "planner_smooth", "shape_paths"]

SMOOTHING_PLANNERS = ("astar", "roadmap")  # planners with their own ``smooth`` option


def planner_smooth(mode, planner: str) -> bool | None:
    """The ``smooth`` option a smoothing planner gets for ``mode`` (None: not set)."""
    if mode is None or planner not in SMOOTHING_PLANNERS:
        return None
    return mode != "raw"


def shape_paths(
    env, result: PlanResult, mode, planner: str, padding: float, check: str = "discretized"
) -> tuple[PlanResult, dict]:
    """The data paths of ``mode`` from a planned pool (see the module doc).

    Args:
        env: the environment.
        result: the verified :class:`PlanResult` of the data planner (a smoothing
            planner already ran with :func:`planner_smooth`'s option).
        mode: ``planner.data_paths``.
        planner: the planner's name (``"custom"`` for a callable).
        padding: the data padding (every new connection is checked at it).
        check: the motion check of the new connections.

    Returns:
        ``(result, info)``: the shaped paths (same queries and statuses; costs
        recomputed) and ``{"mode", "shortcut_kept", "resample_kept"}``: paths left
        as they were because their shortcut or resampled form failed the check
        (counted, never dropped; a resampled path can fail where its shortcut
        passed because the discretised check then samples other states of the
        same segments).
    """
    if not (
        mode in (None, "raw", "shortcut")
        or (isinstance(mode, (int, float)) and not isinstance(mode, bool) and mode > 0)
    ):
        raise ValueError(f"data_paths must be raw, shortcut, a spacing > 0 or None; got {mode!r}")
    info = {"mode": mode, "shortcut_kept": 0, "resample_kept": 0}
    if mode is None or mode == "raw":
        return result, info
    paths, lengths, costs = result.paths, result.lengths, result.costs
    rows = np.flatnonzero(result.solved)
    if not len(rows):
        return result, info
    if planner not in SMOOTHING_PLANNERS:  # shortcut here
        sp, sl, ok = shortcut_paths(
            env.robot, env.world, paths[rows], lengths[rows], padding, check=check
        )
        paths, lengths, costs, info["shortcut_kept"] = _merge(
            paths, lengths, costs, rows, sp, sl, ok, env, padding, check
        )
    rows = rows[lengths[rows] > 2]  # a direct connection stays its two ends (BIT*'s)
    if mode != "shortcut" and len(rows):
        rp, rl = resample_paths(env.robot, paths[rows], lengths[rows], float(mode))
        paths, lengths, costs, info["resample_kept"] = _merge(
            paths, lengths, costs, rows, rp, rl, np.ones(len(rows), bool), env, padding, check
        )
    return PlanResult(paths, lengths, costs, result.status, dict(result.info)), info


def _merge(paths, lengths, costs, rows, new_paths, new_lengths, ok, env, padding, check):
    """``rows`` replaced by the new paths where ``ok`` and the check passes; costs
    recomputed. Returns ``(paths, lengths, costs, rows left as they were)``."""
    good, new_costs = check_paths(env, new_paths, new_lengths, padding, check)
    ok = ok & good
    take = rows[ok]
    k, width = paths.shape[0], max(paths.shape[1], new_paths.shape[1])
    out = np.full((k, width, paths.shape[2]), np.nan, np.float32)
    out[:, : paths.shape[1]] = paths
    out[take] = np.nan
    out[take, : new_paths.shape[1]] = new_paths[ok]
    lengths, costs = lengths.copy(), costs.copy()
    lengths[take], costs[take] = new_lengths[ok], new_costs[ok]
    return out[:, : max(2, int(lengths.max(initial=2)))], lengths, costs, int((~ok).sum())
