"""includeData (Alg. 4 of the paper): training samples from planned paths.

Every segment ``i`` of every path gives the sample ``((pi_i, pi_end), pi_{i+1})``,
in path order, then along the path (Alg. 4's order). With pruning, a sample is
kept only where ``steer_to(pi_i, pi_end)`` is blocked (the pair is a non-trivial
query); all pairs go through one batched call of
:func:`ntq_jax.robots.batch.steer_to_pairs`. The last segment of a path is
therefore always pruned: consecutive waypoints of a feasible path see each other.
"""

from __future__ import annotations

import numpy as np

from ntq_jax.robots.batch import steer_to_pairs

__all__ = ["include_data"]


def include_data(env, paths, lengths, *, prune: bool, padding: float | None = None):
    """Alg. 4 over every segment of every path at once.

    Sample ``((pi_i, pi_end), pi_{i+1})`` for ``i = 0..L_p-2`` of each path ``p``
    (in path order, then along the path). With ``prune``, the sample is dropped
    when ``steer_to(pi_i, pi_end)`` is collision-free at ``padding``.

    Args:
        env: the :class:`ntq_jax.Env`.
        paths: ``(P, L, d)`` waypoints, NaN-padded after ``lengths[p]`` rows.
        lengths: ``(P,)`` waypoints per path (paths with fewer than 2 give no sample).
        prune: Alg. 4's ``pruneData`` flag.
        padding: geometry of the pruning ``steer_to`` (default: the environment's).

    Returns:
        ``(inputs (N, 2d) float32, targets (N, d) float32, path_index (N,) int32)``.
    """
    paths = np.asarray(paths, np.float32)
    lengths = np.asarray(lengths, np.int64).reshape(-1)
    d = env.dim
    if paths.ndim != 3 or paths.shape[2] != d or paths.shape[0] != lengths.shape[0]:
        raise ValueError(f"paths must have shape (P, L, {d}) and lengths (P,), got "
                         f"{paths.shape} and {lengths.shape}")
    L = paths.shape[1]
    if np.any(lengths < 0) or np.any(lengths > L):
        raise ValueError(f"lengths must be in [0, {L}]")
    seg = np.arange(max(L - 1, 0))[None, :] < (lengths - 1)[:, None]
    p_idx, i_idx = np.nonzero(seg)
    cur = paths[p_idx, i_idx]
    nxt = paths[p_idx, i_idx + 1]
    goal = paths[p_idx, lengths[p_idx] - 1] if len(p_idx) else np.zeros((0, d), np.float32)
    if prune and len(p_idx):
        keep = ~steer_to_pairs(env.robot, env.world, cur, goal, env.resolve_padding(padding))
        cur, nxt, goal, p_idx = cur[keep], nxt[keep], goal[keep], p_idx[keep]
    inputs = np.concatenate([cur, goal], axis=1).astype(np.float32).reshape(-1, 2 * d)
    return inputs, nxt.astype(np.float32).reshape(-1, d), p_idx.astype(np.int32)
