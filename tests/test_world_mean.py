"""The mean over a family of worlds (ntq_jax.world_mean): the formula on a hand-computed
case, its limits (every world measured, an unbounded family, one world), the refusals,
and the interval's coverage in seeded two-stage simulations (worlds drawn without
replacement from a finite family, binomial queries within each)."""

import math

import numpy as np
import pytest
from scipy import stats as st

from ntq_jax.world_mean import world_mean


def test_by_hand():
    k, m = [10, 30, 20], [100, 100, 100]
    r = world_mean(k, m, population=6)
    p = np.array([0.1, 0.3, 0.2])
    between = (1 - 0.5) * 0.01 / 3  # s^2 = 0.01
    within = 0.5 * sum(p * (1 - p) / 99) / 9
    v = between + within
    df = v * v / (between * between / 2)
    h = st.t.ppf(0.975, df) * math.sqrt(v)
    assert r.mean == pytest.approx(0.2) and r.spread == pytest.approx(0.1)
    assert r.df == pytest.approx(df) and r.ci95 == pytest.approx((0.2 - h, 0.2 + h))
    assert (r.worlds, r.population) == (3, 6)


def test_limits():
    k, m = [10, 30, 20], [100, 100, 100]
    # every world measured: the query term alone, normal quantile
    full = world_mean(k, m, population=3)
    p = np.array([0.1, 0.3, 0.2])
    h = 1.959963984540054 * math.sqrt(sum(p * (1 - p) / 99) / 9)
    assert math.isinf(full.df) and full.ci95 == pytest.approx((0.2 - h, 0.2 + h))
    # unbounded family: Student's t on s^2 / n with n - 1 df
    free = world_mean(k, m)
    h = st.t.ppf(0.975, 2) * 0.1 / math.sqrt(3)
    assert h > 0.2  # t on 2 df: the interval is clipped at 0, a mean of ratios
    assert free.df == pytest.approx(2) and free.ci95 == pytest.approx((0.0, 0.2 + h))
    assert free.ci95[1] - free.ci95[0] > full.ci95[1] - full.ci95[0]
    # one world of several has no interval; one world that is the whole family has one
    assert world_mean([5], [10], population=4).ci95 is None
    assert world_mean([5], [10]).ci95 is None
    one = world_mean([5], [10], population=1)
    assert math.isnan(one.spread) and one.ci95[0] < 0.5 < one.ci95[1]


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        (([], []), {}, "one hit count"),
        (([1, 2], [10]), {}, "one hit count"),
        (([1], [1]), {}, ">= 2 queries"),
        (([11], [10]), {}, ">= 2 queries"),
        (([-1], [10]), {}, ">= 2 queries"),
        (([1, 2, 3], [10, 10, 10]), {"population": 2}, "population"),
        (([1, 2], [10, 10]), {"confidence": 1.0}, "confidence"),
    ],
)
def test_refusals(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        world_mean(*args, **kwargs)


@pytest.mark.parametrize("n", [5, 20, 40])
def test_coverage_of_the_family_mean(n):
    """2,000 seeded two-stage samples of a family of 40 worlds: the 95 % interval holds the
    family's true mean in 93-97 % of them, whether few, many or all worlds are measured."""
    rng = np.random.default_rng(7 + n)
    big, m, reps = 40, 2000, 2000
    truth_p = rng.beta(4, 12, size=big)  # spread of the worlds' gamma_nt like a scene's
    truth = truth_p.mean()
    hit = 0
    for _ in range(reps):
        pick = rng.choice(big, size=n, replace=False)
        k = rng.binomial(m, truth_p[pick])
        lo, hi = world_mean(k, np.full(n, m), population=big).ci95
        hit += lo <= truth <= hi
    assert 0.93 <= hit / reps <= 0.97, hit / reps


@pytest.mark.parametrize("n", [10, 40])
def test_worlds_on_one_query_stream(n):
    """Worlds measured on one query stream (the same seed) share their query errors: with
    the same uniforms deciding every world's queries, the independent-queries interval of
    all 40 worlds misses the family's mean far more often than 5 %, and
    ``shared_queries=True`` covers it (1,000 seeded samples each)."""
    rng = np.random.default_rng(11 + n)
    big, m, reps = 40, 2000, 1000
    truth_p = rng.beta(4, 12, size=big)
    hit = {False: 0, True: 0}
    for _ in range(reps):
        pick = rng.choice(big, size=n, replace=False)
        u = rng.random(m)  # one stream: query j is blocked in world i when u_j < p_i
        k = (u[None, :] < truth_p[pick, None]).sum(1)
        for shared in hit:
            lo, hi = world_mean(k, np.full(n, m), population=big, shared_queries=shared).ci95
            hit[shared] += lo <= truth_p.mean() <= hi
    # all worlds measured: only the query term is left, and only its bound covers; a part
    # of them: the between-worlds term dominates (t on a skewed family of 40: ~0.93-0.95)
    assert hit[True] / reps >= (0.95 if n == big else 0.92), hit
    if n == big:
        assert hit[False] / reps < 0.6, hit
