"""The verdict test of REPRODUCTION.md: training seeds as a random effect (ntq_jax.stats),
its coverage by simulation on synthetic data with a known effect and a known spread
between seeds (ntq_jax.experiment.coverage; the full study is
benchmarks/seed_test_coverage.py), the multiplicity corrections and the stratified trend
test."""

import itertools
import math

import numpy as np
import pytest
from scipy.stats import kendalltau
from scipy.stats import t as student_t

from ntq_jax import stats as S
from ntq_jax.experiment import coverage as C

# ---------------------------------------------------------------------------
# Multiplicity
# ---------------------------------------------------------------------------


def test_holm_and_benjamini_hochberg_by_hand():
    p = [0.01, 0.04, 0.03, float("nan"), 0.5]
    # Holm, m = 4: 4 x 0.01, max(0.04, 3 x 0.03), max(0.09, 2 x 0.04), 0.5
    assert S.holm(p)[[0, 1, 2, 4]] == pytest.approx([0.04, 0.09, 0.09, 0.5])
    # BH: 0.01 x 4 / 1, min(0.03 x 4 / 2, 0.04 x 4 / 3), 0.04 x 4 / 3, 0.5 x 4 / 4
    assert S.benjamini_hochberg(p)[[0, 1, 2, 4]] == pytest.approx([0.04, 0.16 / 3, 0.16 / 3, 0.5])
    assert np.isnan(S.holm(p)[3]) and np.isnan(S.benjamini_hochberg(p)[3])
    assert S.holm([]).size == 0 and S.holm([0.9, 0.95]).max() <= 1.0
    with pytest.raises(ValueError):
        S.holm([1.5])


# ---------------------------------------------------------------------------
# The seed-aware estimate
# ---------------------------------------------------------------------------


def test_seed_estimate_adds_the_between_seed_variance_to_the_shared_query_variance():
    x, v = [0.096, 0.052, 0.060], [4e-4, 3e-4, 5e-4]
    e = S.seed_estimate(x, v, key="m")
    s2 = np.var(x, ddof=1)
    assert e.estimate == pytest.approx(np.mean(x)) and e.seeds == 3
    assert e.variance == pytest.approx(s2 / 3 + np.mean(v))  # the query term not divided by S
    assert e.spread == pytest.approx(math.sqrt(s2))
    assert e.seed_part == pytest.approx((s2 / 3, 2))
    # Satterthwaite: the query term is known (df inf), so df = V^2 / ((s2/3)^2 / 2)
    assert e.df == pytest.approx(e.variance**2 / ((s2 / 3) ** 2 / 2))
    lo, hi = e.ci()
    half = max(student_t.ppf(0.975, e.df) * e.se, student_t.ppf(0.975, 2) * math.sqrt(s2 / 3))
    assert (lo, hi) == pytest.approx((e.estimate - half, e.estimate + half))
    # the p-value matches the interval: 0.05 at either end
    assert e.p(lo) == pytest.approx(0.05) and e.p(hi) == pytest.approx(0.05)
    assert e.p(e.estimate) == 1.0


def test_one_seed_borrows_the_spread_and_maps_combine():
    alone = S.seed_estimate([0.05], [4e-4])
    assert alone.variance == pytest.approx(4e-4) and alone.df == math.inf and not alone.borrowed
    borrow = S.pooled_spread([[0.01, 0.03, 0.05], [0.10, 0.12], [0.5]], "task")
    s2_a, s2_b = np.var([0.01, 0.03, 0.05], ddof=1), np.var([0.10, 0.12], ddof=1)
    assert borrow[0] == pytest.approx((2 * s2_a + s2_b) / 3) and borrow[1:] == (3, "task")
    e = S.seed_estimate([0.05], [4e-4], borrow=borrow)
    assert e.borrowed and e.variance == pytest.approx(4e-4 + borrow[0])
    assert S.pooled_spread([[0.1], [0.2]]) is None
    # the mean of two maps that borrow the same spread: the borrowed term counts once in df
    f = S.seed_estimate([0.02], [4e-4], borrow=borrow)
    m = S.combine([e, f])
    assert m.estimate == pytest.approx(0.035)
    assert m.variance == pytest.approx((e.variance + f.variance) / 4)
    vs, dfs = m.seed_part
    assert vs == pytest.approx(borrow[0] / 2) and dfs == pytest.approx(3)
    d = S.combine([e, f], [1, -1])
    assert d.estimate == pytest.approx(0.03)
    assert d.variance == pytest.approx(e.variance + f.variance)


def test_query_variances_keep_zero_counts_positive():
    assert S.proportion_variance(500, 500) > 0 and S.proportion_variance(0, 500) > 0
    assert S.proportion_variance(250, 500) == pytest.approx(0.25 / 500, rel=1e-2)
    # (b - c) / n with b = 60, c = 40 of 500: Var(D) = (b + c) / n - d^2
    assert S.paired_difference_variance(60, 40, 500) == pytest.approx(
        (0.2 - 0.04**2) / 500, rel=1e-2
    )
    assert S.paired_difference_variance(0, 0, 500) > 0
    assert math.isnan(S.proportion_variance(1, 0))


# ---------------------------------------------------------------------------
# Coverage by simulation (small; the full study: benchmarks/seed_test_coverage.py)
# ---------------------------------------------------------------------------


def test_the_true_effect_of_the_synthetic_model():
    sc = C.Scenario("t", seed_sd=0.35, model_query_sd=1.0, n=200)
    y3, y0 = C.simulate(sc, 400, np.random.default_rng(3))
    # the mean over 400 experiments x 3 seeds x 200 queries is the true effect
    assert float((y3.mean() - y0.mean())) == pytest.approx(C.true_effect(sc), abs=0.004)


def test_seed_aware_interval_covers_where_the_query_only_tests_do_not():
    """A known effect and a large spread between training seeds (PNet_0's success moves by
    about 0.07 between seeds, as ours does): the seed-aware 95 % interval holds the true
    effect in about 95 % or more of the experiments; McNemar's pairs pooled over the seeds
    and one seed's Newcombe interval, which ignore training, in about half."""
    sc = C.Scenario("large spread", seeds=3, seed_sd=0.35, model_query_sd=1.0)
    got = C.coverage(sc, 300, seed=1, methods=("seed_aware", "pooled_pairs", "one_seed"))
    assert got["seed_aware"]["coverage"] >= 0.93
    assert got["pooled_pairs"]["coverage"] < 0.75 and got["one_seed"]["coverage"] < 0.75
    # and with one seed whose spread is borrowed from two three-seed maps
    borrowed = C.coverage(C.Scenario("b", seeds=3, seed_sd=0.35, borrow_from=2), 200, seed=2)
    assert borrowed["seed_aware"]["coverage"] >= 0.92


# ---------------------------------------------------------------------------
# Kendall's trend within strata
# ---------------------------------------------------------------------------


def test_stratified_kendall_is_exact():
    x, y = [1, 2, 3, 4, 5], [2, 1, 4, 3, 5]
    tau, less, greater = S.stratified_kendall([(x, y)])
    assert tau == pytest.approx(kendalltau(x, y).statistic)
    assert less == pytest.approx(kendalltau(x, y, method="exact", alternative="less").pvalue)
    assert greater == pytest.approx(kendalltau(x, y, method="exact", alternative="greater").pvalue)
    # two strata by brute force over every pair of within-stratum permutations
    a, b = ([1, 2, 3, 4], [3, 1, 2, 4]), ([1, 2, 3], [3, 2, 1])
    tau, less, greater = S.stratified_kendall([a, b])

    def s_of(xs, ys):
        return sum(
            np.sign(xs[i] - xs[j]) * np.sign(ys[i] - ys[j])
            for i, j in itertools.combinations(range(len(xs)), 2)
        )

    obs = s_of(*a) + s_of(*b)
    null = [
        s_of(a[0], pa) + s_of(b[0], pb)
        for pa in itertools.permutations(a[1])
        for pb in itertools.permutations(b[1])
    ]
    assert tau == pytest.approx(obs / 9)
    assert less == pytest.approx(np.mean([s <= obs for s in null]))
    assert greater == pytest.approx(np.mean([s >= obs for s in null]))
    # the smallest p of 4 + 4 + 3 points in perfect order: 1 / (4! 4! 3!)
    _, p, _ = S.stratified_kendall([([1, 2, 3, 4], [4, 3, 2, 1])] * 2 + [([1, 2, 3], [3, 2, 1])])
    assert p == pytest.approx(1 / 3456)
