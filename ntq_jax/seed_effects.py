"""Training seeds as a random effect: the verdict test of ``REPRODUCTION.md``.

The same test queries are planned by the PNets of S trainings of the same data
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
difference of two maps).

The claims that use it: :mod:`ntq_jax.experiment.claims`; the p-values it gives are
adjusted as one family by :func:`ntq_jax.multiplicity.holm`. Only NumPy and SciPy
(``scipy.stats``, imported on first use); no JAX. Also importable from
:mod:`ntq_jax.stats`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = [
    "proportion_variance",
    "paired_difference_variance",
    "SeedEstimate",
    "seed_estimate",
    "pooled_spread",
    "combine",
]


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
    return SeedEstimate(
        float(sum(wi * e.estimate for e, wi in zip(es, w))),
        comps,
        sum(e.seeds for e in es),
        spread,
        any(e.borrowed for e in es),
        all(e.seed_aware for e in es),
    )
