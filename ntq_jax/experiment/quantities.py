"""The quantities a claim measures in every training seed, and their estimates over a map's seeds.

**The test** (:mod:`ntq_jax.seed_effects`, training seeds as a random effect). A map's
runs are its training seeds: the main run (seed 0) and ``seeds/train_seed_<k>``, the
same data and test queries. A quantity (a paired success difference, a success
ratio, ...) is measured in every seed with its variance over the test queries;
its estimate is the mean over the seeds, with the between-seed variance ``s^2 / S``
(S - 1 degrees of freedom) added to the query variance
(:func:`ntq_jax.seed_effects.seed_estimate`). A map with one seed borrows the
between-seed variance of the same quantity from its robot's maps that have two or
more seeds (:func:`ntq_jax.seed_effects.pooled_spread`). A claim over several maps
takes the mean of the maps' estimates (:func:`ntq_jax.seed_effects.combine`). Query
variances: McNemar's discordant pairs for a paired difference the summary has; else
the two success ratios' variances added (the same queries, assumed not negatively
correlated; conservative); queries of the two kinds are independent. The effect's
95 % interval and two-sided p-value are :meth:`ntq_jax.seed_effects.SeedEstimate.ci`
and ``.p``; its coverage was checked by simulation
(``results/paper/seed_test_coverage.md``).

A :class:`Quantity` is one such measurement, named by its key (``q_diff``: a paired
success difference; ``q_diff_kinds``: the same over both query kinds; ``q_level``: a
success ratio; ``q_members``: the mean success of PNet_0..3; ``q_kind_gap``: uniform
minus non-trivial; ``q_steer_gap``: with minus without steerTo); :class:`Seeds` holds
the summaries by map and training seed and gives a quantity's per-seed values and its
:class:`ntq_jax.seed_effects.SeedEstimate` on a map. The claims built on them:
:mod:`ntq_jax.experiment.claims`.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

from ntq_jax.experiment.formatting import num
from ntq_jax.experiment.paper import KINDS, MAPS, MEMBERS
from ntq_jax.experiment.summaries import main_runs, run_cells
from ntq_jax.seed_effects import (
    SeedEstimate,
    paired_difference_variance,
    pooled_spread,
    proportion_variance,
    seed_estimate,
)

__all__ = [
    "Quantity",
    "Seeds",
    "q_diff",
    "q_diff_kinds",
    "q_level",
    "q_members",
    "q_kind_gap",
    "q_steer_gap",
]

Value = "tuple[float, float] | None"  # (value, its variance over the test queries)


def _comparison(s, a: str, b: str, kind: str, steer: bool):
    for c in (s or {}).get("comparisons", []):
        if c.get("query_kind") != kind or bool(c.get("steer", True)) != steer:
            continue
        if (c.get("model"), c.get("baseline")) == (a, b):
            return c["only_a"], c["only_b"], c["n"]
        if (c.get("model"), c.get("baseline")) == (b, a):
            return c["only_b"], c["only_a"], c["n"]
    return None


def _level(s, model: str, kind: str, steer: bool = True):
    r = run_cells(s, steer).get((model, kind))
    if r is None or not r.get("k_test"):
        return None
    return r["success_ratio"], proportion_variance(r["successes"], r["k_test"])


def _diff(s, a: str, b: str, kind: str, steer: bool = True):
    """Success of ``a`` minus ``b`` on the same queries: McNemar's counts when the summary
    has the paired comparison, else the rows (variances added)."""
    c = _comparison(s, a, b, kind, steer)
    if c is not None and c[2]:
        only_a, only_b, n = c
        return (only_a - only_b) / n, paired_difference_variance(only_a, only_b, n)
    la, lb = _level(s, a, kind, steer), _level(s, b, kind, steer)
    if la is None or lb is None:
        return None
    return la[0] - lb[0], la[1] + lb[1]


def _members(s, kind: str, steer: bool = True):
    """Mean success of PNet_0..3 (the members' standard deviations averaged: they are
    positively correlated on the same queries)."""
    got = [_level(s, m, kind, steer) for m in MEMBERS]
    if any(g is None for g in got):
        return None
    sd = sum(math.sqrt(v) for _, v in got) / len(got)
    return sum(x for x, _ in got) / len(got), sd * sd


def _both_kinds(f: Callable):
    """The mean over the two query kinds of ``f(s, kind)`` (independent query sets)."""

    def g(s):
        got = [f(s, k) for k in KINDS]
        if any(x is None for x in got):
            return None
        return sum(x for x, _ in got) / len(got), sum(v for _, v in got) / len(got) ** 2

    return g


def _gap(a, b):
    """``a - b`` of two (value, variance) on independent or positively correlated queries."""
    return None if a is None or b is None else (a[0] - b[0], a[1] + b[1])


class Quantity(NamedTuple):
    """A value measured in each training seed: ``key`` names it (the spread borrowed by a
    one-seed map is the same quantity's on the robot's other maps)."""

    key: str
    fn: Callable


def q_diff(a: str, b: str, kind: str, steer: bool = True) -> Quantity:
    return Quantity(f"{a}-{b}|{kind}|{steer}", lambda s: _diff(s, a, b, kind, steer))


def q_diff_kinds(a: str, b: str, steer: bool = True) -> Quantity:
    return Quantity(f"{a}-{b}|both|{steer}", _both_kinds(lambda s, k: _diff(s, a, b, k, steer)))


def q_level(model: str, kind: str, steer: bool = True) -> Quantity:
    return Quantity(f"{model}|{kind}|{steer}", lambda s: _level(s, model, kind, steer))


def q_members(kind: str, steer: bool = True) -> Quantity:
    return Quantity(f"members|{kind}|{steer}", lambda s: _members(s, kind, steer))


def q_kind_gap(model: str, steer: bool = True) -> Quantity:
    return Quantity(
        f"{model}|uniform-nontrivial|{steer}",
        lambda s: _gap(_level(s, model, "uniform", steer), _level(s, model, "nontrivial", steer)),
    )


def q_steer_gap(model: str) -> Quantity:
    return Quantity(
        f"{model}|steer-nosteer|both",
        _both_kinds(lambda s, k: _gap(_level(s, model, k, True), _level(s, model, k, False))),
    )


class Seeds:
    """The summaries by map and training seed (one run per seed, the main run first)."""

    def __init__(self, summaries):
        self.runs: dict[str, list[dict]] = {}
        seen = set()
        for s in summaries:
            key = (s.get("env"), s.get("train_seed"))
            if key not in seen:
                seen.add(key)
                self.runs.setdefault(s.get("env"), []).append(s)
        self.main = main_runs(summaries)
        self._cache: dict = {}

    def values(self, env: str, q: Quantity) -> list[tuple[int, float, float]]:
        """``[(train seed, value, query variance), ...]`` of the seeds that have it."""
        out = []
        for s in self.runs.get(env, []) if env in self.main else []:
            got = q.fn(s)
            if got is not None and num(got[0]) and num(got[1]):
                out.append((s.get("train_seed"), float(got[0]), float(got[1])))
        return out

    def borrow(self, task: str, q: Quantity):
        """The between-seed variance of ``q`` pooled over the task's maps with two or more
        seeds (None when there is none)."""
        envs = [e for e in MAPS if e.startswith(task + "/")]
        return pooled_spread(
            [[x for _, x, _ in self.values(e, q)] for e in envs], f"{task}|{q.key}"
        )

    def estimate(self, env: str, q: Quantity) -> SeedEstimate | None:
        """``q`` on ``env`` over its seeds (None if no seed has it)."""
        key = (env, q.key)
        if key not in self._cache:
            vals = self.values(env, q)
            borrow = self.borrow(env.split("/")[0], q) if len(vals) == 1 else None
            self._cache[key] = (
                None
                if not vals
                else seed_estimate(
                    [x for _, x, _ in vals],
                    [v for _, _, v in vals],
                    key=f"{env}|{q.key}",
                    borrow=borrow,
                )
            )
        return self._cache[key]

    def seed_values(self, env: str, q: Quantity) -> list[float]:
        return [x for _, x, _ in self.values(env, q)]
