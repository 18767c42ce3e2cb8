"""Multiplicity: p-values adjusted as a family.

* :func:`holm`, Holm's step-down adjustment (the family-wise error rate): the
  verdicts of ``REPRODUCTION.md`` (:mod:`ntq_jax.experiment.verdicts`) adjust every
  p-value they use together with it;
* :func:`benjamini_hochberg`, the Benjamini-Hochberg q-values (the false-discovery
  rate): the factor study's p-values (:mod:`ntq_jax.experiment.factor_table`).

Both take p-values in any order (NaN: no test, left out of the family) and return
the adjusted values in that order. Only NumPy; also importable from :mod:`ntq_jax.stats`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["holm", "benjamini_hochberg"]


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
