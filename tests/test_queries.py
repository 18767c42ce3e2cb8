"""Query sampling (uniform, non-trivial = Alg. 3, the p_nt mixture of Alg. 2) and gamma_nt.

The references here are independent of the package: a plain sequential Python
Alg. 3, a brute-force sequential rejection sampler driven by NumPy's RNG, and an
exact shapely oracle for validity and straight-line connections.
"""

from __future__ import annotations

import collections
import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

import ntq_jax as nj
from ntq_jax import gamma as G
from ntq_jax import prng
from ntq_jax import queries as Q
from ntq_jax.geometry import World
from ntq_jax.robots import PointRobot, RigidBody
from ntq_jax.robots.batch import is_valid_batch, steer_to_batch
from ntq_jax.stats import wilson_interval

P_MIN = 1e-3  # significance threshold of every statistical test (fixed seeds: deterministic)


# ---------------------------------------------------------------------------
# (a) replay_nontrivial == a plain sequential Alg. 3
# ---------------------------------------------------------------------------


def sequential_alg3(blocked, n_max, attempts=0):
    """The paper's Alg. 3 run call after call over one stream of candidate queries.

    Returns the indices of the returned candidates, whether each was returned after
    ``n_max`` trivial attempts, and the attempts made in the unfinished call.
    """
    idx, exhausted = [], []
    for k, b in enumerate(blocked):
        attempts += 1
        if b:
            idx.append(k)
            exhausted.append(False)
            attempts = 0
        elif attempts == n_max:
            idx.append(k)
            exhausted.append(True)
            attempts = 0
    return idx, exhausted, attempts


def replay_in_blocks(blocked, n_max, cuts):
    """``replay_nontrivial`` over the stream split at ``cuts``, carrying attempts across blocks."""
    idx, exh, attempts, start = [], [], 0, 0
    for end in list(cuts) + [len(blocked)]:
        i, x, attempts = Q.replay_nontrivial(np.asarray(blocked[start:end], bool), n_max, attempts)
        assert 0 <= attempts < n_max
        idx += (np.asarray(i) + start).tolist()
        exh += np.asarray(x, bool).tolist()
        start = end
    return idx, exh, attempts


@st.composite
def blocked_streams(draw):
    n = draw(st.integers(0, 600))
    rate = draw(st.sampled_from([0.0, 0.001, 0.05, 0.3, 0.7, 1.0]))
    seed = draw(st.integers(0, 2**32 - 1))
    stream = (np.random.default_rng(seed).random(n) < rate).tolist()
    if draw(st.booleans()):  # hypothesis-shaped streams too (shrinkable)
        stream = draw(st.lists(st.booleans(), min_size=0, max_size=60))
    cuts = sorted(draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    return stream, cuts


@settings(max_examples=400, deadline=None, database=None)
@given(data=blocked_streams(), n_max=st.sampled_from([1, 2, 3, 5, 17, 10_000]))
def test_replay_equals_sequential_alg3(data, n_max):
    stream, cuts = data
    assert replay_in_blocks(stream, n_max, cuts) == sequential_alg3(stream, n_max)
    # one block at a time, and everything at once
    assert replay_in_blocks(stream, n_max, range(1, len(stream))) == sequential_alg3(stream, n_max)
    assert replay_in_blocks(stream, n_max, []) == sequential_alg3(stream, n_max)


def test_replay_edge_cases():
    # N_max = 1: every candidate is returned; the trivial ones flagged
    idx, exh, after = Q.replay_nontrivial(np.array([False, True, False]), 1)
    assert idx.tolist() == [0, 1, 2] and exh.tolist() == [True, False, True] and after == 0
    # carried attempts complete a call started in the previous block
    idx, exh, after = Q.replay_nontrivial(np.array([False, False, False]), 3, attempts0=2)
    assert idx.tolist() == [0] and exh.tolist() == [True] and after == 2
    # a blocked candidate on the N_max-th attempt is returned as non-trivial
    idx, exh, after = Q.replay_nontrivial(np.array([False, True]), 2)
    assert idx.tolist() == [1] and exh.tolist() == [False] and after == 0
    # an empty block changes nothing
    idx, exh, after = Q.replay_nontrivial(np.zeros(0, bool), 4, attempts0=3)
    assert idx.size == 0 and exh.size == 0 and after == 3


# ---------------------------------------------------------------------------
# An independent oracle for a small point map (shapely, float64, exact)
# ---------------------------------------------------------------------------

BOUNDS = np.array([[0.0, 10.0], [0.0, 10.0]])
BOXES = np.array([[3.0, 5.0, 0.5, 3.0], [7.0, 3.0, 1.5, 0.5]])
DISCS = np.array([[7.0, 7.5, 1.0]])
PAD = 0.25


class Oracle:
    """Validity and straight-line connections on a point map, from shapely distances."""

    def __init__(self, bounds, boxes, discs, pad):
        self.bounds, self.pad = np.asarray(bounds, np.float64), float(pad)
        b = np.asarray(boxes, np.float64).reshape(-1, 4)
        self.obstacles = np.concatenate(
            [
                shapely.box(
                    b[:, 0] - b[:, 2], b[:, 1] - b[:, 3], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3]
                ),
                shapely.points(np.asarray(discs, np.float64).reshape(-1, 3)[:, :2]),
            ]
        )
        self.radii = np.concatenate(
            [np.zeros(len(b)), np.asarray(discs, np.float64).reshape(-1, 3)[:, 2]]
        )

    def margin(self, geoms):
        """``min over obstacles (distance - padding)`` per geometry: > 0 means clear."""
        geoms = np.atleast_1d(geoms)
        d = shapely.distance(geoms[:, None], self.obstacles[None, :]) - self.radii
        return d.min(axis=1) - self.pad

    def inside(self, pts):
        pts = np.asarray(pts, np.float64).reshape(-1, 2)
        b = self.bounds
        return (
            (pts[:, 0] >= b[0, 0])
            & (pts[:, 0] <= b[0, 1])
            & (pts[:, 1] >= b[1, 0])
            & (pts[:, 1] <= b[1, 1])
        )

    def valid(self, pts):
        pts = np.asarray(pts, np.float64).reshape(-1, 2)
        return self.inside(pts) & (self.margin(shapely.points(pts)) > 0)

    def segment_margin(self, a, b):
        a = np.asarray(a, np.float64).reshape(-1, 2)
        b = np.asarray(b, np.float64).reshape(-1, 2)
        segs = np.stack([a, b], 1)  # (N, 2, 2)
        return self.margin(shapely.linestrings(segs))

    def blocked(self, a, b):
        return self.segment_margin(a, b) <= 0


ORACLE = Oracle(BOUNDS, BOXES, DISCS, PAD)
ROBOT = PointRobot()
WORLD = World.create(BOUNDS, BOXES, DISCS)
ENV = nj.Env("test/point", ROBOT, WORLD, PAD)


def brute_force_nontrivial(rng, n, n_max, oracle=ORACLE):
    """The paper's sequential Alg. 3 with rejection-sampled uniform valid states, one at a time."""
    lo, hi = oracle.bounds[:, 0], oracle.bounds[:, 1]

    def valid_state():
        while True:
            p = rng.uniform(lo, hi)
            if oracle.valid(p)[0]:
                return p

    out, exhausted = np.zeros((n, 2, 2)), np.zeros(n, bool)
    for j in range(n):
        for _ in range(n_max):
            s, g = valid_state(), valid_state()
            blocked = oracle.blocked(s, g)[0]
            if blocked:
                break
        out[j] = s, g
        exhausted[j] = not blocked
    return out, exhausted


def brute_force_uniform(rng, n, oracle=ORACLE):
    """``n`` uniform valid queries by vectorised rejection (NumPy RNG)."""
    states = []
    while sum(len(s) for s in states) < 2 * n:
        p = rng.uniform(oracle.bounds[:, 0], oracle.bounds[:, 1], (4 * n, 2))
        states.append(p[oracle.valid(p)])
    return np.concatenate(states)[: 2 * n].reshape(n, 2, 2)


def brute_force_gamma(rng, n, oracle=ORACLE):
    q = brute_force_uniform(rng, n, oracle)
    return int(oracle.blocked(q[:, 0], q[:, 1]).sum())


def features(q):
    """1D summaries of a query set for two-sample KS tests."""
    q = np.asarray(q, np.float64)
    d = q[:, 1] - q[:, 0]
    return {
        "start x": q[:, 0, 0],
        "start y": q[:, 0, 1],
        "goal x": q[:, 1, 0],
        "goal y": q[:, 1, 1],
        "length": np.hypot(d[:, 0], d[:, 1]),
        "direction": np.arctan2(d[:, 1], d[:, 0]),
    }


def assert_same_distribution(a, b, what):
    fa, fb = features(a), features(b)
    pvals = {k: stats.ks_2samp(fa[k], fb[k]).pvalue for k in fa}
    assert min(pvals.values()) > P_MIN, f"{what}: KS p-values {pvals}"


# the exact gamma of this map (to +-0.003 at 4 sigma), from a large brute-force Monte Carlo
@pytest.fixture(scope="module")
def gamma_ref():
    n = 200_000
    k = brute_force_gamma(np.random.default_rng(12345), n)
    return k / n, math.sqrt(k / n * (1 - k / n) / n)


N_STAT = 3000


@pytest.fixture(scope="module")
def nt_samples():
    """Package and brute-force non-trivial samples, for a large and a small N_max."""
    out = {}
    for n_max, seed in ((Q.DEFAULT_N_MAX, 0), (2, 1)):
        q, exh = Q.sample_nontrivial_queries(
            ROBOT, WORLD, jax.random.PRNGKey(seed), N_STAT, PAD, n_max
        )
        bq, bexh = brute_force_nontrivial(np.random.default_rng(100 + seed), N_STAT, n_max)
        out[n_max] = (q, exh, bq, bexh)
    return out


# ---------------------------------------------------------------------------
# (b) the non-trivial sampler has the distribution of the sequential rejection sampler
# ---------------------------------------------------------------------------


def test_nontrivial_matches_brute_force_sequential_sampler(nt_samples):
    q, exh, bq, bexh = nt_samples[Q.DEFAULT_N_MAX]
    assert q.shape == (N_STAT, 2, 2) and q.dtype == np.float32 and exh.shape == (N_STAT,)
    assert not exh.any() and not bexh.any()  # N_max = 10^4 is never exhausted at gamma ~ 0.6
    assert_same_distribution(q, bq, "non-trivial, N_max large")
    # and it is far from the uniform query distribution (the test has power)
    uq = brute_force_uniform(np.random.default_rng(7), N_STAT)
    assert stats.ks_2samp(features(q)["length"], features(uq)["length"]).pvalue < 1e-6


def test_nontrivial_small_n_max_exhausts_at_the_expected_rate(nt_samples, gamma_ref):
    n_max = 2
    q, exh, bq, bexh = nt_samples[n_max]
    assert_same_distribution(q, bq, f"non-trivial, N_max={n_max}")
    assert_same_distribution(q[exh], bq[bexh], f"exhausted (trivial) queries, N_max={n_max}")
    assert_same_distribution(q[~exh], bq[~bexh], f"non-trivial queries, N_max={n_max}")
    # exhausted fraction ~ Binomial(n, (1 - gamma)^N_max); gamma known to +-4 sd_g
    g, sd_g = gamma_ref
    p = (1 - g) ** n_max
    sd_p = n_max * (1 - g) ** (n_max - 1) * sd_g
    for k in (int(exh.sum()), int(bexh.sum())):
        sd = math.sqrt(p * (1 - p) / N_STAT + sd_p**2)
        assert abs(k / N_STAT - p) < 4 * sd, (k / N_STAT, p, sd)
    # the two samplers' exhausted rates agree (two-proportion, Fisher exact)
    table = [[int(exh.sum()), N_STAT - int(exh.sum())], [int(bexh.sum()), N_STAT - int(bexh.sum())]]
    assert stats.fisher_exact(table).pvalue > P_MIN


def test_n_max_one_returns_uniform_queries_flagged_by_triviality():
    q, exh = Q.sample_nontrivial_queries(ROBOT, WORLD, jax.random.PRNGKey(5), 2000, PAD, n_max=1)
    blocked = ORACLE.blocked(q[:, 0], q[:, 1])
    margin = np.abs(ORACLE.segment_margin(q[:, 0], q[:, 1]))
    sure = margin > 1e-5
    assert (exh[sure] == ~blocked[sure]).all()
    assert_same_distribution(q, brute_force_uniform(np.random.default_rng(8), 2000), "N_max = 1")
    with pytest.raises(ValueError, match="n_max"):
        Q.sample_nontrivial_queries(ROBOT, WORLD, jax.random.PRNGKey(5), 10, PAD, n_max=0)


# ---------------------------------------------------------------------------
# (c) every non-trivial query is blocked, every exhausted one trivial (independent check)
# ---------------------------------------------------------------------------

BAND = 1e-5  # float32 tangency band at coordinates <= 10: 1e-6 + 4 * eps32 * 10 ~ 5e-6, rounded up


def test_returned_queries_are_checked_independently(nt_samples):
    for n_max, (q, exh, _, _) in nt_samples.items():
        assert ORACLE.valid(q.reshape(-1, 2)).all(), "an endpoint is not a valid state"
        margin = ORACLE.segment_margin(q[:, 0], q[:, 1])
        sure = np.abs(margin) > BAND
        assert sure.mean() > 0.999
        assert (margin[sure & ~exh] < 0).all(), f"N_max={n_max}: a non-trivial query is not blocked"
        assert (margin[sure & exh] > 0).all(), f"N_max={n_max}: an exhausted query is blocked"


def _discretized_blocked(robot, q, oracle_valid):
    """Independent discretised steer_to: ``n = ceil(distance / resolution)`` steps, every state
    checked with the oracle. Returns (blocked, certain) per query."""
    out, certain = [], []
    for a, b in np.asarray(q, np.float64):
        if isinstance(robot, RigidBody):
            dth = (b[2] - a[2] + np.pi) % (2 * np.pi) - np.pi
            dist = math.hypot(*(b[:2] - a[:2])) + robot.angle_weight * abs(dth)
        else:
            dth = None
            dist = float(np.linalg.norm(b - a))
        n = max(math.ceil(np.float32(dist) / np.float32(robot.resolution)), 1)
        t = np.arange(n + 1)[:, None] / n
        states = a + t * (b - a)
        if dth is not None:
            states[:, 2] = (a[2] + t[:, 0] * dth + np.pi) % (2 * np.pi) - np.pi
        worst = oracle_valid(states).min()
        out.append(worst <= 0)
        certain.append(abs(worst) > 1e-4)
    return np.array(out), np.array(certain)


def _rect_margin(robot, world, pad):
    b = np.asarray(world.boxes, np.float64)
    boxes = shapely.box(b[:, 0] - b[:, 2], b[:, 1] - b[:, 3], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3])
    bounds = np.asarray(world.bounds, np.float64)

    def margin(states):
        x, y, th = states.T
        c, s = np.cos(th), np.sin(th)
        hl, hw = robot.length / 2, robot.width / 2
        corners = np.stack(
            [
                np.stack([x + a * hl * c - e * hw * s, y + a * hl * s + e * hw * c], 1)
                for a, e in ((1, 1), (-1, 1), (-1, -1), (1, -1))
            ],
            1,
        )
        d = shapely.distance(shapely.polygons(corners)[:, None], boxes[None]).min(1) - pad
        inside = np.minimum.reduce(
            [
                corners[..., 0] - bounds[0, 0],
                bounds[0, 1] - corners[..., 0],
                corners[..., 1] - bounds[1, 0],
                bounds[1, 1] - corners[..., 1],
            ]
        ).min(1)
        return np.minimum(d, inside)

    return margin


def _arm_margin(robot, world, pad):
    b = np.asarray(world.boxes, np.float64)
    boxes = shapely.box(b[:, 0] - b[:, 2], b[:, 1] - b[:, 3], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3])
    bounds = np.asarray(world.bounds, np.float64)

    def margin(states):
        phi = np.cumsum(states, 1)
        L = np.asarray(robot.link_lengths)
        x = robot.base[0] + np.concatenate(
            [np.zeros((len(states), 1)), np.cumsum(L * np.cos(phi), 1)], 1
        )
        y = robot.base[1] + np.concatenate(
            [np.zeros((len(states), 1)), np.cumsum(L * np.sin(phi), 1)], 1
        )
        segs = np.stack(
            [np.stack([x[:, :-1], y[:, :-1]], -1), np.stack([x[:, 1:], y[:, 1:]], -1)], 2
        )
        d = shapely.distance(shapely.linestrings(segs.reshape(-1, 2, 2))[:, None], boxes[None])
        d = d.min(1).reshape(len(states), -1).min(1) - pad
        inside = np.minimum.reduce(
            [x - bounds[0, 0], bounds[0, 1] - x, y - bounds[1, 0], bounds[1, 1] - y]
        ).min(1)
        return np.minimum(d, inside)  # interpolated joints stay within the endpoints' limits

    return margin


@pytest.mark.parametrize("name", ["rigid/1", "nlink/2"])
def test_nontrivial_queries_of_discretised_robots_are_blocked(name):
    env = nj.make_env(name)
    assert not env.world.discs.size  # the oracles below model boxes only
    make = _rect_margin if env.robot.kind == "rigid_body" else _arm_margin
    oracle = make(env.robot, env.world, env.padding)
    q, kind = env.sample_queries(jax.random.PRNGKey(11), 120, p_nt=1.0, n_max=2)
    assert set(np.unique(kind)) <= {nj.NON_TRIVIAL, nj.NT_EXHAUSTED}
    assert (kind == nj.NT_EXHAUSTED).any() and (kind == nj.NON_TRIVIAL).any()
    assert (oracle(q.reshape(-1, env.dim).astype(np.float64)) > 0).all()
    blocked, certain = _discretized_blocked(env.robot, q, oracle)
    assert certain.mean() > 0.95
    nt = kind == nj.NON_TRIVIAL
    assert (blocked[certain & nt]).all(), "a non-trivial query passes the independent check"
    assert (~blocked[certain & ~nt]).all(), "an exhausted query fails the independent check"


# ---------------------------------------------------------------------------
# (d) the p_nt mixture of Alg. 2
# ---------------------------------------------------------------------------


def test_sample_queries_kinds_follow_p_nt():
    n, p_nt = 3000, 0.3
    q, kind = Q.sample_queries(ROBOT, WORLD, jax.random.PRNGKey(21), n, p_nt, PAD)
    assert q.shape == (n, 2, 2) and kind.dtype == np.int8
    assert set(np.unique(kind)) <= {Q.UNIFORM, Q.NON_TRIVIAL, Q.NT_EXHAUSTED}
    k = int((kind != Q.UNIFORM).sum())
    assert stats.binomtest(k, n, p_nt).pvalue > P_MIN
    assert ORACLE.valid(q.reshape(-1, 2)).all()
    # the uniform part is uniform, the non-trivial part blocked
    uni = q[kind == Q.UNIFORM]
    assert_same_distribution(
        uni, brute_force_uniform(np.random.default_rng(9), len(uni)), "uniform part"
    )
    nt = q[kind == Q.NON_TRIVIAL]
    margin = ORACLE.segment_margin(nt[:, 0], nt[:, 1])
    assert (margin[np.abs(margin) > BAND] < 0).all()
    # 300 queries: a size test_samplers_and_gamma_compile_once (and test_envs.py) samples too,
    # so the mixture's draw (jax.random.uniform, compiled per n) is shared
    _, kind0 = Q.sample_queries(ROBOT, WORLD, jax.random.PRNGKey(22), 300, 0.0, PAD)
    _, kind1 = Q.sample_queries(ROBOT, WORLD, jax.random.PRNGKey(22), 300, 1.0, PAD)
    assert (kind0 == Q.UNIFORM).all() and (kind1 != Q.UNIFORM).all()


@pytest.mark.parametrize("p_nt", [-0.1, 1.0001, 2.0, float("nan"), float("inf")])
def test_p_nt_outside_unit_interval_raises(p_nt):
    with pytest.raises(ValueError, match="p_nt"):
        Q.sample_queries(ROBOT, WORLD, jax.random.PRNGKey(0), 10, p_nt, PAD)
    with pytest.raises(ValueError, match="p_nt"):
        ENV.sample_queries(jax.random.PRNGKey(0), 10, p_nt=p_nt)


# ---------------------------------------------------------------------------
# (e) determinism and stream extension
# ---------------------------------------------------------------------------


def test_same_key_same_queries_and_more_queries_extend_the_stream():
    key = jax.random.PRNGKey(31)
    # n = N_STAT (3000): the size test_sample_queries_kinds_follow_p_nt samples, so the
    # mixture's draw (jax.random.uniform, compiled per n) is shared; its uniform and
    # non-trivial parts still fit in the first state and query blocks, which n = 9000 crosses
    n = N_STAT
    q1, k1 = ENV.sample_queries(key, n, p_nt=0.5)
    q2, k2 = ENV.sample_queries(key, n, p_nt=0.5)
    assert np.array_equal(q1, q2) and np.array_equal(k1, k2)
    q3, k3 = ENV.sample_queries(key, 9000, p_nt=0.5)  # crosses state and query block boundaries
    assert np.array_equal(q3[:n], q1) and np.array_equal(k3[:n], k1)
    q4, _ = ENV.sample_queries(jax.random.PRNGKey(32), n, p_nt=0.5)
    assert not np.array_equal(q4, q1)
    for f in (Q.sample_states, Q.sample_uniform_queries):
        a = f(ROBOT, WORLD, key, 50, PAD)
        b = f(ROBOT, WORLD, key, 20_000, PAD)
        assert np.array_equal(a, b[:50]) and np.array_equal(a, f(ROBOT, WORLD, key, 50, PAD))
    a, ax = Q.sample_nontrivial_queries(ROBOT, WORLD, key, 10, PAD, n_max=3)
    b, bx = Q.sample_nontrivial_queries(ROBOT, WORLD, key, 5000, PAD, n_max=3)
    assert np.array_equal(a, b[:10]) and np.array_equal(ax, bx[:10])


# ---------------------------------------------------------------------------
# (f) gamma_nt and the Wilson interval
# ---------------------------------------------------------------------------


def test_gamma_nt_agrees_with_brute_force_monte_carlo(gamma_ref):
    n = 1_000_000
    est = ENV.gamma_nt(jax.random.PRNGKey(41), n)
    assert est.queries == n and 0 <= est.non_trivial <= n and est.candidates >= n
    assert est.gamma == est.non_trivial / n
    assert est.ci95 == wilson_interval(est.non_trivial, n)
    g, sd_g = gamma_ref
    sd = math.sqrt(est.gamma * (1 - est.gamma) / n + sd_g**2)
    assert abs(est.gamma - g) < 4 * sd, (est.gamma, g, sd)
    lo, hi = est.ci95
    assert lo <= est.gamma <= hi and hi - lo < 0.003


def test_gamma_nt_counts_exactly_n_queries():
    key = jax.random.PRNGKey(42)
    chunk = 1024  # small chunks: n below crosses many chunk boundaries
    seen = []
    prev = None
    for n in [1, 2, 3, 500, 501, 999, 1000, 1001, 2047, 2048, 2049, 5000]:
        est = ENV.gamma_nt(key, n, chunk=chunk, progress=seen.append)
        assert est.queries == n
        assert seen[-1] == n
        if prev is not None:
            # the same stream, counted one prefix further: at most (n - n_prev) more blocked
            assert 0 <= est.non_trivial - prev.non_trivial <= n - prev.queries
            assert est.candidates >= prev.candidates
        prev = est
    # consecutive n differ by exactly the outcome of one query
    ests = [ENV.gamma_nt(key, n, chunk=chunk).non_trivial for n in range(1020, 1030)]
    assert all(d in (0, 1) for d in np.diff(ests))
    # and n = 1 .. 8 reproduce the outcomes of the first 8 valid candidate pairs
    firsts = [ENV.gamma_nt(key, n, chunk=chunk).non_trivial for n in range(1, 9)]
    assert all(d in (0, 1) for d in np.diff([0] + firsts))
    with pytest.raises(ValueError):
        ENV.gamma_nt(key, 0)


def test_gamma_nt_small_n_read_lane_by_lane_equals_whole_chunks(monkeypatch):
    """The first rows of chunk 0 read lane by lane (a small ``n``) give exactly the counts
    of the whole-chunk path, and a run they cannot finish falls back to it unchanged."""
    key = jax.random.PRNGKey(7)
    chunk = 4096  # rows of 64 lanes: the lane-by-lane path takes n <= 256
    ns = [1, 2, 63, 64, 65, 200, 256, 257, 1000]
    small = [ENV.gamma_nt(key, n, chunk=chunk) for n in ns]
    monkeypatch.setattr(G, "SMALL_ROWS", 0)  # whole chunks only
    whole = [ENV.gamma_nt(key, n, chunk=chunk) for n in ns]
    for n, a, b in zip(ns, small, whole):
        assert (a.queries, a.non_trivial, a.candidates) == (
            b.queries,
            b.non_trivial,
            b.candidates,
        ), n
    # rows too few for n: the lane-by-lane attempt gives up and whole chunks count it
    monkeypatch.setattr(G, "SMALL_ROWS", 8)
    assert G._small_estimate(ROBOT, WORLD, prng.stream_seeds(key, 0), PAD, chunk, 10**6) is None
    # (no padding: the lane program test_free_space_too_small_is_raised runs on its one-box
    # map; the 0.4-wide free border holds ~12 valid pairs among those 512 lanes, not 250)
    nearly_empty = World.create(BOUNDS, np.array([[5.0, 5.0, 4.6, 4.6]]), np.zeros((0, 3)))
    assert (
        G._small_estimate(ROBOT, nearly_empty, prng.stream_seeds(key, 0), 0.0, chunk, 250) is None
    )


@pytest.mark.parametrize(
    "k, n",
    [
        (0, 1),
        (1, 1),
        (0, 10),
        (3, 10),
        (10, 10),
        (1, 1000),
        (500, 1000),
        (311_000, 1_000_000),
        (7, 10**9),
    ],
)
def test_wilson_interval_matches_scipy_and_the_textbook(k, n):
    lo, hi = wilson_interval(k, n)
    ref = stats.binomtest(k, n).proportion_ci(0.95, method="wilson")
    assert lo == pytest.approx(ref.low, rel=1e-9, abs=1e-12)
    assert hi == pytest.approx(ref.high, rel=1e-9, abs=1e-12)
    # textbook: (p + z^2/2n +- z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)
    z, p = stats.norm.ppf(0.975), k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert lo == pytest.approx(max(0.0, c - h), rel=1e-9, abs=1e-12)
    assert hi == pytest.approx(min(1.0, c + h), rel=1e-9, abs=1e-12)
    assert 0.0 <= lo <= p + 1e-12 and p - 1e-12 <= hi <= 1.0


# ---------------------------------------------------------------------------
# (g) a fully covered map
# ---------------------------------------------------------------------------


def test_free_space_too_small_is_raised():
    world = World.create(BOUNDS, [[5.0, 5.0, 5.0, 5.0]])  # the box covers the whole map
    key = jax.random.PRNGKey(0)
    with pytest.raises(nj.FreeSpaceTooSmall, match="padding"):
        Q.sample_states(ROBOT, world, key, 1, 0.0)
    with pytest.raises(nj.FreeSpaceTooSmall):  # 300: a size sampled above (one mixture draw)
        Q.sample_queries(ROBOT, world, key, 300, 0.5, 0.0)
    with pytest.raises(nj.FreeSpaceTooSmall):
        Q.sample_nontrivial_queries(ROBOT, world, key, 5, 0.0)
    with pytest.raises(nj.FreeSpaceTooSmall):
        G.gamma_nt(ROBOT, world, key, 10, 0.0, chunk=4096)
    assert issubclass(nj.FreeSpaceTooSmall, ValueError)
    # free space that the padding closes: fine without padding, an error with it
    world = World.create(BOUNDS, [[5.0, 5.0, 4.9, 4.9]])
    assert len(Q.sample_states(ROBOT, world, key, 3, 0.0)) == 3
    with pytest.raises(nj.FreeSpaceTooSmall):
        Q.sample_states(ROBOT, world, key, 3, 0.2)


# ---------------------------------------------------------------------------
# (h) compilation happens once per shape
# ---------------------------------------------------------------------------

TRACES = collections.Counter()


@dataclasses.dataclass(frozen=True)
class TracedPoint(PointRobot):
    """A point robot whose kernels count how often JAX traces them (a Python side effect)."""

    def is_valid(self, q, world, padding):
        TRACES["is_valid"] += 1
        return super().is_valid(q, world, padding)

    def steer_to(self, a, b, world, padding):
        TRACES["steer_to"] += 1
        return super().steer_to(a, b, world, padding)


def _world(seed):
    rng = np.random.default_rng(seed)
    boxes = np.concatenate([rng.uniform(2, 8, (3, 2)), rng.uniform(0.2, 1, (3, 2))], 1)
    discs = np.concatenate([rng.uniform(2, 8, (2, 2)), rng.uniform(0.2, 1, (2, 1))], 1)
    return World.create(BOUNDS, boxes, discs)


def test_batch_kernels_compile_once_per_shape():
    robot = TracedPoint()
    TRACES.clear()
    rng = np.random.default_rng(0)
    for i in range(4):
        world = _world(i)  # a new map with the same obstacle counts
        # 1024 rows (one bucket): Env's is_valid runs the direct call's program, its
        # steer_to the masked program of steer_to_pairs (one more trace)
        a = jnp.asarray(rng.uniform(0, 10, (1024, 2)), jnp.float32)
        b = jnp.asarray(rng.uniform(0, 10, (1024, 2)), jnp.float32)
        steer_to_batch(robot, world, a, b, 0.3)
        is_valid_batch(robot, world, a, 0.3)
        env = nj.Env("traced", robot, world, 0.3)
        env.steer_to(np.asarray(a), np.asarray(b))
        env.is_valid(np.asarray(a))
    assert TRACES == {"steer_to": 2, "is_valid": 1}
    # a new shape (or padding) compiles again, once
    steer_to_batch(robot, _world(9), a[:10], b[:10], 0.3)
    steer_to_batch(robot, _world(9), a[:10], b[:10], 0.3)
    assert TRACES["steer_to"] == 3
    # Env: one program per size class (100 and 112 share the bucket of 112 rows, 8100 and
    # 8192 the bucket of 8192: steer_to_pairs' chunk)
    env = nj.Env("traced", robot, _world(9), 0.3)
    for n in (100, 112, 8100, 8192):
        env.steer_to(np.asarray(a[:1])[[0] * n], np.asarray(b[:1])[[0] * n])
    assert TRACES["steer_to"] == 5


def test_samplers_and_gamma_compile_once():
    robot = TracedPoint()
    key = jax.random.PRNGKey(0)
    Q.sample_queries(robot, _world(0), key, 300, 0.5, 0.3, n_max=3)
    G.gamma_nt(robot, _world(0), key, 5000, 0.3, chunk=4096)
    before = TRACES.copy()
    # other sizes than the first call's, ones other tests here sample (the mixture's
    # jax.random.uniform draw, not a robot kernel, compiles per n: those programs are shared)
    for i, n in zip(range(1, 4), (120, N_STAT, 9000)):
        Q.sample_queries(robot, _world(i), jax.random.PRNGKey(i), n, 0.5, 0.3, n_max=3)
        G.gamma_nt(robot, _world(i), jax.random.PRNGKey(i), 5000 * i, 0.3, chunk=4096)
    assert TRACES == before
