"""The verdict test's coverage by simulation: synthetic PNet_0 / PNet_3 outcomes with a
known effect and a known spread between training seeds.

The seed-aware test of ``REPRODUCTION.md`` (:func:`ntq_jax.stats.seed_estimate`) is
checked here against a generative model with the structure of the experiment: S
trainings (training seeds) of two models on the same n test queries. On the logit
scale, model k in seed s solves query q with probability

    expit(mu_k + z_q + [k = 3] w_q + a_ks + e_ksq)

``z_q ~ N(0, query_sd^2)``: the query's difficulty, shared by both models and every
seed (it makes the two models' outcomes correlated, as McNemar's discordant pairs
are rare); ``w_q ~ N(0, model_query_sd^2)``: how much the query favours PNet_3, shared
by every seed (the part of the query noise that does not average out over seeds);
``a_ks ~ N(0, seed_sd^2)``: the training seed's shift of each model (the random
effect); ``e_ksq ~ N(0, cell_sd^2)``: a training's own luck on a query. The true
effect, the expected difference of success ratios for a new training on a new
query, is a one-dimensional integral per model (:func:`true_effect`).

Methods compared (:data:`METHODS`), each a 95 % interval of that effect:

* ``seed_aware``: the verdict test, :func:`ntq_jax.stats.seed_estimate` on the
  per-seed paired differences and their McNemar counts;
* ``satterthwaite``: the same variance with Satterthwaite's degrees of freedom
  alone (without the verdict test's floor, the t-interval of the between-seed term);
* ``pooled_pairs``: every seed's pairs taken as independent queries (summing the
  discordant pairs over seeds, as a pooled McNemar test does);
* ``one_seed``: Newcombe's interval of seed 0 alone (what a one-seed map offers);
* ``t_over_seeds``: Student's t on the S per-seed differences, S - 1 degrees of
  freedom (leaves out the shared query term);
* ``bootstrap``: the two-level (crossed) percentile bootstrap, seeds and queries
  resampled with replacement.

Scenarios (:class:`Scenario`) also cover a map with one seed that borrows the
between-seed variance of other maps (:func:`ntq_jax.stats.pooled_spread`) and the
mean over several maps (:func:`ntq_jax.stats.combine`). ``benchmarks/seed_test_coverage.py``
runs the grid; ``results/paper/seed_test_coverage.md`` is its committed result.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ntq_jax import stats as S

__all__ = ["Scenario", "METHODS", "true_effect", "simulate", "coverage", "GRID"]

METHODS = ("seed_aware", "satterthwaite", "pooled_pairs", "one_seed", "t_over_seeds", "bootstrap")


@dataclasses.dataclass(frozen=True)
class Scenario:
    """One synthetic experiment (see the module docstring for the model).

    ``maps``: maps averaged (each with ``seeds`` seeds, the same parameters);
    ``borrow_from``: > 0 makes the target a one-seed map whose between-seed variance is
    borrowed from that many other maps with ``seeds`` seeds each."""

    name: str
    seeds: int = 3
    n: int = 500
    mu0: float = 1.5
    mu3: float = 1.8
    query_sd: float = 1.5
    model_query_sd: float = 0.0
    seed_sd: float = 0.0
    cell_sd: float = 0.8
    maps: int = 1
    borrow_from: int = 0


def _mean_expit(mu: float, sd: float) -> float:
    """E[expit(mu + sd Z)], Z standard normal (Gauss-Hermite, 80 nodes)."""
    x, w = np.polynomial.hermite_e.hermegauss(80)
    return float(np.sum(w / np.sqrt(2 * np.pi) / (1 + np.exp(-(mu + sd * x)))))


def true_effect(sc: Scenario) -> float:
    """The expected success of PNet_3 minus PNet_0 over new seeds and new queries."""
    base = sc.query_sd**2 + sc.seed_sd**2 + sc.cell_sd**2
    return _mean_expit(sc.mu3, math.sqrt(base + sc.model_query_sd**2)) - _mean_expit(
        sc.mu0, math.sqrt(base)
    )


def simulate(sc: Scenario, reps: int, rng: np.random.Generator, seeds: int | None = None):
    """``(reps, S, n)`` bool successes ``(y3, y0)`` of PNet_3 and PNet_0 in ``reps``
    independent experiments (new queries, new seeds each)."""
    s = sc.seeds if seeds is None else seeds
    shape = (reps, s, sc.n)
    z = rng.normal(0, sc.query_sd, (reps, 1, sc.n))
    w = rng.normal(0, sc.model_query_sd, (reps, 1, sc.n)) if sc.model_query_sd else 0.0
    a0 = rng.normal(0, sc.seed_sd, (reps, s, 1))
    a3 = rng.normal(0, sc.seed_sd, (reps, s, 1))
    l0 = sc.mu0 + z + a0 + rng.normal(0, sc.cell_sd, shape)
    l3 = sc.mu3 + z + w + a3 + rng.normal(0, sc.cell_sd, shape)
    y0 = rng.random(shape) < 1 / (1 + np.exp(-l0))
    y3 = rng.random(shape) < 1 / (1 + np.exp(-l3))
    return y3, y0


def _diff(y) -> np.ndarray:
    return y[0].astype(np.int8) - y[1].astype(np.int8)


def _seed_parts(d: np.ndarray):
    """Per seed: the difference and its query variance from the discordant counts."""
    n = d.shape[-1]
    b, c = (d == 1).sum(-1), (d == -1).sum(-1)
    var = np.vectorize(S.paired_difference_variance)(b, c, n)
    return (b - c) / n, var


def _estimate(d: np.ndarray, borrow=None) -> S.SeedEstimate:
    x, v = _seed_parts(d)
    return S.seed_estimate(x, v, key="map", borrow=borrow)


def _interval(
    method: str, y3: np.ndarray, y0: np.ndarray, rng: np.random.Generator, boot: int
) -> tuple:
    """The 95 % interval of ``method`` for one experiment's successes (S, n)."""
    d = y3.astype(np.int8) - y0.astype(np.int8)
    s, n = d.shape
    if method == "seed_aware":
        return tuple(_estimate(d).ci())
    if method == "satterthwaite":
        from scipy.stats import t

        e = _estimate(d)
        h = t.ppf(0.975, e.df) * e.se
        return e.estimate - h, e.estimate + h
    if method == "pooled_pairs":
        flat = d.reshape(-1).astype(np.float64)
        h = 1.959963984540054 * flat.std(ddof=1) / math.sqrt(flat.size)
        return flat.mean() - h, flat.mean() + h
    if method == "one_seed":
        return tuple(S.paired_success_difference(y3[0], y0[0])["ci"])
    if method == "t_over_seeds":
        from scipy.stats import t

        x = d.mean(-1)
        h = t.ppf(0.975, s - 1) * x.std(ddof=1) / math.sqrt(s)
        return x.mean() - h, x.mean() + h
    if method == "bootstrap":
        si = rng.integers(0, s, (boot, s))
        qi = rng.integers(0, n, (boot, n))
        means = d[si[:, :, None], qi[:, None, :]].mean(axis=(1, 2))
        lo, hi = np.quantile(means, [0.025, 0.975])
        return float(lo), float(hi)
    raise ValueError(f"unknown method {method!r}")


def coverage(
    sc: Scenario,
    reps: int,
    seed: int = 0,
    methods=METHODS,
    boot: int = 400,
    boot_reps: int | None = None,
) -> dict:
    """Coverage of the true effect by each method's 95 % interval over ``reps`` simulated
    experiments (the bootstrap over the first ``boot_reps`` only: it is the slow one).

    Returns ``{"effect", "discordant" (mean share of discordant pairs), "sd_per_seed"
    (mean standard deviation of the per-seed differences), method: {"coverage",
    "width", "reps"}}``. Scenarios with ``maps`` > 1 or ``borrow_from`` > 0 run the
    seed-aware test only (the others have no such form)."""
    rng = np.random.default_rng(seed)
    eff = true_effect(sc)
    if sc.maps > 1 or sc.borrow_from:
        methods = ("seed_aware",)
    hits = {m: [] for m in methods}
    widths = {m: [] for m in methods}
    disc, sds = [], []
    chunk = 200
    done = 0
    while done < reps:
        k = min(chunk, reps - done)
        if sc.maps > 1:
            ds = [_diff(simulate(sc, k, rng)) for _ in range(sc.maps)]
            for r in range(k):
                e = S.combine([_estimate(d[r]) for d in ds])
                lo, hi = e.ci()
                hits["seed_aware"].append(lo <= eff <= hi)
                widths["seed_aware"].append(hi - lo)
            d = ds[0]
        elif sc.borrow_from:
            d = _diff(simulate(sc, k, rng, seeds=1))
            others = [_diff(simulate(sc, k, rng)) for _ in range(sc.borrow_from)]
            for r in range(k):
                borrow = S.pooled_spread([_seed_parts(o[r])[0] for o in others], "borrowed")
                lo, hi = _estimate(d[r], borrow).ci()
                hits["seed_aware"].append(lo <= eff <= hi)
                widths["seed_aware"].append(hi - lo)
        else:
            y3, y0 = simulate(sc, k, rng)
            d = _diff((y3, y0))
            for r in range(k):
                for m in methods:
                    if m == "bootstrap" and boot_reps is not None and len(hits[m]) >= boot_reps:
                        continue
                    lo, hi = _interval(m, y3[r], y0[r], rng, boot)
                    hits[m].append(lo <= eff <= hi)
                    widths[m].append(hi - lo)
        disc.append(float(np.mean(d != 0)))
        if d.shape[1] > 1:
            sds.append(float(np.mean(d.mean(-1).std(axis=1, ddof=1))))
        done += k
    out = {
        "effect": eff,
        "discordant": float(np.mean(disc)),
        "sd_per_seed": float(np.mean(sds)) if sds else float("nan"),
    }
    for m in methods:
        out[m] = {
            "coverage": float(np.mean(hits[m])),
            "width": float(np.mean(widths[m])),
            "reps": len(hits[m]),
        }
    return out


#: The full study's scenarios: seeds 2, 3, 5 x between-seed spread none / moderate / large
#: / very large (a logit shift of sd 0.15 / 0.35 / 0.5 per model and seed: PNet_0's success
#: moves by about 0.03 / 0.07 / 0.1 between seeds; ours moves by up to 0.10) x a shared
#: query effect on PNet_3 or none; then a one-seed map borrowing the spread of two
#: three-seed maps, and the mean over four three-seed maps.
GRID = (
    tuple(
        Scenario(
            f"S={s}, seed_sd={sd}, model_query_sd={mq}", seeds=s, seed_sd=sd, model_query_sd=mq
        )
        for s in (2, 3, 5)
        for sd in (0.0, 0.15, 0.35, 0.5)
        for mq in (0.0, 1.0)
    )
    + tuple(
        Scenario(
            f"one seed, spread borrowed from 2 maps x 3 seeds, seed_sd={sd}, model_query_sd={mq}",
            seeds=3,
            seed_sd=sd,
            model_query_sd=mq,
            borrow_from=2,
        )
        for sd in (0.15, 0.35)
        for mq in (0.0, 1.0)
    )
    + tuple(
        Scenario(
            f"mean over 4 maps x 3 seeds, seed_sd={sd}, model_query_sd={mq}",
            seeds=3,
            seed_sd=sd,
            model_query_sd=mq,
            maps=4,
        )
        for sd in (0.15, 0.35)
        for mq in (0.0, 1.0)
    )
)
