"""Statistics of success ratios: one interval, paired and unpaired tests.

* one proportion: :func:`wilson_interval`, the Wilson score interval of ``k / n``
  (gamma_nt, success ratios);
* two proportions on different queries: :func:`fisher_exact_p`;
* trends over maps: :func:`kendall_tau`, and :func:`stratified_kendall` (Kendall's
  trend test within strata, robots, combined exactly).

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

The rest of the package's statistics live in their own modules and are importable
from here too (every name of ``__all__``):

* training seeds as a random effect, the verdict test of ``REPRODUCTION.md``
  (:func:`seed_estimate`, :class:`SeedEstimate`, :func:`pooled_spread`,
  :func:`combine`, :func:`proportion_variance`, :func:`paired_difference_variance`):
  :mod:`ntq_jax.seed_effects`;
* multiplicity (:func:`holm`, :func:`benjamini_hochberg`): :mod:`ntq_jax.multiplicity`;
* the mean of a ratio over a family of worlds measured in part (:func:`world_mean`,
  :class:`WorldMean`; a scene's gamma_nt over its problems): :mod:`ntq_jax.world_mean`.

Only NumPy and SciPy (``scipy.stats``, imported on first use); no JAX.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np

from ntq_jax.multiplicity import benjamini_hochberg, holm
from ntq_jax.seed_effects import (
    SeedEstimate,
    combine,
    paired_difference_variance,
    pooled_spread,
    proportion_variance,
    seed_estimate,
)
from ntq_jax.world_mean import WorldMean, world_mean

__all__ = [
    "wilson_interval",
    "fisher_exact_p",
    "kendall_tau",
    "mcnemar_exact",
    "paired_success_difference",
    "paired_cost_difference",
    "wilcoxon_p",
    "paired_comparison",
    "N_BOOT",
    "SEED",
    "holm",
    "benjamini_hochberg",
    "proportion_variance",
    "paired_difference_variance",
    "SeedEstimate",
    "seed_estimate",
    "pooled_spread",
    "combine",
    "stratified_kendall",
    "WorldMean",
    "world_mean",
]

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


def paired_cost_difference(
    x, y, *, n_boot: int = N_BOOT, seed: int = SEED, confidence: float = 0.95
) -> dict:
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
        means[s : s + k] = d[rng.integers(0, n, size=(k, n), dtype=np.int32)].mean(axis=1)
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


def paired_comparison(
    a: dict, b: dict, *, n_boot: int = N_BOOT, seed: int = SEED, confidence: float = 0.95
) -> dict:
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
        raise ValueError(
            f"not paired: {sa.shape[0] if sa.ndim else 0} and "
            f"{sb.shape[0] if sb.ndim else 0} queries"
        )
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
    return {
        "n": s["n"],
        "both": s["both"],
        "only_a": s["only_a"],
        "only_b": s["only_b"],
        "neither": s["neither"],
        "success_diff": s["diff"],
        "success_diff_ci95": s["ci"],
        "mcnemar_p": mcnemar_exact(s["only_a"], s["only_b"]),
        "cost_n": cd["n"],
        "cost_ratio_diff": cd["diff"],
        "cost_ratio_diff_ci95": cd["ci"],
        "wilcoxon_p": wilcoxon_p(ra, rb),
    }


# ---------------------------------------------------------------------------
# Trends over maps within strata
# ---------------------------------------------------------------------------


def _kendall_s(x, y) -> int:
    """Kendall's S: concordant minus discordant pairs (a tie counts 0)."""
    return int(
        sum(
            np.sign(x[i] - x[j]) * np.sign(y[i] - y[j])
            for i, j in itertools.combinations(range(len(x)), 2)
        )
    )


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
            raise ValueError(
                f"stratified_kendall enumerates permutations: at most 8 points per stratum, got {n}"
            )
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
