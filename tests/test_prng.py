"""Statistical quality of the fast counter-based generator in ``ntq_jax.prng``.

All seeds are fixed, so every test is deterministic. Each test keeps a family-wise
significance threshold of p > 0.001: a test of ``m`` correlations (z-scores) or bits
requires every |z| below the Bonferroni bound ``z_max(m)`` (3.29 for one, 3.9 for 8
lags, 4.4 for the 66 row pairs of a 6-link query).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import ntq_jax as nj
from ntq_jax import prng
from ntq_jax.stats import wilson_interval

P_MIN = 1e-3
N = 1_000_000

_uniform = jax.jit(prng.uniform)


def z_max(m):
    """Two-sided Bonferroni bound on |z| for ``m`` simultaneous tests at family-wise P_MIN."""
    return float(stats.norm.isf(P_MIN / (2 * m)))


def draws(seeds, counters):
    return np.asarray(_uniform(seeds, jnp.asarray(counters, jnp.uint32)))


def seeds_of(key_seed, index):
    return prng.stream_seeds(jax.random.PRNGKey(key_seed), index)


STREAMS = [seeds_of(0, 0), seeds_of(0, 1), seeds_of(123, 7)]


def test_range_and_dtype():
    u = draws(STREAMS[0], np.arange(N, dtype=np.uint32))
    assert u.dtype == np.float32 and u.shape == (N,)
    assert u.min() >= 0.0 and u.max() < 1.0
    # the extreme counters too (the counter wraps as uint32)
    v = draws(STREAMS[0], np.array([0, 1, 2**31, 2**32 - 2, 2**32 - 1], np.uint32))
    assert ((v >= 0) & (v < 1)).all()
    # deterministic: same seeds and counters, same values
    assert np.array_equal(u[:1000], draws(STREAMS[0], np.arange(1000, dtype=np.uint32)))


@pytest.mark.parametrize("s", range(len(STREAMS)))
def test_chi_square_uniformity_256_bins(s):
    u = draws(STREAMS[s], np.arange(N, dtype=np.uint32))
    counts = np.bincount((u * 256).astype(np.int64), minlength=256)
    assert stats.chisquare(counts).pvalue > P_MIN
    # every one of the 24 kept bits is fair
    bits = (u * (1 << 24)).astype(np.int64)
    ones = np.array([((bits >> b) & 1).sum() for b in range(24)])
    z = (ones - N / 2) / math.sqrt(N / 4)
    assert np.abs(z).max() < z_max(24), z


@pytest.mark.parametrize("s", range(len(STREAMS)))
def test_chi_square_pairs_64x64(s):
    """Consecutive counters as (x, y) pairs: exactly how the estimator places a point state."""
    u = draws(STREAMS[s], np.arange(2 * N, dtype=np.uint32)).reshape(N, 2)
    cell = (u[:, 0] * 64).astype(np.int64) * 64 + (u[:, 1] * 64).astype(np.int64)
    counts = np.bincount(cell, minlength=64 * 64)
    assert stats.chisquare(counts).pvalue > P_MIN


def _corr(a, b):
    a = a.astype(np.float64) - a.mean()
    b = b.astype(np.float64) - b.mean()
    return float((a * b).sum() / math.sqrt((a * a).sum() * (b * b).sum()))


@pytest.mark.parametrize("s", range(len(STREAMS)))
def test_serial_correlation_lags_1_to_8(s):
    u = draws(STREAMS[s], np.arange(N, dtype=np.uint32))
    for lag in range(1, 9):
        r = _corr(u[:-lag], u[lag:])
        assert abs(r) * math.sqrt(N - lag) < z_max(8), (lag, r)


@pytest.mark.parametrize("k", [4, 6, 12])
def test_rows_of_the_estimator_layout_are_uncorrelated(k):
    """The estimator draws row j of lane l from counter l * k + j (k = 2 * dim): every pair of
    rows (the coordinates of one candidate query) must be independent."""
    lanes = N // k
    u = draws(STREAMS[0], np.arange(lanes * k, dtype=np.uint32)).reshape(lanes, k)
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
    for i, j in pairs:
        assert abs(_corr(u[:, i], u[:, j])) * math.sqrt(lanes) < z_max(len(pairs)), (i, j)
    # the start (rows 0, 1) and goal (rows k/2, k/2 + 1) of a point query: joint histogram
    cell = (u[:, 0] * 16).astype(np.int64) * 16 + (u[:, k // 2] * 16).astype(np.int64)
    assert stats.chisquare(np.bincount(cell, minlength=256)).pvalue > P_MIN


@pytest.mark.parametrize("a, b", [(0, 1), (0, 2), (1, 2)])
def test_different_streams_are_uncorrelated(a, b):
    c = np.arange(N, dtype=np.uint32)
    u, v = draws(STREAMS[a], c), draws(STREAMS[b], c)
    assert not np.array_equal(u[:100], v[:100])
    assert abs(_corr(u, v)) * math.sqrt(N) < z_max(2)
    # also shifted by one counter (chunks of the estimator use the same counters)
    assert abs(_corr(u[1:], v[:-1])) * math.sqrt(N - 1) < z_max(2)
    cell = (u * 64).astype(np.int64) * 64 + (v * 64).astype(np.int64)
    assert stats.chisquare(np.bincount(cell, minlength=4096)).pvalue > P_MIN


def _threefry_gamma(env, key, n, padding):
    """gamma_nt from jax.random (threefry) candidates, checked with the public Env API."""
    lo, hi = (np.asarray(v) for v in env.robot.config_bounds(env.world))
    d = env.dim
    blocked, total, i = [], 0, 0
    while total < n:
        u = np.asarray(jax.random.uniform(jax.random.fold_in(key, i), (1 << 20, 2 * d)))
        a = (lo + u[:, :d] * (hi - lo)).astype(np.float32)
        b = (lo + u[:, d:] * (hi - lo)).astype(np.float32)
        ok = np.asarray(env.is_valid(a, padding=padding)) & np.asarray(
            env.is_valid(b, padding=padding)
        )
        free = np.asarray(env.steer_to(a[ok], b[ok], padding=padding))
        blocked.append(~free)
        total += len(free)
        i += 1
    blocked = np.concatenate(blocked)[:n]
    return int(blocked.sum())


@pytest.mark.parametrize("name, n", [("point/3", 1_000_000), ("point/1", 300_000)])
def test_fused_gamma_agrees_with_threefry(name, n):
    env = nj.make_env(name)
    est = env.gamma_nt(jax.random.PRNGKey(2024), n, padding=0.0)
    k = _threefry_gamma(env, jax.random.PRNGKey(99), n, 0.0)
    assert est.queries == n
    g1, g2 = est.gamma, k / n
    se = math.sqrt(g1 * (1 - g1) / n + g2 * (1 - g2) / n)
    assert abs(g1 - g2) < 4 * se, (g1, g2, se)
    lo1, hi1 = est.ci95
    lo2, hi2 = wilson_interval(k, n)
    assert lo1 <= hi2 and lo2 <= hi1  # the two 95% intervals overlap


def test_uniform_array_for_dropout_masks():
    """``uniform_array`` (PNet's dropout masks): shape, range, a function of the key only,
    different keys give independent draws, uniform (KS), keep-rate of a p=0.5 mask."""
    key = jax.random.key(7)
    u = np.asarray(jax.jit(prng.uniform_array, static_argnums=1)(key, (1000, 500)))
    assert u.shape == (1000, 500) and u.dtype == np.float32
    assert u.min() >= 0.0 and u.max() < 1.0
    np.testing.assert_array_equal(u, np.asarray(prng.uniform_array(key, (1000, 500))))
    v = np.asarray(prng.uniform_array(jax.random.key(8), (1000, 500)))
    assert stats.kstest(u.ravel(), "uniform").pvalue > P_MIN
    r = np.corrcoef(u.ravel(), v.ravel())[0, 1]
    assert abs(r) * math.sqrt(u.size) < z_max(1)
    keep = (u >= 0.5).mean()
    assert abs(keep - 0.5) < z_max(1) * 0.5 / math.sqrt(u.size)
    # vmapped over keys (one key per ensemble member) = one call per key
    keys = jax.random.split(key, 3)
    w = np.asarray(jax.vmap(lambda k: prng.uniform_array(k, (4, 5)))(keys))
    for i in range(3):
        np.testing.assert_array_equal(w[i], np.asarray(prng.uniform_array(keys[i], (4, 5))))
    with pytest.raises(ValueError, match="2\\*\\*32"):
        prng.uniform_array(key, (2**16, 2**16 + 1))


def test_uniform_prefix_is_jax_random_uniform_bit_for_bit(monkeypatch):
    """``uniform_prefix(key, n)`` equals ``jax.random.uniform(key, (n,))`` bit for bit for
    every ``n`` (both key kinds), draws one program per power-of-two bucket, and without
    ``jax_threefry_partitionable`` falls back to the draw of ``n`` itself."""
    sizes = [0, 1, 3, 100, 128, 129, 4097]
    for key in (jax.random.key(7), jax.random.PRNGKey(7)):
        for n in sizes:
            got = prng.uniform_prefix(key, n)
            want = np.asarray(jax.random.uniform(key, (n,)))
            assert got.dtype == np.float32 and got.shape == (n,)
            np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    seen = []
    real = jax.random.uniform
    monkeypatch.setattr(
        jax.random, "uniform", lambda k, shape: seen.append(shape) or real(k, shape)
    )
    for n in (65, 100, 128):
        prng.uniform_prefix(jax.random.key(1), n)
    assert seen == [(128,)] * 3
    seen.clear()
    before = jax.config.jax_threefry_partitionable
    jax.config.update("jax_threefry_partitionable", False)
    try:
        prng.uniform_prefix(jax.random.key(1), 100)
    finally:
        jax.config.update("jax_threefry_partitionable", before)
    assert seen == [(100,)]
