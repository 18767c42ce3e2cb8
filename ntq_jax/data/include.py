"""includeData (Alg. 4 of the paper): training samples from planned paths.

Every segment ``i`` of every path gives the sample ``((pi_i, pi_end), pi_{i+1})``,
in path order, then along the path (Alg. 4's order). With pruning, a sample is
kept only where ``steer_to(pi_i, pi_end)`` is blocked (the pair is a non-trivial
query); all pairs go through one batched call of
:func:`ntq_jax.robots.batch.steer_to_pairs`. The last segment of a path is
therefore always pruned: consecutive waypoints of a feasible path see each other.

Probabilistic pruning (the paper's Sec. VI, "calling the pruning procedure with a
probability of gamma_nt"): with ``prune = p`` in (0, 1) each sample whose
``steer_to(pi_i, pi_end)`` is free is dropped with probability ``p``; blocked
(non-trivial) samples are always kept. Sample ``s`` (in the order above) is
dropped when it is free and ``u_s < p``, with ``u = rng.random(N)`` drawn once
per dataset: ``p = 0`` keeps everything (= no pruning, bit for bit), ``p = 1``
drops every free sample (= Alg. 4's pruning, bit for bit), and the datasets of
a run draw ``u`` from :func:`prune_rng` (seed, environment, dataset name),
so the choice does not depend on chunking, and a prefix of the paths gets a
prefix of the draws.

Keeping the last step (``keep_last``, beyond the paper): pruning as above, but
each path keeps its last sample ``((pi_{L-2}, pi_end), pi_end)``, the step into
the goal, whether or not it is free. On a path whose only goal-seeing waypoint
is ``pi_{L-2}`` (a shortcut path), pruning would otherwise remove exactly that
step from every path of the dataset.
"""

from __future__ import annotations

import zlib

import numpy as np

from ntq_jax.robots.batch import steer_to_pairs

__all__ = ["include_data", "prune_probability", "prune_rng"]


def prune_probability(prune) -> float:
    """The drop probability of a free sample: ``False`` -> 0, ``True`` -> 1, a number -> itself."""
    if isinstance(prune, (bool, np.bool_)):
        return 1.0 if prune else 0.0
    p = float(prune)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"prune must be a bool or a probability in [0, 1], got {prune!r}")
    return p


def prune_rng(seed: int, env_slug: str, dataset: str) -> np.random.Generator:
    """The generator of a dataset's probabilistic pruning draws.

    Seeded from ``(seed, crc32(env_slug), crc32(dataset), crc32("prune"))`` (a
    :class:`numpy.random.SeedSequence`): the same run seed, environment and
    dataset name give the same draws, whatever the chunking or the other datasets.
    """

    def h(t: str) -> int:
        return zlib.crc32(t.encode())

    return np.random.default_rng(
        np.random.SeedSequence([int(seed), h(env_slug), h(dataset), h("prune")])
    )


def include_data(
    env,
    paths,
    lengths,
    *,
    prune: bool | float,
    padding: float | None = None,
    rng: np.random.Generator | None = None,
    keep_last: bool = False,
):
    """Alg. 4 over every segment of every path at once.

    Sample ``((pi_i, pi_end), pi_{i+1})`` for ``i = 0..L_p-2`` of each path ``p``
    (in path order, then along the path). With ``prune``, the sample is dropped
    when ``steer_to(pi_i, pi_end)`` is collision-free at ``padding``; with a
    probability ``prune`` in (0, 1), such a sample is dropped with that
    probability (draws from ``rng``, one per sample, see the module docstring).

    Args:
        env: the :class:`ntq_jax.Env`.
        paths: ``(P, L, d)`` waypoints, NaN-padded after ``lengths[p]`` rows.
        lengths: ``(P,)`` waypoints per path (paths with fewer than 2 give no sample).
        prune: Alg. 4's ``pruneData`` flag, or the drop probability of a free sample
            (``0`` = ``False``, ``1`` = ``True``, bit for bit).
        padding: geometry of the pruning ``steer_to`` (default: the environment's).
        rng: the generator of the draws; required when ``0 < prune < 1``.
        keep_last: with pruning, keep each path's last sample (the step into the
            goal) even when it is free.

    Returns:
        ``(inputs (N, 2d) float32, targets (N, d) float32, path_index (N,) int32)``.
    """
    p_drop = prune_probability(prune)
    if 0.0 < p_drop < 1.0 and rng is None:
        raise ValueError("probabilistic pruning (0 < prune < 1) needs rng (see prune_rng)")
    paths = np.asarray(paths, np.float32)
    lengths = np.asarray(lengths, np.int64).reshape(-1)
    d = env.dim
    if paths.ndim != 3 or paths.shape[2] != d or paths.shape[0] != lengths.shape[0]:
        raise ValueError(
            f"paths must have shape (P, L, {d}) and lengths (P,), got "
            f"{paths.shape} and {lengths.shape}"
        )
    L = paths.shape[1]
    if np.any(lengths < 0) or np.any(lengths > L):
        raise ValueError(f"lengths must be in [0, {L}]")
    seg = np.arange(max(L - 1, 0))[None, :] < (lengths - 1)[:, None]
    p_idx, i_idx = np.nonzero(seg)
    cur = paths[p_idx, i_idx]
    nxt = paths[p_idx, i_idx + 1]
    goal = paths[p_idx, lengths[p_idx] - 1] if len(p_idx) else np.zeros((0, d), np.float32)
    if p_drop > 0.0 and len(p_idx):
        keep = ~steer_to_pairs(env.robot, env.world, cur, goal, env.resolve_padding(padding))
        if p_drop < 1.0:
            keep |= rng.random(len(keep)) >= p_drop
        if keep_last:
            keep |= i_idx == lengths[p_idx] - 2
        cur, nxt, goal, p_idx = cur[keep], nxt[keep], goal[keep], p_idx[keep]
    inputs = np.concatenate([cur, goal], axis=1).astype(np.float32).reshape(-1, 2 * d)
    return inputs, nxt.astype(np.float32).reshape(-1, d), p_idx.astype(np.int32)
