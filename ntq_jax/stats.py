"""Statistics of success ratios: one interval, paired and unpaired tests.

* one proportion: :func:`wilson_interval`, the Wilson score interval of ``k / n``
  (gamma_nt, success ratios);
* two proportions on different queries: :func:`fisher_exact_p`;
* a trend over maps: :func:`kendall_tau`.

Paired comparisons of two planners tested on the same queries:

Every model of a run is evaluated on the same test queries (per environment,
query kind and steerTo variant), so two models are compared query by query:

* success: :func:`mcnemar_exact`, McNemar's exact test (two-sided), the exact
  binomial test of the discordant pairs (``b`` queries only model A solves,
  ``c`` only model B solves) against 1/2; and :func:`paired_success_difference`,
  the difference of success ratios ``(b - c) / n`` with Newcombe's hybrid score
  interval for paired proportions (Newcombe 1998, method 10: the Wilson
  intervals of the two success ratios combined with the correlation of the
  pairs; the form of Altman et al., *Statistics with Confidence*, 2000, and of
  Fagerland, Lydersen & Laake, *Statistical Analysis of Contingency Tables*, 2017);
* cost, over the queries both solve: :func:`paired_cost_difference`, the mean
  paired difference (A - B) of the per-query cost ratios with a percentile
  paired bootstrap interval over queries (fixed seed, vectorised resampling)
  and :func:`wilcoxon_p`, the two-sided Wilcoxon signed-rank p-value.

:func:`paired_comparison` does all of it from the per-query arrays of two
models (as saved in the run's paths files, :mod:`ntq_jax.experiment.evaluate`).

Training seeds as a random effect (the verdicts of ``REPRODUCTION.md``): the
same test queries are planned by the PNets of S trainings of the same data
(training seeds), and a difference measured on one training moves with the
training. :func:`seed_estimate` treats the training seed as a random effect:
the estimate is the mean of the S per-seed values ``x_s`` (e.g. each seed's
paired success difference on the same n queries), and its variance

    V = s^2 / S + mean_s(v_s)

adds the between-seed term (``s^2``: the sample variance of the ``x_s``, S - 1
degrees of freedom) and the query term (``v_s``: the variance of ``x_s`` over the
test queries, :func:`proportion_variance`, :func:`paired_difference_variance`).
The query term is not divided by S because the seeds share their test queries: a
query that favours one model does so in every seed, and that part of the error
does not average out over seeds. It also holds each seed's own query noise, which
``s^2`` already counts, so V is conservative by at most that term (measured in
``results/paper/seed_test_coverage.md``). The interval is the wider of Student's t
on V with Satterthwaite's degrees of freedom and Student's t on the between-seed
term alone with its own S - 1 degrees of freedom (:class:`SeedEstimate`: the
first alone undercovers when two or three seeds differ a lot); with one seed the
between-seed variance is borrowed from other maps (:func:`pooled_spread`).
:func:`combine` adds estimates of independent maps (a mean over maps, the
difference of two maps). :func:`holm` and :func:`benjamini_hochberg` adjust a
family of p-values for multiplicity; :func:`stratified_kendall` is Kendall's
trend test within strata (robots), combined exactly.

Only NumPy and SciPy (``scipy.stats``, imported on first use); no JAX.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import warnings

import numpy as np

__all__ = ["wilson_interval", "fisher_exact_p", "kendall_tau", "mcnemar_exact",
           "paired_success_difference", "paired_cost_difference",
           "wilcoxon_p", "paired_comparison", "N_BOOT", "SEED", "holm", "benjamini_hochberg",
           "proportion_variance", "paired_difference_variance", "SeedEstimate", "seed_estimate",
           "pooled_spread", "combine", "stratified_kendall"]

N_BOOT = 10_000  #: bootstrap resamples of the cost difference
SEED = 0  #: bootstrap seed (results are deterministic per seed)
_MAX_DRAWS = 1 << 22  # resample indices drawn per chunk (memory bound of the bootstrap)


def _z(confidence: float) -> float:
    from scipy import stats as _st
    return float(_st.norm.ppf(0.5 + confidence / 2))


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (95 % at the default ``z``).

    Returns ``(lo, hi)`` clipped to ``[0, 1]``; ``(0.0, 1.0)`` when ``n <= 0``.
    """
    if n <= 0:
        return (0.0, 1.0)
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (max(0.0, centre - half), min(1.0, centre + half))


def fisher_exact_p(sa: int, na: int, sb: int, nb: int) -> float:
    """Two-sided Fisher exact p-value of ``sa / na`` against ``sb / nb`` (independent samples)."""
    from scipy.stats import fisher_exact
    return float(fisher_exact([[sa, na - sa], [sb, nb - sb]]).pvalue)


def kendall_tau(x, y) -> tuple[float, float, float]:
    """Kendall's tau of ``x, y`` and its one-sided p-values ``(tau, p(tau < 0), p(tau > 0))``.

    Exact when neither ``x`` nor ``y`` has ties, SciPy's ``auto`` otherwise.
    """
    from scipy.stats import kendalltau
    method = "exact" if len(set(x)) == len(x) and len(set(y)) == len(y) else "auto"
    lo = kendalltau(x, y, method=method, alternative="less")
    hi = kendalltau(x, y, method=method, alternative="greater")
    return float(lo.statistic), float(lo.pvalue), float(hi.pvalue)


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided p-value of McNemar's exact test for ``b`` and ``c`` discordant pairs.

    The exact binomial test of ``b`` successes in ``b + c`` trials at 1/2
    (``scipy.stats.binomtest``). No discordant pair (``b = c = 0``): no evidence
    of a difference, p = 1.
    """
    b, c = int(b), int(c)
    if b < 0 or c < 0:
        raise ValueError(f"discordant counts must be >= 0, got b={b}, c={c}")
    if b + c == 0:
        return 1.0
    from scipy import stats as _st
    return float(_st.binomtest(b, b + c, 0.5).pvalue)


def paired_success_difference(success_a, success_b, confidence: float = 0.95) -> dict:
    """Difference of the success ratios of two models on the same queries, with its interval.

    Newcombe's hybrid score interval for the difference of paired proportions
    (Newcombe 1998, method 10): with ``a`` queries both solve, ``b`` only A,
    ``c`` only B, ``d`` neither (``n`` in all), ``p1 = (a + b) / n``,
    ``p2 = (a + c) / n`` and their Wilson intervals ``[l1, u1]``, ``[l2, u2]``,
    the interval of ``D = p1 - p2`` is::

        [D - sqrt((p1 - l1)^2 - 2 phi (p1 - l1)(u2 - p2) + (u2 - p2)^2),
         D + sqrt((p2 - l2)^2 - 2 phi (p2 - l2)(u1 - p1) + (u1 - p1)^2)]

    where ``phi`` is the correlation of the pairs, ``(a d - b c) / sqrt((a+b)(c+d)(a+c)(b+d))``
    with ``a d - b c`` replaced by ``max(a d - b c - n / 2, 0)`` when positive
    (0 when a margin is empty).

    Args:
        success_a, success_b: ``(n,)`` bool, per query, in the same query order.
        confidence: the interval's level.

    Returns:
        ``n``, ``both`` (a), ``only_a`` (b), ``only_b`` (c), ``neither`` (d),
        ``diff`` (``p1 - p2``, NaN for ``n = 0``) and ``ci`` ``[lo, hi]``
        (NaN for ``n = 0``).
    """
    sa, sb = np.asarray(success_a, bool), np.asarray(success_b, bool)
    if sa.shape != sb.shape or sa.ndim != 1:
        raise ValueError(f"success arrays must be paired 1-D arrays, got {sa.shape} and {sb.shape}")
    a, b = int(np.sum(sa & sb)), int(np.sum(sa & ~sb))
    c, d = int(np.sum(~sa & sb)), int(np.sum(~sa & ~sb))
    n = a + b + c + d
    out = {"n": n, "both": a, "only_a": b, "only_b": c, "neither": d}
    if n == 0:
        return {**out, "diff": float("nan"), "ci": [float("nan"), float("nan")]}
    z = _z(confidence)
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = wilson_interval(a + b, n, z)
    l2, u2 = wilson_interval(a + c, n, z)
    margins = float(a + b) * (c + d) * (a + c) * (b + d)
    num = float(a * d - b * c)
    num = max(num - n / 2, 0.0) if num > 0 else num
    phi = num / math.sqrt(margins) if margins > 0 else 0.0
    diff = p1 - p2
    lo = diff - math.sqrt(max((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2, 0))
    hi = diff + math.sqrt(max((p2 - l2) ** 2 - 2 * phi * (p2 - l2) * (u1 - p1) + (u1 - p1) ** 2, 0))
    return {**out, "diff": diff, "ci": [max(-1.0, lo), min(1.0, hi)]}


def paired_cost_difference(x, y, *, n_boot: int = N_BOOT, seed: int = SEED,
                           confidence: float = 0.95) -> dict:
    """Mean paired difference ``mean(x - y)`` with a percentile paired bootstrap interval.

    The ``n`` query pairs are resampled with replacement ``n_boot`` times
    (``numpy.random.default_rng(seed)``, vectorised, in chunks of at most a few
    million indices; the chunking depends only on ``n`` and ``n_boot``, so the
    result is deterministic per seed); the interval is the ``(1 - confidence) / 2``
    and ``(1 + confidence) / 2`` quantiles of the resampled means.

    Args:
        x, y: ``(n,)`` finite floats, paired (e.g. the cost ratios of two models
            on the queries both solve).
        n_boot: bootstrap resamples.
        seed: the generator's seed.
        confidence: the interval's level.

    Returns:
        ``n``, ``diff`` (NaN for ``n = 0``) and ``ci`` ``[lo, hi]`` (NaN for
        ``n < 2``: one pair has no spread to resample).
    """
    d = np.asarray(x, np.float64) - np.asarray(y, np.float64)
    if d.ndim != 1:
        raise ValueError(f"paired arrays must be 1-D, got shape {d.shape}")
    n = int(d.size)
    nan = float("nan")
    if n == 0:
        return {"n": 0, "diff": nan, "ci": [nan, nan]}
    diff = float(d.mean())
    if n < 2:
        return {"n": n, "diff": diff, "ci": [nan, nan]}
    rng = np.random.default_rng(seed)
    per = max(1, _MAX_DRAWS // n)
    means = np.empty(n_boot)
    for s in range(0, n_boot, per):
        k = min(per, n_boot - s)
        means[s:s + k] = d[rng.integers(0, n, size=(k, n), dtype=np.int32)].mean(axis=1)
    alpha = (1 - confidence) / 2
    lo, hi = np.quantile(means, [alpha, 1 - alpha])
    return {"n": n, "diff": diff, "ci": [float(lo), float(hi)]}


#: Pairs up to which scipy's ``wilcoxon`` (``method="auto"``) takes, when there are zeros or
#: ties, the exact permutation test over all ``2**n`` sign flips; :func:`wilcoxon_p`
#: computes that same test itself, in one vectorised pass (scipy's is about a second a call).
EXACT_SIGN_FLIPS_MAX = 13


def _sign_flip_p(nz: np.ndarray) -> float:
    """Two-sided p-value of the signed-rank sum ``R+`` of the non-zero differences ``nz``
    over all ``2**m`` sign flips (average ranks for ties): ``min(1, 2 min(P(R+ <= r),
    P(R+ >= r)))``, with scipy's ``permutation_test`` relative tolerance of ``100 eps``.
    Zero differences carry no rank, so flipping them leaves every proportion unchanged."""
    from scipy.stats import rankdata

    ranks = rankdata(np.abs(nz), method="average")
    observed = float(ranks[nz > 0].sum())
    m = nz.size
    signs = (np.arange(1 << m)[:, None] >> np.arange(m)[None, :]) & 1  # (2**m, m): 1 = positive
    null = signs @ ranks
    gamma = abs(np.finfo(np.float64).eps * 100 * observed)
    less = np.count_nonzero(null <= observed + gamma) / null.size
    greater = np.count_nonzero(null >= observed - gamma) / null.size
    return float(np.clip(2 * min(less, greater), 0.0, 1.0))


def wilcoxon_p(x, y) -> float:
    """Two-sided Wilcoxon signed-rank p-value of the pairs ``x - y`` (``scipy.stats.wilcoxon``).

    Zero differences are dropped (scipy's default ``zero_method="wilcox"``).
    NaN when fewer than 2 pairs or no non-zero difference (no test possible).
    """
    d = np.asarray(x, np.float64) - np.asarray(y, np.float64)
    if d.size < 2 or not np.any(d != 0):
        return float("nan")
    if d.ndim == 1 and d.size <= EXACT_SIGN_FLIPS_MAX and np.isfinite(d).all():
        nz = d[d != 0]
        if nz.size < d.size or np.unique(np.abs(nz)).size < nz.size:  # zeros or ties
            return _sign_flip_p(nz)
    try:
        with warnings.catch_warnings():  # scipy's small-sample / ties notes
            warnings.simplefilter("ignore")
            from scipy import stats as _st
            p = _st.wilcoxon(d).pvalue
    except ValueError:
        return float("nan")
    return float(p)


def paired_comparison(a: dict, b: dict, *, n_boot: int = N_BOOT, seed: int = SEED,
                      confidence: float = 0.95) -> dict:
    """Model A against model B on the same queries, from their per-query arrays.

    Args:
        a, b: per-query arrays of each model (a paths file of
            :mod:`ntq_jax.experiment.evaluate`): ``success`` (bool), ``costs`` and
            ``ref_costs`` (the reference planner's cost, NaN/inf/<= 0 when it
            failed); optionally ``ref_status`` (0 = solved) and ``queries``,
            which must then be equal in both.
        n_boot, seed, confidence: see :func:`paired_cost_difference`.

    Returns:
        A flat dict: ``n``, ``both``, ``only_a`` (McNemar's b), ``only_b`` (c),
        ``neither``, ``success_diff`` (A - B) and ``success_diff_ci95``
        (:func:`paired_success_difference`), ``mcnemar_p``
        (:func:`mcnemar_exact`); ``cost_n`` (queries both solve with a
        reference cost), ``cost_ratio_diff`` (mean of A's minus B's cost /
        reference cost; negative: A's paths are cheaper),
        ``cost_ratio_diff_ci95`` (paired bootstrap) and ``wilcoxon_p``.

    Raises:
        ValueError: the arrays are not paired (different lengths or queries).
    """
    sa, sb = np.asarray(a["success"], bool), np.asarray(b["success"], bool)
    if sa.shape != sb.shape:
        raise ValueError(f"not paired: {sa.shape[0] if sa.ndim else 0} and "
                         f"{sb.shape[0] if sb.ndim else 0} queries")
    if "queries" in a and "queries" in b and not np.array_equal(a["queries"], b["queries"]):
        raise ValueError("not paired: the two models were tested on different queries")
    s = paired_success_difference(sa, sb, confidence)
    ref = np.asarray(a["ref_costs"], np.float64)
    ok = np.isfinite(ref) & (ref > 0)
    if "ref_status" in a:
        ok &= np.asarray(a["ref_status"]) == 0
    both = sa & sb & ok
    ra = np.asarray(a["costs"], np.float64)[both] / ref[both]
    rb = np.asarray(b["costs"], np.float64)[both] / ref[both]
    cd = paired_cost_difference(ra, rb, n_boot=n_boot, seed=seed, confidence=confidence)
    return {"n": s["n"], "both": s["both"], "only_a": s["only_a"], "only_b": s["only_b"],
            "neither": s["neither"], "success_diff": s["diff"], "success_diff_ci95": s["ci"],
            "mcnemar_p": mcnemar_exact(s["only_a"], s["only_b"]),
            "cost_n": cd["n"], "cost_ratio_diff": cd["diff"], "cost_ratio_diff_ci95": cd["ci"],
            "wilcoxon_p": wilcoxon_p(ra, rb)}


# ---------------------------------------------------------------------------
# Multiplicity
# ---------------------------------------------------------------------------

def _finite_p(pvalues) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(pvalues, np.float64).reshape(-1)
    ok = np.isfinite(p)
    if np.any((p[ok] < 0) | (p[ok] > 1)):
        raise ValueError("p-values must lie in [0, 1]")
    return p, ok


def holm(pvalues) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error), in the input's order.

    With the m finite p-values sorted, ``p_(1) <= ... <= p_(m)``, the adjusted value of
    ``p_(j)`` is ``max_{i <= j} min(1, (m - i + 1) p_(i))``; rejecting where the adjusted
    p < alpha keeps the probability of any false rejection <= alpha under any dependence.
    NaN (no test) stays NaN and does not count in m.
    """
    p, ok = _finite_p(pvalues)
    out = np.full(p.shape, np.nan)
    m = int(ok.sum())
    if m:
        idx = np.flatnonzero(ok)[np.argsort(p[ok], kind="stable")]
        adj = np.minimum(1.0, (m - np.arange(m)) * p[idx])
        out[idx] = np.maximum.accumulate(adj)
    return out


def benjamini_hochberg(pvalues) -> np.ndarray:
    """Benjamini-Hochberg q-values (false-discovery rate), in the input's order.

    With the m finite p-values sorted, the q-value of ``p_(j)`` is
    ``min_{i >= j} min(1, m p_(i) / i)``; rejecting where q < alpha keeps the expected
    share of false rejections among the rejections <= alpha (independent or positively
    dependent tests). NaN stays NaN and does not count in m.
    """
    p, ok = _finite_p(pvalues)
    out = np.full(p.shape, np.nan)
    m = int(ok.sum())
    if m:
        idx = np.flatnonzero(ok)[np.argsort(p[ok], kind="stable")]
        q = p[idx] * m / np.arange(1, m + 1)
        out[idx] = np.minimum(1.0, np.minimum.accumulate(q[::-1])[::-1])
    return out


# ---------------------------------------------------------------------------
# Training seeds as a random effect
# ---------------------------------------------------------------------------

def proportion_variance(k: int, n: int) -> float:
    """Variance of a success ratio ``k / n`` over the test queries, ``p (1 - p) / n`` with
    ``p = (k + 1/2) / (n + 1)`` (half a success added, so that 0 and n successes keep
    a variance). NaN for ``n <= 0``."""
    if n <= 0:
        return float("nan")
    p = (k + 0.5) / (n + 1)
    return p * (1 - p) / n


def paired_difference_variance(only_a: int, only_b: int, n: int) -> float:
    """Variance over the test queries of a paired success difference ``(b - c) / n``
    (``b = only_a``, ``c = only_b`` discordant pairs): ``(p_b + p_c - (p_b - p_c)^2) / n``
    with ``p_b = (b + 1/2) / (n + 1)``, ``p_c = (c + 1/2) / (n + 1)``. NaN for ``n <= 0``."""
    if n <= 0:
        return float("nan")
    pb, pc = (only_a + 0.5) / (n + 1), (only_b + 0.5) / (n + 1)
    return (pb + pc - (pb - pc) ** 2) / n


@dataclasses.dataclass(frozen=True)
class SeedEstimate:
    """An estimate with its variance split into independently estimated components.

    Attributes:
        estimate: the value (e.g. the mean over training seeds of a success difference).
        components: ``((key, variance, df), ...)``: the estimated variance is their sum;
            ``df`` is each component's degrees of freedom (``inf``: known, as the query
            term). Components with the same key are one estimate scaled (a spread borrowed
            by several maps) and are added before Satterthwaite's formula.
        seeds: training seeds behind the estimate (summed over maps for a combination).
        spread: standard deviation of the per-seed values (NaN with one seed; for a
            combination the root mean square of the maps' spreads).
        borrowed: whether a between-seed variance was borrowed (a one-seed map).
        seed_aware: whether every part has a between-seed term (False for a one-seed
            map with nothing to borrow: its interval covers the test queries only).
    """

    estimate: float
    components: tuple = ()
    seeds: int = 0
    spread: float = float("nan")
    borrowed: bool = False
    seed_aware: bool = True

    @property
    def variance(self) -> float:
        return float(sum(v for _, v, _ in self.components))

    @property
    def se(self) -> float:
        return math.sqrt(max(self.variance, 0.0))

    @staticmethod
    def _satterthwaite(components) -> tuple[float, float]:
        """``(V, df)``: the summed variance and Satterthwaite's ``V^2 / sum(V_k^2 / df_k)``
        (inf when every component is known or V is 0)."""
        merged: dict = {}
        for key, v, df in components:
            mv, mdf = merged.get(key, (0.0, df))
            merged[key] = (mv + v, min(mdf, df))
        total = float(sum(v for v, _ in merged.values()))
        den = sum(v * v / df for v, df in merged.values() if math.isfinite(df) and df > 0)
        return total, (math.inf if den <= 0 or total <= 0 else total * total / den)

    @property
    def df(self) -> float:
        """Satterthwaite's degrees of freedom of the whole variance."""
        return self._satterthwaite(self.components)[1]

    @property
    def seed_part(self) -> tuple[float, float]:
        """``(variance, df)`` of the between-seed components alone (``(0, inf)`` if none)."""
        return self._satterthwaite([c for c in self.components if c[0][0] == "seed"])

    def _halfwidth(self, confidence: float) -> float:
        """``max(t_{df} se, t_{df_seed} sqrt(V_seed))``."""
        from scipy import stats as _st
        q = 0.5 + confidence / 2
        tq = lambda df: float(_st.norm.ppf(q) if math.isinf(df) else _st.t.ppf(q, df))  # noqa: E731
        vs, dfs = self.seed_part
        return max(tq(self.df) * self.se, tq(dfs) * math.sqrt(max(vs, 0.0)))

    def ci(self, confidence: float = 0.95) -> list[float]:
        """``[lo, hi]``, ``estimate -+ max(t_{df} se, t_{df_seed} sqrt(V_seed))``: the wider
        of the interval on the whole variance (Satterthwaite's df) and the one on the
        between-seed variance alone (its own df; S - 1 for one map)."""
        if not math.isfinite(self.estimate):
            return [float("nan"), float("nan")]
        h = self._halfwidth(confidence)
        return [self.estimate - h, self.estimate + h]

    def p(self, null: float = 0.0) -> float:
        """Two-sided p-value of ``estimate = null`` matching :meth:`ci` (``null`` lies
        outside the interval iff p < 1 - confidence): the larger of the two t-tests' p
        (0 or 1 when the variance is 0)."""
        if not (math.isfinite(self.estimate) and math.isfinite(null)):
            return float("nan")
        d = abs(self.estimate - null)
        if self.se == 0:
            return 1.0 if d == 0 else 0.0
        from scipy import stats as _st

        def sf(t, df):
            return float(_st.norm.sf(t) if math.isinf(df) else _st.t.sf(t, df))
        p = 2 * sf(d / self.se, self.df)
        vs, dfs = self.seed_part
        if vs > 0:
            p = max(p, 2 * sf(d / math.sqrt(vs), dfs))
        return float(min(1.0, p))


def seed_estimate(values, query_variances, *, key: str = "", borrow=None) -> SeedEstimate:
    """The mean of per-seed values with the training seed as a random effect.

    Args:
        values: ``(S,)`` one value per training seed, on the same test queries.
        query_variances: ``(S,)`` each value's variance over the test queries.
        key: names this estimate's between-seed component (for :func:`combine`).
        borrow: ``(variance, df, key)`` of a between-seed variance estimated elsewhere
            (:func:`pooled_spread`), used when there is one seed only.

    Returns:
        A :class:`SeedEstimate` of the mean with variance ``s^2 / S + mean(v_s)``
        (``s^2`` the sample variance of the values, S - 1 degrees of freedom; with one
        seed ``borrow``'s variance, or no between-seed term when ``borrow`` is None).
    """
    x = np.asarray(values, np.float64).reshape(-1)
    v = np.asarray(query_variances, np.float64).reshape(-1)
    if x.size == 0 or x.shape != v.shape:
        raise ValueError(f"one value and one query variance per seed, got {x.shape} and {v.shape}")
    s = int(x.size)
    comps = [(("query", key), float(v.mean()), math.inf)]
    spread, borrowed = float("nan"), False
    if s >= 2:
        var = float(x.var(ddof=1))
        spread = math.sqrt(var)
        comps.append((("seed", key), var / s, s - 1))
    elif borrow is not None:
        var, df, bkey = borrow
        comps.append((("seed", bkey), float(var), float(df)))
        borrowed = True
    return SeedEstimate(float(x.mean()), tuple(comps), s, spread, borrowed, s >= 2 or borrowed)


def pooled_spread(groups, key: str = "pooled") -> tuple[float, float, str] | None:
    """The between-seed variance pooled over groups (maps) of per-seed values:
    ``sum (S_g - 1) s_g^2 / sum (S_g - 1)`` with ``sum (S_g - 1)`` degrees of freedom, as
    ``(variance, df, key)`` for :func:`seed_estimate`'s ``borrow``; None without a group
    of two or more seeds."""
    num_, df = 0.0, 0
    for g in groups:
        x = np.asarray(g, np.float64).reshape(-1)
        if x.size >= 2:
            num_ += float(x.var(ddof=1)) * (x.size - 1)
            df += x.size - 1
    return None if df == 0 else (num_ / df, float(df), key)


def combine(estimates, weights=None) -> SeedEstimate:
    """``sum_i w_i e_i`` of independent estimates (default: their mean): each component's
    variance scaled by ``w_i^2``; spreads combined as their root mean square."""
    es = list(estimates)
    if not es:
        raise ValueError("combine needs at least one estimate")
    w = [1.0 / len(es)] * len(es) if weights is None else [float(x) for x in weights]
    comps = tuple((k, wi * wi * v, df) for e, wi in zip(es, w) for k, v, df in e.components)
    spreads = [e.spread for e in es if math.isfinite(e.spread)]
    spread = math.sqrt(sum(s * s for s in spreads) / len(spreads)) if spreads else float("nan")
    return SeedEstimate(float(sum(wi * e.estimate for e, wi in zip(es, w))), comps,
                        sum(e.seeds for e in es), spread, any(e.borrowed for e in es),
                        all(e.seed_aware for e in es))


def _kendall_s(x, y) -> int:
    """Kendall's S: concordant minus discordant pairs (a tie counts 0)."""
    return int(sum(np.sign(x[i] - x[j]) * np.sign(y[i] - y[j])
                   for i, j in itertools.combinations(range(len(x)), 2)))


def stratified_kendall(strata) -> tuple[float, float, float]:
    """Kendall's trend test within strata, combined: ``S = sum_g S_g`` (concordant minus
    discordant pairs within each stratum, ties counting 0), tau = S / (pairs within
    strata), and its exact one-sided p-values ``(tau, P(S <= s), P(S >= s))`` over every
    permutation of y within each stratum (independent strata; their exact distributions
    convolved). ``strata``: a list of ``(x, y)``, at most 8 points each (8! permutations)."""
    dist = {0: 1}
    s_obs, pairs = 0, 0
    for x, y in strata:
        x, y = np.asarray(x, float), np.asarray(y, float)
        n = x.size
        if n < 2:
            continue
        if n > 8:
            raise ValueError(f"stratified_kendall enumerates permutations: at most 8 points "
                             f"per stratum, got {n}")
        s_obs += _kendall_s(x, y)
        pairs += n * (n - 1) // 2
        here: dict = {}
        for perm in itertools.permutations(y):
            k = _kendall_s(x, np.asarray(perm))
            here[k] = here.get(k, 0) + 1
        new: dict = {}
        for a, ca in dist.items():
            for b, cb in here.items():
                new[a + b] = new.get(a + b, 0) + ca * cb
        dist = new
    if pairs == 0:
        return float("nan"), float("nan"), float("nan")
    total = sum(dist.values())
    less = sum(c for k, c in dist.items() if k <= s_obs) / total
    greater = sum(c for k, c in dist.items() if k >= s_obs) / total
    return s_obs / pairs, float(less), float(greater)
