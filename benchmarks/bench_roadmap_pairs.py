"""The roadmap's edge list: one int64 code per pair against NumPy's row-wise unique.

    python benchmarks/bench_roadmap_pairs.py [--milestones 20000] [--reps 7]

Both build the distinct undirected ``(min, max)`` pairs of a k-nearest-neighbour graph of
``--milestones`` nodes with PRM*'s ``k`` (random neighbours, as many rows as the roadmap
planner's default first round): ``unique_rows`` is ``np.unique(..., axis=0)`` on the
stacked pairs with the self-loops dropped (what ``build_roadmap`` did),
``undirected_pairs`` is :func:`ntq_jax.planners.roadmap_build.undirected_pairs`. Repeats are
interleaved; medians and their ratio are printed, and the two results are checked equal.
"""

from __future__ import annotations

import argparse

import numpy as np
from common import interleaved

from ntq_jax.planners.roadmap_build import prm_star_k, undirected_pairs


def unique_rows(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    pairs = np.unique(np.stack([np.minimum(i, j), np.maximum(i, j)], 1), axis=0)
    return pairs[pairs[:, 0] != pairs[:, 1]]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--milestones", type=int, default=20_000)
    ap.add_argument("--reps", type=int, default=7)
    args = ap.parse_args()
    n = args.milestones
    k = prm_star_k(n, 2)
    rng = np.random.default_rng(0)
    i = np.repeat(np.arange(n), k)
    j = rng.integers(0, n, i.size)
    assert np.array_equal(unique_rows(i, j), undirected_pairs(i, j, n))
    med = interleaved(
        {
            "unique_rows": lambda: unique_rows(i, j),
            "undirected_pairs": lambda: undirected_pairs(i, j, n),
        },
        args.reps,
    )
    print(f"{n} milestones, k = {k}: {i.size} pairs")
    for name, t in med.items():
        print(f"{name:17s} {t * 1e3:8.1f} ms (median of {args.reps})")
    print(
        f"ratio undirected_pairs / unique_rows: {med['undirected_pairs'] / med['unique_rows']:.3f}"
    )


if __name__ == "__main__":
    main()
