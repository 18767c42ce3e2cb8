"""The mean of a proportion over a family of worlds, from some of its worlds measured.

A family of worlds shares one description but places its obstacles differently in each:
the 100 problems of a MotionBenchMaker scene are 100 worlds, and their gamma_nt differ
(from 0.07 to 0.29 over ten problems of one scene). The family's value is the mean over
its ``N`` worlds. Measuring ``n`` of them, world ``i`` over ``m_i`` queries with
``k_i`` hits, is a two-stage sample (Cochran, *Sampling Techniques*, 3rd ed., 1977,
sections 10.2-10.4: worlds drawn without replacement, then queries within each world
from an unbounded population). The estimate is the mean of the worlds' ratios
``p_i = k_i / m_i``, and its estimated variance is

    v = (1 - n / N) s^2 / n + (n / N) sum_i v_i / n^2

with ``s^2`` the sample variance of the ``p_i`` (``n - 1`` degrees of freedom) and
``v_i = p_i (1 - p_i) / (m_i - 1)`` world ``i``'s query variance. The first term, the
spread between worlds, vanishes once every world is measured (``n = N``): the value is
then that of the measured worlds, known up to their queries (the second term). With
``N`` unknown (None: an unbounded family) only the first term remains (``s^2`` holds
the query noise too). The interval is Student's t on ``v`` with Satterthwaite's degrees
of freedom (the query term known), the normal one when only the query term remains,
clipped to ``[0, 1]`` (a mean of ratios).

The interval treats the measured worlds as a random sample of the family; worlds that
were generated independently of each other (MotionBenchMaker's problems) may be taken
in any order. The query term assumes independent queries in every world. Worlds
measured on one query stream (the same seed: the same configurations, checked in each
world) have correlated query errors, which do not average out over the worlds and do
not show in ``s^2``. ``shared_queries=True`` then takes the query term at its bound
under perfect correlation, ``(sum_i sqrt(v_i) / n)^2``, whatever ``n / N`` (``s^2``
holds at most the part of the query noise that is not shared, so the sum stays
conservative).

Only NumPy and SciPy (``scipy.stats``, imported on first use); no JAX.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["WorldMean", "world_mean"]


class WorldMean(NamedTuple):
    """Result of :func:`world_mean`.

    Attributes:
        mean: the mean of the measured worlds' ratios, the estimate of the family's mean.
        ci95: its interval ``(lo, hi)`` at the confidence asked (95 % by default, within
            ``[0, 1]``), or
            None when it cannot be estimated (one world measured of several).
        worlds: how many worlds were measured (``n``).
        population: how many worlds the family has (``N``), or None (unbounded).
        spread: standard deviation of the measured worlds' ratios (NaN for one world).
        df: degrees of freedom of the interval (inf: the normal one).
    """

    mean: float
    ci95: tuple[float, float] | None
    worlds: int
    population: int | None
    spread: float
    df: float


def world_mean(
    hits,
    queries,
    population: int | None = None,
    confidence: float = 0.95,
    shared_queries: bool = False,
):
    """The mean over a family of worlds of a ratio measured on ``n`` of them.

    Args:
        hits: ``(n,)`` per measured world, the queries counted (e.g. non-trivial ones).
        queries: ``(n,)`` per measured world, the queries examined (each >= 2).
        population: the number of worlds in the family (>= n), or None for an unbounded
            family (the conservative choice: no finite-population correction).
        confidence: the interval's level, in (0, 1).
        shared_queries: the worlds were measured on one query stream (correlated query
            errors): the query term is bounded by perfect correlation (module docstring).

    Returns:
        A :class:`WorldMean`; see the module docstring for the variance and interval.

    Raises:
        ValueError: empty or mismatched counts, a world with fewer than 2 queries or
            hits outside ``[0, queries]``, ``population < n``, ``confidence`` outside (0, 1).
    """
    k = np.asarray(hits, np.float64).reshape(-1)
    m = np.asarray(queries, np.float64).reshape(-1)
    n = int(k.size)
    if n == 0 or k.shape != m.shape:
        raise ValueError(f"one hit count and one query count per world, got {k.shape}, {m.shape}")
    if np.any(m < 2) or np.any(k < 0) or np.any(k > m):
        raise ValueError("every world needs >= 2 queries and 0 <= hits <= queries")
    if population is not None and int(population) < n:
        raise ValueError(f"population ({population}) is smaller than the worlds measured ({n})")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    p = k / m
    f = 0.0 if population is None else n / int(population)
    spread = float(p.std(ddof=1)) if n >= 2 else float("nan")
    between = (1 - f) * spread**2 / n if n >= 2 else 0.0
    v_query = p * (1 - p) / (m - 1)
    if shared_queries:  # perfectly correlated query errors: the variance of their mean
        within = float(np.mean(np.sqrt(v_query))) ** 2
    else:
        within = f * float(np.sum(v_query)) / n**2
    out = dict(mean=float(p.mean()), worlds=n, population=population, spread=spread)
    if n < 2 and f < 1:  # one world of several: no spread between worlds to go on
        return WorldMean(ci95=None, df=float("nan"), **out)
    v = between + within
    df = math.inf if between == 0 or v == 0 else v * v / (between * between / (n - 1))
    from scipy import stats as _st

    q = 0.5 + confidence / 2
    h = float(_st.norm.ppf(q) if math.isinf(df) else _st.t.ppf(q, df)) * math.sqrt(v)
    lo, hi = max(out["mean"] - h, 0.0), min(out["mean"] + h, 1.0)  # a mean of ratios
    return WorldMean(ci95=(lo, hi), df=df, **out)
