"""The two query pools of a run and how each dataset draws its queries from them.

Alg. 2 gives dataset ``j`` ``K`` queries, each non-trivial (Alg. 3) with
probability ``p_nt`` (its mixing bit), else uniform. Here the bits are drawn
once per dataset (:func:`mixing_bits`) and query ``t`` is the next unused query
of the non-trivial pool ``N`` if bit ``t`` is set, else the next unused query
of the uniform pool ``U`` (:func:`pool_index`). Everything depends only on the
seed and the environment's slug (:func:`run_keys`).
"""

from __future__ import annotations

import zlib
from typing import NamedTuple

import jax
import numpy as np

from ntq_jax import prng
from ntq_jax import queries as Q
from ntq_jax.progress import open_bar

__all__ = ["Keys", "run_keys", "mixing_bits", "pool_sizes", "Pools", "sample_pools", "pool_index"]


class Keys(NamedTuple):
    """The PRNG keys of one environment's run."""

    uniform: jax.Array  # the uniform pool U
    nontrivial: jax.Array  # the non-trivial pool N
    mix: jax.Array  # the datasets' mixing bits
    gamma: jax.Array  # the gamma_nt estimates


def run_keys(seed: int, slug: str) -> Keys:
    """The keys of environment ``slug``: ``fold_in(PRNGKey(seed), crc32(slug))`` split in four."""
    key = jax.random.fold_in(jax.random.PRNGKey(seed), zlib.crc32(slug.encode()) & 0x7FFFFFFF)
    return Keys(*jax.random.split(key, 4))


def mixing_bits(key: jax.Array, k: int, p_nt: float) -> np.ndarray:
    """Alg. 2's draws ``u_rand < p_nt`` for ``k`` queries, ``(k,)`` bool (True = non-trivial).

    The uniforms come from ``fold_in(key, round(1e6 p_nt))``: datasets with the same
    ``p_nt`` get the same bits, hence the same queries (e.g. D3 = D2 pruned).
    """
    if p_nt <= 0.0:
        return np.zeros(k, bool)
    if p_nt >= 1.0:
        return np.ones(k, bool)
    sub = jax.random.fold_in(key, int(round(p_nt * 1_000_000)))
    return prng.uniform_prefix(sub, k) < p_nt


def pool_sizes(bits: list[np.ndarray]) -> tuple[int, int]:
    """``(n_u, n_nt)``: the pool sizes every dataset's bits fit in."""
    return max(int((~b).sum()) for b in bits), max(int(b.sum()) for b in bits)


class Pools(NamedTuple):
    """The pooled queries: ``U`` first, then ``N``.

    Attributes:
        queries: ``(n_u + n_nt, 2, d)`` float32.
        kind: ``(n_u + n_nt,)`` int8 ``query_kind`` (uniform, non-trivial, exhausted).
        n_u: the size of ``U``.
    """

    queries: np.ndarray
    kind: np.ndarray
    n_u: int


def sample_pools(
    env,
    keys: Keys,
    n_u: int,
    n_nt: int,
    padding: float,
    n_max: int,
    progress=None,
    desc: str = "sample queries",
) -> Pools:
    """``n_u`` i.i.d. uniform and ``n_nt`` i.i.d. non-trivial queries (Alg. 3, ``n_max`` attempts)."""
    d = env.dim
    with open_bar(progress, desc=desc, total=n_u + n_nt, unit="query") as bar:
        U = (
            Q.sample_uniform_queries(env.robot, env.world, keys.uniform, n_u, padding)
            if n_u
            else np.zeros((0, 2, d), np.float32)
        )
        bar.update(n_u)
        if n_nt:
            N, exh = Q.sample_nontrivial_queries(
                env.robot, env.world, keys.nontrivial, n_nt, padding, n_max
            )
        else:
            N, exh = np.zeros((0, 2, d), np.float32), np.zeros(0, bool)
        bar.update(n_nt)
    kind = np.concatenate(
        [
            np.full(n_u, Q.UNIFORM, np.int8),
            np.where(exh, Q.NT_EXHAUSTED, Q.NON_TRIVIAL).astype(np.int8),
        ]
    )
    return Pools(np.concatenate([U, N]).astype(np.float32), kind, n_u)


def pool_index(bits: np.ndarray, n_u: int) -> np.ndarray:
    """Pool rows of a dataset's queries: query ``t`` is the next of ``N`` if ``bits[t]``
    (row ``n_u + `` its rank in ``N``), else the next of ``U``."""
    rank_nt = np.cumsum(bits) - 1
    rank_u = np.cumsum(~bits) - 1
    return np.where(bits, n_u + rank_nt, rank_u)
