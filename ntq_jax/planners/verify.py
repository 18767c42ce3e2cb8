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

__all__ = [
    "valid_queries",
    "states_valid",
    "check_paths",
    "finalize",
    "motions_free",
    "ARM_CHUNKS",
]

#: The compiled batch sizes of a 3-D serial arm's motion checks in :func:`motions_free`,
#: smallest first: a batch runs in chunks of the first size that holds it (else of the
#: last). A planner checks anything from one motion (a query's verification) to 10^5
#: (a roadmap's edges) and a fixed chunk costs its whole size's set-up whatever it holds
#: (on the Panda, 3 motions in a chunk of 8,192: ~7 ms of CPU, of 64: ~0.3 ms; certified
#: in 1,024: ~18 ms, in 16: ~6 ms), while a few sizes keep the compiled programs few.
ARM_CHUNKS = {"discretized": (64, 1024, 8192), "certified": (16, 1024)}


def motions_free(robot, world, a, b, padding: float, check: str = "discretized") -> np.ndarray:
    """``(N,)`` bool, the motions ``a -> b`` ``(N, d)`` free by ``check``: the planners'
    batched motion check, :func:`ntq_jax.robots.batch.steer_to_pairs` (its answers) in
    chunks of :data:`ARM_CHUNKS` for a serial arm, of its own default for other robots
    (as every planner of the package has always used)."""
    sizes = ARM_CHUNKS.get(check) if getattr(robot, "kind", None) == "serial_arm" else None
    if sizes is None:
        return steer_to_pairs(robot, world, a, b, padding, check=check)
    n = int(np.shape(a)[0]) if np.ndim(a) > 1 else 0
    chunk = next((c for c in sizes if n <= c), sizes[-1])
    return steer_to_pairs(robot, world, a, b, padding, check=check, chunk=chunk)


def states_valid(robot, world, states, padding: float) -> np.ndarray:
    """``(N,)`` bool, the states ``(N, d)`` valid: :func:`ntq_jax.robots.batch.valid_states`
    (its answers), for a serial arm a batch of at most ``ARM_CHUNKS["discretized"][0]``
    states in a chunk of that size (one state's check then costs what a motion's smallest
    chunk does, not a whole default chunk's), otherwise in its default chunks."""
    small = ARM_CHUNKS["discretized"][0]
    if getattr(robot, "kind", None) == "serial_arm" and int(np.shape(states)[0]) <= small:
        return valid_states(robot, world, states, padding, chunk=small)
    return valid_states(robot, world, states, padding)


def valid_queries(env, q: np.ndarray, padding: float) -> np.ndarray:
    """``(K,)`` bool: start and goal finite and valid at ``padding``."""
    k, d = q.shape[0], q.shape[2]
    flat = q.reshape(2 * k, d)
    ok = states_valid(env.robot, env.world, flat, padding)
    return ok.reshape(k, 2).all(axis=1) & np.isfinite(flat).all(axis=1).reshape(k, 2).all(axis=1)


def _segment_costs(env, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(S,)`` float64 lengths of the segments ``a -> b`` in the robot's metric (exact
    float64 Euclidean for the point robot)."""
    if env.robot.kind == "point":
        return np.linalg.norm(b.astype(np.float64) - a.astype(np.float64), axis=1)
    return distances(env.robot, a, b).astype(np.float64)


def check_paths(
    env,
    paths: np.ndarray,
    lengths: np.ndarray,
    padding: float,
    check: str = "discretized",
    *,
    chunk: int | None = None,
    segments: bool = False,
):
    """Verifies NaN-padded paths with the exact kernel and computes their costs.

    Args:
        env: the environment.
        paths: ``(K, L, d)`` float32; lengths ``(K,)`` waypoint counts.
        padding: planning clearance.
        check: the motion check of every segment, ``"discretized"`` (the paper's)
            or ``"certified"`` (every configuration proven clear); see
            :func:`ntq_jax.robots.batch.motion_check`.
        chunk: motions per compiled call of the check (None: :func:`motions_free`'s
            calls); the answers do not depend on it.
        segments: also return each segment's verdict.

    Returns:
        ``(ok (K,) bool, costs (K,) float64)``: ``ok`` where the path has at least 2
        waypoints, all finite, and every segment passes ``env.steer_to`` in the
        travelled direction; costs are float64 sums of segment lengths in the
        robot's metric (exact float64 Euclidean for the point robot), inf where not ok.
        With ``segments``, also ``free (K, L - 1) bool``: segment ``j`` (waypoint
        ``j`` to ``j + 1``) is finite and passes the check (False past the path's end).
    """
    k, l, d = paths.shape
    lengths = np.asarray(lengths)
    seg = np.arange(max(l - 1, 0))[None, :] < (lengths[:, None] - 1)  # (K, L-1)
    rows, cols = np.nonzero(seg)
    a = paths[rows, cols]
    b = paths[rows, cols + 1]
    finite = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    if chunk is None:
        free = motions_free(env.robot, env.world, a, b, padding, check)
    else:
        free = steer_to_pairs(env.robot, env.world, a, b, padding, check=check, chunk=chunk)
    dist = _segment_costs(env, a, b)
    bad = np.zeros(k, bool)
    np.logical_or.at(bad, rows, ~(free & finite))
    costs = np.zeros(k)
    np.add.at(costs, rows, dist)
    ok = (lengths >= 2) & ~bad
    if not segments:
        return ok, np.where(ok, costs, np.inf)
    verdict = np.zeros(seg.shape, bool)
    verdict[rows, cols] = free & finite
    return ok, np.where(ok, costs, np.inf), verdict


def finalize(
    q: np.ndarray,
    paths: np.ndarray,
    lengths: np.ndarray,
    status: np.ndarray,
    info: dict,
    env,
    padding: float,
    check: str = "discretized",
    *,
    fallback: tuple | None = None,
    chunk: int | None = None,
) -> PlanResult:
    """A planner's raw output as a verified :class:`PlanResult`.

    Rows with ``status == SOLVED`` get the query's exact endpoints and are checked
    with :func:`check_paths` (motion check ``check``); a path that fails becomes NO_PATH (counted in
    ``info["rejected"]``). Non-solved rows are NaN with length 0 and cost inf.

    ``fallback`` (optional): ``(raw (K, R, d), raw_lengths (K,), index (K, L) int)``,
    the paths ``paths`` were shortcut from, with ``paths[i, j] == raw[i, index[i, j]]``
    (:func:`~ntq_jax.planners.smoothing.shortcut_paths`' ``return_index``). A segment
    that fails the check is then replaced by the raw waypoints it skipped, whose
    segments are checked in turn (``info["repaired"]`` counts the rows saved so): a
    planner can shortcut with a cheap check and still return only paths whose every
    segment passes ``check``. ``chunk``: as in :func:`check_paths`.
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
    if fallback is None:
        ok, costs = check_paths(env, out, lengths, padding, check, chunk=chunk)
        info["repaired"] = 0
    else:
        out, lengths, ok, costs = _check_with_fallback(
            q, out, lengths, fallback, env, padding, check, chunk, info
        )
    status = status.astype(np.int8).copy()
    rejected = (status == PlanStatus.SOLVED) & ~ok
    status[rejected] = PlanStatus.NO_PATH
    info["rejected"] = int(rejected.sum())
    solved = status == PlanStatus.SOLVED
    lengths = np.where(solved, lengths, 0).astype(np.int32)
    out[~solved] = np.nan
    costs = np.where(solved, costs, np.inf)
    return PlanResult(out, lengths, costs, status, info)


def _check_with_fallback(q, out, lengths, fallback, env, padding, check, chunk, info):
    """:func:`finalize`'s check with ``fallback``: ``(paths, lengths, ok, costs)``, failed
    segments replaced by the raw waypoints they skipped (each new segment checked once)."""
    raw, raw_len, index = fallback
    raw = np.array(raw, np.float32)
    raw_len = np.asarray(raw_len, np.int64)
    index = np.asarray(index, np.int64)
    ok, costs, free = check_paths(env, out, lengths, padding, check, chunk=chunk, segments=True)
    fix = np.flatnonzero(~ok & (lengths >= 2) & (raw_len >= 2))
    info["repaired"] = 0
    if not len(fix):
        return out, lengths, ok, costs
    raw[fix, 0] = q[fix, 0]  # the same exact ends as the shortcut path
    raw[fix, raw_len[fix] - 1] = q[fix, 1]
    spliced, verdicts, new_a, new_b, owner = [], [], [], [], []
    for r in fix:
        n = int(lengths[r])
        idx = index[r, :n]
        pts, known = [out[r, 0]], []
        for j in range(n - 1):
            if free[r, j] or idx[j + 1] - idx[j] <= 1 or idx[j] < 0:
                pts.append(out[r, j + 1])
                known.append(bool(free[r, j]))
                continue
            for m in range(idx[j] + 1, idx[j + 1] + 1):  # the skipped raw waypoints, then the end
                pts.append(raw[r, m])
                known.append(None)  # to check
                new_a.append(pts[-2])
                new_b.append(pts[-1])
                owner.append(len(spliced))
        spliced.append(np.asarray(pts, np.float32))
        verdicts.append(known)
    if new_a:
        a, b = np.asarray(new_a), np.asarray(new_b)
        new_free = iter(
            motions_free(env.robot, env.world, a, b, padding, check)
            if chunk is None
            else steer_to_pairs(env.robot, env.world, a, b, padding, check=check, chunk=chunk)
        )
        verdicts = [[next(new_free) if v is None else v for v in known] for known in verdicts]
    width = max(out.shape[1], max(len(p) for p in spliced))
    if width > out.shape[1]:
        out = np.concatenate(
            [out, np.full((out.shape[0], width - out.shape[1], out.shape[2]), np.nan, np.float32)],
            axis=1,
        )
    lengths = lengths.copy()
    ok, costs = ok.copy(), costs.copy()
    for r, p, v in zip(fix, spliced, verdicts):
        if not all(v) or not np.isfinite(p).all():
            continue
        out[r] = np.nan
        out[r, : len(p)] = p
        lengths[r] = len(p)
        ok[r] = True
        costs[r] = float(_segment_costs(env, p[:-1], p[1:]).sum())
        info["repaired"] += 1
    return out, lengths, ok, costs
