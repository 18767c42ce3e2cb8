"""Synthetic MPNet rows without a map or a planner, for training tests and benchmarks."""

from __future__ import annotations

import numpy as np

__all__ = ["straight_line_rows"]


def straight_line_rows(
    seed: int, lo, hi, *, step: float, n_paths: int | None = None, n_rows: int | None = None
):
    """Synthetic MPNet rows without obstacles or a planner (smoke tests, benchmarks).

    Straight paths between uniform random points of the box ``[lo, hi]``, cut
    into ``ceil(length / step)`` equal steps; each step is a row ``(current, goal)
    -> next``. Give ``n_paths`` (all rows of that many paths) or ``n_rows`` (the
    first ``n_rows`` rows of as many paths as needed).

    Returns:
        ``(inputs (N, 2 d) float32, targets (N, d) float32, path_index (N,) int32)``.
    """
    if (n_paths is None) == (n_rows is None):
        raise ValueError("straight_line_rows: give exactly one of n_paths and n_rows")
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lo), np.asarray(hi)
    xs, ys, pis, p = [], [], [], 0
    while (p < n_paths) if n_rows is None else (len(xs) < n_rows):
        a, b = rng.uniform(lo, hi), rng.uniform(lo, hi)
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        pts = a + (b - a) * (np.arange(n + 1) / n)[:, None]
        for k in range(n):
            xs.append(np.concatenate([pts[k], b]))
            ys.append(pts[k + 1])
            pis.append(p)
        p += 1
    end = len(xs) if n_rows is None else n_rows
    return (
        np.array(xs[:end], np.float32),
        np.array(ys[:end], np.float32),
        np.array(pis[:end], np.int32),
    )
