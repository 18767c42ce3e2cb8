"""The paper's claims checked against our summaries, with training seeds as a random effect.

Every claim is one line with an effect, its 95 % interval, a p-value, the spread
between training seeds, a Holm-adjusted p-value and a verdict. The tests and the
rule are written here once; ``REPRODUCTION.md`` and ``docs/guide/reproducing-the-paper.md``
quote them.

**The test** (:mod:`ntq_jax.stats`, "Training seeds as a random effect"). A map's
runs are its training seeds: the main run (seed 0) and ``seeds/train_seed_<k>``, the
same data and test queries. A quantity (a paired success difference, a success
ratio, ...) is measured in every seed with its variance over the test queries;
its estimate is the mean over the seeds, with the between-seed variance ``s^2 / S``
(S - 1 degrees of freedom) added to the query variance (:func:`ntq_jax.stats.seed_estimate`).
A map with one seed borrows the between-seed variance of the same quantity from its
robot's maps that have two or more seeds (:func:`ntq_jax.stats.pooled_spread`). A
claim over several maps takes the mean of the maps' estimates
(:func:`ntq_jax.stats.combine`). Query variances: McNemar's discordant pairs for a
paired difference the summary has; else the two success ratios' variances added (the
same queries, assumed not negatively correlated; conservative); queries of the two
kinds are independent. The effect's 95 % interval and two-sided p-value are
:meth:`ntq_jax.stats.SeedEstimate.ci` and ``.p``; its coverage was checked by
simulation (``results/paper/seed_test_coverage.md``).

**Claims of several parts.** "PNet_3 is the best / the worst" and "every model ..."
need every part: their p-value is the largest of the parts' when every part has the
claimed sign (an intersection-union test), and the smallest part's p times the
number of parts (Bonferroni) for a part of the opposite sign, which would contradict
the claim. "In some cases" needs one part: the smallest p of a part with the claimed
sign times the number of parts. The line shows the part that decides.

**Trends over maps** (maps are the units; each map's value is its mean over
seeds): "success falls as gamma_nt rises" is Kendall's tau with its exact p,
within a robot, and over all 11 maps stratified by robot
(:func:`ntq_jax.stats.stratified_kendall`: robots differ in level, so a pooled
trend would compare robots, not gamma_nt); "the cost ratio is lower for the rigid
body and the 6-link arm" is the exact Mann-Whitney test of the maps' mean cost
ratios. Their p-values are two-sided (twice the smaller one-sided p).

**Multiplicity.** Every p-value a verdict uses (one per claim line, and for the
claims with a magnitude in the paper the test of that magnitude) is one family:
:func:`ntq_jax.stats.holm` adjusts them together, and the verdicts use the adjusted
values.

**The verdict** (:func:`verdict`, level :data:`ALPHA`), in this order:

1. *contradicted*: the Holm-adjusted p < 0.05 and our effect has the sign opposite
   to the claim's (a claim about a magnitude, "about 25 % above": the adjusted p
   of the test of that magnitude < 0.05);
2. *holds*: the Holm-adjusted p < 0.05 and our effect has the claimed sign;
3. *the paper's magnitude excluded*: neither, and the Holm-adjusted p of the test
   of the paper's own effect (e.g. its PNet_3 - PNet_0) < 0.05: the paper's effect
   lies outside what our seeds allow;
4. *unresolved*: otherwise.

A claim whose maps are not run yet is *not run*.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

from ntq_jax.experiment.formatting import fixed, kind_name, num, p_value, signed
from ntq_jax.experiment.paper import KINDS, MAPS, MEMBERS, PAPER, PAPER_TABLES
from ntq_jax.experiment.summaries import main_runs, run_cells
from ntq_jax.stats import (SeedEstimate, combine, holm, paired_difference_variance,
                           pooled_spread, proportion_variance, seed_estimate,
                           stratified_kendall)

__all__ = ["ALPHA", "HOLDS", "CONTRADICTED", "FAILS", "MAGNITUDE", "UNRESOLVED", "NOT_RUN",
           "VERDICTS", "verdict", "Seeds", "Quantity", "claims", "headline", "HEADLINE_CLAIM",
           "effect_text"]

ALPHA = 0.05  #: significance level of every verdict (on Holm-adjusted p-values)
HOLDS, CONTRADICTED, MAGNITUDE, UNRESOLVED, NOT_RUN = (
    "holds", "contradicted", "paper's magnitude excluded", "unresolved", "not run")
FAILS = CONTRADICTED  #: the former name of a claim our data contradict
VERDICTS = (HOLDS, CONTRADICTED, MAGNITUDE, UNRESOLVED, NOT_RUN)
HEADLINE_CLAIM = "PNet_3 >= PNet_0 in success on non-trivial queries"


def verdict(direction: int, p, p_paper=None, *, magnitude_claim: bool = False,
            alpha: float = ALPHA) -> str:
    """The verdict rule (the module docstring's, in its order).

    Args:
        direction: +1 if our effect has the claimed sign, -1 if the opposite, 0 if neither.
        p: the (Holm-adjusted) p-value of the claim's test.
        p_paper: the (Holm-adjusted) p-value of the test of the paper's magnitude, if any.
        magnitude_claim: the claim is the magnitude itself (excluding it contradicts).
    """
    if not num(p):
        return NOT_RUN
    if magnitude_claim and num(p_paper) and p_paper < alpha:
        return CONTRADICTED
    if p < alpha and direction < 0:
        return CONTRADICTED
    if p < alpha and direction > 0:
        return HOLDS
    if num(p_paper) and p_paper < alpha:
        return MAGNITUDE
    return UNRESOLVED


# ---------------------------------------------------------------------------
# Per-seed values and the maps' estimates
# ---------------------------------------------------------------------------

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
    return Quantity(f"{model}|uniform-nontrivial|{steer}",
                    lambda s: _gap(_level(s, model, "uniform", steer),
                                   _level(s, model, "nontrivial", steer)))


def q_steer_gap(model: str) -> Quantity:
    return Quantity(f"{model}|steer-nosteer|both", _both_kinds(
        lambda s, k: _gap(_level(s, model, k, True), _level(s, model, k, False))))


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
        return pooled_spread([[x for _, x, _ in self.values(e, q)] for e in envs],
                             f"{task}|{q.key}")

    def estimate(self, env: str, q: Quantity) -> SeedEstimate | None:
        """``q`` on ``env`` over its seeds (None if no seed has it)."""
        key = (env, q.key)
        if key not in self._cache:
            vals = self.values(env, q)
            borrow = self.borrow(env.split("/")[0], q) if len(vals) == 1 else None
            self._cache[key] = None if not vals else seed_estimate(
                [x for _, x, _ in vals], [v for _, _, v in vals], key=f"{env}|{q.key}",
                borrow=borrow)
        return self._cache[key]

    def seed_values(self, env: str, q: Quantity) -> list[float]:
        return [x for _, x, _ in self.values(env, q)]


# ---------------------------------------------------------------------------
# Claim lines
# ---------------------------------------------------------------------------

def effect_text(e: SeedEstimate | None, null: float = 0.0) -> str:
    """``+0.069 [+0.011, +0.128], 3 seeds, sd 0.024`` (``1 seed, sd borrowed``)."""
    if e is None:
        return "-"
    lo, hi = e.ci()
    seeds = f"{e.seeds} seed{'s' if e.seeds != 1 else ''}"
    sd = ("sd borrowed" if e.borrowed and not num(e.spread)
          else "no sd (one seed)" if not num(e.spread)
          else f"sd {fixed(e.spread)}" + (" (one-seed maps borrow)" if e.borrowed else "")
          + ("" if e.seed_aware else " (a one-seed map without)"))
    return f"{signed(e.estimate)} [{signed(lo)}, {signed(hi)}], {seeds}, {sd}"


def _line(table, claim, scope, *, est=None, null=0.0, sign=1, p=None, direction=None,
          paper_effect=None, magnitude_claim=False, evidence="", paper="",
          effect=None, aware=None) -> dict:
    """One claim line. ``est``: the effect's estimate (its p and direction derived unless
    given); ``paper_effect``: the paper's value of the same effect (its test joins the
    family); ``effect``: the line's effect text (default: ``est``'s); ``aware``: whether
    the test is seed-aware (default: ``est``'s)."""
    if aware is None:
        aware = est is None or est.seed_aware
    if est is not None:
        d = sign * (est.estimate - null)
        direction = (d > 0) - (d < 0) if direction is None else direction
        p = est.p(null) if p is None else p
    if not aware:  # one seed and no spread to borrow: no seed-aware test, no verdict
        p = None
        evidence = ("one training seed and no map of this robot with more: the between-seed "
                    "variance is unknown; " + evidence)
    p_paper = est.p(paper_effect) if est is not None and aware and num(paper_effect) else None
    return {"table": table, "claim": claim, "scope": scope, "estimate": est,
            "effect": effect if effect is not None else effect_text(est, null),
            "p": p if num(p) else None, "direction": direction or 0,
            "paper_effect": paper_effect, "p_paper": p_paper,
            "magnitude_claim": magnitude_claim, "evidence": evidence, "paper": paper,
            "seed_aware": aware, "seeds": None if est is None else est.seeds,
            "spread": None if est is None else est.spread}


def _not_run(table, claim, scope, evidence, paper) -> dict:
    return _line(table, claim, scope, evidence=evidence, paper=paper, effect="-")


def _paper_s(table: str, env: str, model: str, kind: str) -> float:
    return PAPER[table][env]["models"][model][kind]["success"]


def _paper_diff(table, env, a, b, kind) -> float:
    return _paper_s(table, env, a, kind) - _paper_s(table, env, b, kind)


def _seed_list(seeds: Seeds, env: str, q: Quantity) -> str:
    vals = seeds.values(env, q)
    return ", ".join(f"{signed(x)}" for _, x, _ in vals)


def _parts(parts, sign: int, need: str = "all"):
    """A claim of several parts ``[(label, estimate, null), ...]`` (every estimate not
    None): ``(direction, p, deciding part index)`` by the module docstring's rule."""
    k = len(parts)
    ps = [e.p(null) for _, e, null in parts]
    ds = [sign * (e.estimate - null) for _, e, null in parts]
    pos = [i for i in range(k) if ds[i] > 0]
    neg = [i for i in range(k) if ds[i] < 0]
    if need == "all":
        if len(pos) == k:
            i = max(pos, key=lambda j: ps[j])
            return 1, ps[i], i
        if neg:
            i = min(neg, key=lambda j: ps[j])
            return -1, min(1.0, k * ps[i]), i
        return 0, 1.0, max(range(k), key=lambda j: ps[j])
    if pos:  # need == "any"
        i = min(pos, key=lambda j: ps[j])
        return 1, min(1.0, k * ps[i]), i
    if len(neg) == k:
        i = max(neg, key=lambda j: ps[j])
        return -1, ps[i], i
    return 0, 1.0, max(range(k), key=lambda j: ps[j])


def _parts_line(table, claim, scope, parts, sign, paper, need="all") -> dict:
    """The line of a claim of several parts (not run if a part is missing)."""
    if any(e is None for _, e, _ in parts):
        return _not_run(table, claim, scope, "not run", paper)
    direction, p, i = _parts(parts, sign, need)
    label, e, null = parts[i]
    ev = "; ".join(f"{lab} {fixed(x.estimate) if nl else signed(x.estimate)} "
                   f"(p {p_value(x.p(nl))})" for lab, x, nl in parts)
    text = effect_text(e)
    if null:  # a level against a threshold: the level itself, not its distance
        text = text.split(" [", 1)
        lo, hi = e.ci()
        text = f"{fixed(e.estimate)} [{fixed(lo)}, {fixed(hi)}]" + text[1].split("]", 1)[1] \
            + f"; vs {null}"
    return _line(table, claim, scope, est=e, null=null, sign=sign, p=p, direction=direction,
                 evidence=f"parts: {ev}", paper=paper, effect=f"{label}: {text}",
                 aware=all(x.seed_aware for _, x, _ in parts))


def _claims_pnet_vs_pnet0(seeds: Seeds) -> list[dict]:
    """PNet_3 >= PNet_0 on non-trivial queries per map, per robot and over all 11 maps;
    PNet_2 and PNet_3 >= PNet_0 over both kinds per robot ("In most cases, PNet_2 and PNet_3
    outperform PNet_0 in terms of success ratio")."""
    out, every, every_paper = [], [], []
    for table in ("I", "II", "IV"):
        spec = PAPER_TABLES[table]
        q = q_diff("PNet_3", "PNet_0", "nontrivial")
        ests, pds = [], []
        for env in spec["envs"]:
            e = seeds.estimate(env, q)
            pd = _paper_diff(table, env, "PNet_3", "PNet_0", "nontrivial")
            ests.append(e)
            pds.append(pd)
            paper = (f"{fixed(_paper_s(table, env, 'PNet_3', 'nontrivial'))} vs "
                     f"{fixed(_paper_s(table, env, 'PNet_0', 'nontrivial'))} ({signed(pd)})")
            if e is None:
                out.append(_not_run(table, HEADLINE_CLAIM, env, "not run", paper))
                continue
            out.append(_line(table, HEADLINE_CLAIM, env, est=e, paper_effect=pd, paper=paper,
                             evidence=f"per seed {_seed_list(seeds, env, q)}"))
        every += ests
        every_paper += pds
        out.append(_pooled_line(table, HEADLINE_CLAIM, f"{spec['task']}, pooled over "
                                f"{len(ests)} maps", ests, pds, "PNet_3"))
        for model in ("PNet_2", "PNet_3"):
            qk = q_diff_kinds(model, "PNet_0")
            pk = [_paper_diff(table, e, model, "PNet_0", k) for e in spec["envs"] for k in KINDS]
            out.append(_pooled_line(table, f"{model} >= PNet_0 in success (both kinds)",
                                    f"{spec['task']}, pooled over {len(spec['envs'])} maps",
                                    [seeds.estimate(env, qk) for env in spec["envs"]], pk, model))
    out.append(_pooled_line("I, II, IV", HEADLINE_CLAIM, f"all {len(every)} maps, pooled",
                            every, every_paper, "PNet_3"))
    return out


def _pooled_line(table, claim, scope, ests, paper_diffs, model) -> dict:
    paper = (f"mean diff {signed(sum(paper_diffs) / len(paper_diffs))}; {model} ahead in "
             f"{sum(d > 0 for d in paper_diffs)} of {len(paper_diffs)}")
    if any(e is None for e in ests):
        n_run = sum(e is not None for e in ests)
        return _not_run(table, claim, scope, f"not run ({n_run} of {len(ests)} maps present)",
                        paper)
    e = combine(ests)
    return _line(table, claim, scope, est=e, paper_effect=sum(paper_diffs) / len(paper_diffs),
                 paper=paper, evidence="mean of the maps' estimates"
                 + (" (one-seed maps borrow their robot's between-seed variance)"
                    if e.borrowed else ""))


def _claims_point_90(seeds: Seeds) -> list[dict]:
    """"For the case of point robot planning, all models perform well with a success rate of
    over 90%": every member on both kinds above 0.9, per map."""
    out = []
    text = "every model succeeds on over 90% of queries"
    for env in PAPER_TABLES["I"]["envs"]:
        pmin = min(_paper_s("I", env, m, k) for m in MEMBERS for k in KINDS)
        paper = f"min {pmin:.3f}" + ("" if pmin > 0.9 else " (not so in the paper)")
        parts = [(f"{m} {kind_name(k)}", seeds.estimate(env, q_level(m, k)), 0.9)
                 for m in MEMBERS for k in KINDS]
        out.append(_parts_line("I", text, env, parts, 1, paper))
    return out


def _claims_rank(seeds: Seeds, table, model, others, sign, kinds, text) -> list[dict]:
    """``model`` above (sign +1) or below (sign -1) each of ``others`` on each map and kind."""
    spec = PAPER_TABLES[table]
    out = []
    for env in spec["envs"]:
        for kind in kinds:
            parts = [(f"vs {o}", seeds.estimate(env, q_diff(model, o, kind, spec["steer"])), 0.0)
                     for o in others]
            ps = _paper_s(table, env, model, kind)
            paper = ", ".join(f"{m} {fixed(_paper_s(table, env, m, kind))}"
                              for m in (model,) + tuple(others))
            ok = all(sign * (ps - _paper_s(table, env, o, kind)) >= 0 for o in others)
            out.append(_parts_line(table, text, f"{env}, {kind_name(kind)}", parts, sign,
                                   paper + ("" if ok else " (not so in the paper)")))
    return out


def _claims_nlink(seeds: Seeds) -> list[dict]:
    """Table IV: uniform success about 0.9, 0.8, 0.7 for 2, 4, 6 links (tested as falling
    with the number of links) and PNet_3 about 25% above PNet_0 on 6-link non-trivial."""
    envs = PAPER_TABLES["IV"]["envs"]
    q = q_members("uniform")
    lv = [seeds.estimate(e, q) for e in envs]
    paper = "; ".join(f"{e} {sum(_paper_s('IV', e, m, 'uniform') for m in MEMBERS) / 4:.3f}"
                      for e in envs)
    text = ("uniform success about 0.9, 0.8, 0.7 for 2, 4, 6 links (falls with the number of "
            "links; mean of PNet_0..3)")
    parts = [(f"{envs[i]} minus {envs[i + 1]}",
              None if lv[i] is None or lv[i + 1] is None else combine([lv[i], lv[i + 1]],
                                                                     [1, -1]), 0.0)
             for i in (0, 1)]
    line = _parts_line("IV", text, "nlink", parts, 1, paper)
    if all(x is not None for x in lv):
        line["evidence"] += "; levels " + ", ".join(f"{e} {fixed(x.estimate)}"
                                                    for e, x in zip(envs, lv))
    out = [line]
    e = seeds.estimate("nlink/6", q_diff("PNet_3", "PNet_0", "nontrivial"))
    p0 = seeds.estimate("nlink/6", q_level("PNet_0", "nontrivial"))
    pp0, pp3 = (_paper_s("IV", "nlink/6", m, "nontrivial") for m in ("PNet_0", "PNet_3"))
    paper = f"{pp3:.3f} vs {pp0:.3f} ({pp3 / pp0 - 1:+.1%})"
    text = "PNet_3 about 25% above PNet_0 in success on non-trivial queries"
    scope = "nlink/6 (claimed diff = 0.25 x our PNet_0)"
    if e is None or p0 is None or p0.estimate <= 0:
        out.append(_not_run("IV", text, scope, "not run", paper))
        return out
    claimed = 0.25 * p0.estimate
    line = _line("IV", text, scope, est=e, paper_effect=claimed, magnitude_claim=True,
                 paper=paper, evidence=f"ours {e.estimate / p0.estimate:+.1%} of our PNet_0 "
                 f"{fixed(p0.estimate)}; claimed diff {signed(claimed)}, p of the claimed diff "
                 f"{p_value(e.p(claimed))} ("
                 + ("our gain is smaller" if e.estimate < claimed else "our gain is larger") + ")")
    out.append(line)
    return out


def _claims_nlink_gain(seeds: Seeds) -> list[dict]:
    """"For the relatively simpler 2-link planning case ... only small gains ... much more
    evident for the higher dimensional 4 and 6-link cases": the gain PNet_3 - PNet_0
    (non-trivial) of the 4- and of the 6-link arm each above the 2-link arm's."""
    envs = PAPER_TABLES["IV"]["envs"]
    q = q_diff("PNet_3", "PNet_0", "nontrivial")
    g = [seeds.estimate(e, q) for e in envs]
    pd = [_paper_diff("IV", e, "PNet_3", "PNet_0", "nontrivial") for e in envs]
    paper = ", ".join(f"{e} {signed(d)}" for e, d in zip(envs, pd))
    parts = [(f"{envs[i]} minus {envs[0]}",
              None if g[i] is None or g[0] is None else combine([g[i], g[0]], [1, -1]), 0.0)
             for i in (1, 2)]
    return [_parts_line("IV", "PNet_3's gain over PNet_0 (non-trivial) larger for 4 and 6 "
                        "links than for 2 links", "nlink", parts, 1, paper)]


def _mean_cost(seeds: Seeds, env: str):
    """The map's mean cost ratio over PNet_0..3 and both kinds, averaged over its seeds."""
    vals = []
    for s in seeds.runs.get(env, []) if env in seeds.main else []:
        rs = [run_cells(s, True).get((m, k)) for m in MEMBERS for k in KINDS]
        if all(r is not None and num(r.get("cost_ratio")) for r in rs):
            vals.append(sum(r["cost_ratio"] for r in rs) / len(rs))
    return sum(vals) / len(vals) if vals else None


def _paper_cost(table, env):
    ms = PAPER[table][env]["models"]
    return sum(ms[m][k]["cost"] for m in MEMBERS for k in KINDS) / (len(MEMBERS) * len(KINDS))


#: "The cost ratio is relatively lower for the rigid body and 6-link case compared to
#: others": the maps of the low group (table, env) and of the others.
_LOW_COST = tuple(("II", e) for e in PAPER_TABLES["II"]["envs"]) + (("IV", "nlink/6"),)
_OTHER_COST = tuple(("I", e) for e in PAPER_TABLES["I"]["envs"]) + (("IV", "nlink/2"),
                                                                    ("IV", "nlink/4"))


def _references(seeds: Seeds) -> str:
    """Our reference planners per robot (the cost ratio's denominator)."""
    refs = {}
    for env, s in seeds.main.items():
        for r in s.get("rows", []):
            refs.setdefault(env.split("/")[0], set()).add(str(r.get("reference_planner")))
    return ", ".join(f"{t} {'/'.join(sorted(v))}" for t, v in sorted(refs.items()))


def _claims_cost(seeds: Seeds) -> list[dict]:
    """Cost ratio lower for rigid body and 6-link than for the other maps: the maps' mean
    cost ratio (PNet_0..3, both kinds, mean over seeds), exact Mann-Whitney test between
    the two groups of maps (all 11 needed). Our cost ratio's denominator is our reference
    planner, not the paper's BIT*."""
    from scipy.stats import mannwhitneyu
    low = [_mean_cost(seeds, e) for _, e in _LOW_COST]
    other = [_mean_cost(seeds, e) for _, e in _OTHER_COST]
    pl, po = [_paper_cost(t, e) for t, e in _LOW_COST], [_paper_cost(t, e) for t, e in _OTHER_COST]
    paper = f"mean {sum(pl) / len(pl):.3f} vs {sum(po) / len(po):.3f} (against BIT*)"
    text = "cost ratio lower for rigid body and 6-link than for the other maps"
    scope = ("rigid/0-3 + nlink/6 vs point/0-3 + nlink/2, nlink/4; ours against our "
             f"reference planners ({_references(seeds)}), not the paper's BIT*")
    if any(x is None for x in low + other):
        n = sum(x is not None for x in low + other)
        return [_not_run("I, II, IV", text, scope, f"{n} of 11 maps run", paper)]
    p_less = float(mannwhitneyu(low, other, alternative="less", method="exact").pvalue)
    p_greater = float(mannwhitneyu(low, other, alternative="greater", method="exact").pvalue)
    ml, mo = sum(low) / len(low), sum(other) / len(other)
    eff = f"{signed(ml - mo)} (mean {ml:.3f} vs {mo:.3f}, maps as units)"
    return [_line("I, II, IV", text, scope, p=min(1.0, 2 * min(p_less, p_greater)),
                  direction=1 if p_less < p_greater else -1 if p_greater < p_less else 0,
                  effect=eff, paper=paper,
                  evidence=f"exact Mann-Whitney, one-sided p {p_value(p_less)} (lower) / "
                           f"{p_value(p_greater)} (higher)")]


def _claims_uniform_above_nt(seeds: Seeds, table) -> list[dict]:
    """"The success ratio for all PNet models is naturally higher over uniform test queries
    rather than non-trivial test queries": per model, uniform minus non-trivial success
    pooled over the task's maps; every model needed."""
    spec = PAPER_TABLES[table]
    parts, paper = [], []
    for m in MEMBERS:
        es = [seeds.estimate(e, q_kind_gap(m, spec["steer"])) for e in spec["envs"]]
        parts.append((m, None if any(x is None for x in es) else combine(es), 0.0))
        pu = [_paper_s(table, e, m, "uniform") - _paper_s(table, e, m, "nontrivial")
              for e in spec["envs"]]
        paper.append(f"{m} {sum(d > 0 for d in pu)}/{len(pu)} maps")
    return [_parts_line(table, "success higher on uniform than on non-trivial queries, every "
                        "model", f"{spec['task']}, pooled over {len(spec['envs'])} maps",
                        parts, 1, "uniform above in " + ", ".join(paper))]


def _gamma(seeds: Seeds, env: str, steer=True):
    cells = run_cells(seeds.main.get(env), steer)
    r = cells.get(("PNet_0", "uniform")) or next(iter(cells.values()), None)
    return None if r is None else r.get("gamma_nt")


def _trend(points_by_task: dict):
    """Kendall's tau of (gamma_nt, success) within each task, combined over tasks."""
    strata = [(list(x), list(y)) for x, y in points_by_task.values() if len(x) >= 2]
    return stratified_kendall(strata)


def _claims_gamma(seeds: Seeds, tables, scope, label: str | None = None) -> list[dict]:
    """"The success ratio also generally has an inverse relation with gamma_nt": Kendall's
    tau between gamma_nt and the mean success over PNet_0..3 (mean over seeds), per query
    kind; over several robots stratified by robot."""
    out = []
    for kind in KINDS:
        ours, paper = {}, {}
        pts = []
        for table in tables:
            spec = PAPER_TABLES[table]
            for env in spec["envs"]:
                pg = PAPER[table][env]["gamma_nt"]
                ps = sum(_paper_s(table, env, m, kind) for m in MEMBERS) / len(MEMBERS)
                paper.setdefault(spec["task"], ([], []))
                paper[spec["task"]][0].append(pg)
                paper[spec["task"]][1].append(ps)
                e = seeds.estimate(env, q_members(kind, spec["steer"]))
                g = _gamma(seeds, env, spec["steer"])
                if e is not None and num(g):
                    ours.setdefault(spec["task"], ([], []))
                    ours[spec["task"]][0].append(g)
                    ours[spec["task"]][1].append(e.estimate)
                    pts.append((g, e.estimate))
        ptau, pl, pg_ = _trend(paper)
        strat = " within robots" if len(tables) > 1 else ""
        paper_txt = (f"tau {ptau:+.2f}{strat} over {sum(len(x) for x, _ in paper.values())} "
                     f"maps (two-sided p {p_value(min(1.0, 2 * min(pl, pg_)))})")
        text = f"success falls as gamma_nt rises ({kind_name(kind)} queries, mean of PNet_0..3)"
        n_maps = sum(len(x) for x, _ in ours.values())
        need = sum(len(PAPER_TABLES[t]["envs"]) for t in tables)
        pts_txt = ", ".join(f"{g:.3f}: {s:.3f}" for g, s in sorted(pts))
        if n_maps < need:
            out.append(_not_run(label or tables[0], text, scope, f"{n_maps} of {need} maps run"
                                + (f" (gamma_nt: success {pts_txt})" if pts else ""), paper_txt))
            continue
        tau, p_less, p_greater = _trend(ours)
        p = min(1.0, 2 * min(p_less, p_greater))
        few = (f" ({n_maps} maps: the smallest two-sided p is {2 / math.factorial(n_maps):.3f})"
               if len(tables) == 1 and n_maps <= 4 else "")
        out.append(_line(label or tables[0], text, scope, p=p,
                         direction=1 if p_less < p_greater else -1 if p_greater < p_less else 0,
                         effect=f"Kendall tau {tau:+.2f}{strat} over {n_maps} maps{few}",
                         paper=paper_txt, evidence=f"gamma_nt: success {pts_txt}"))
    return out


def _claims_nosteer(seeds: Seeds) -> list[dict]:
    """Table III: PNet_3 worst, PNet_0 best on uniform, PNet_1/2 better on non-trivial in some
    cases, and every model below its steerTo success."""
    out = _claims_rank(seeds, "III", "PNet_3", ("PNet_0", "PNet_1", "PNet_2"), -1, KINDS,
                       "without steerTo PNet_3 is the worst")
    out += _claims_rank(seeds, "III", "PNet_0", ("PNet_1", "PNet_2", "PNet_3"), 1, ("uniform",),
                        "without steerTo PNet_0 is the best on uniform queries")
    envs = PAPER_TABLES["III"]["envs"]
    parts = [(f"{e} {m}", seeds.estimate(e, q_diff(m, "PNet_0", "nontrivial", False)), 0.0)
             for e in envs for m in ("PNet_1", "PNet_2")]
    paper = "; ".join(f"{e} {m} {signed(_paper_diff('III', e, m, 'PNet_0', 'nontrivial'))}"
                      for e in envs for m in ("PNet_1", "PNet_2"))
    out.append(_parts_line("III", "without steerTo PNet_1 or PNet_2 beats PNet_0 on non-trivial "
                           "queries in some cases", "rigid, any map", parts, 1, paper, need="any"))
    for m in MEMBERS:
        es = [seeds.estimate(e, q_steer_gap(m)) for e in envs]
        pp = [_paper_s("II", e, m, k) - _paper_s("III", e, m, k) for e in envs for k in KINDS]
        paper = f"below in {sum(d > 0 for d in pp)}/{len(pp)} (mean {signed(-sum(pp) / len(pp))})"
        text = "the success of every model falls without steerTo"
        scope = f"rigid, {m}, pooled over maps and kinds"
        if any(x is None for x in es):
            out.append(_not_run("III", text, scope, "not run", paper))
            continue
        e = combine(es)
        out.append(_line("III", text, scope, est=e, paper=paper,
                         effect=f"with minus without steerTo {effect_text(e)}"))
    return out


def claims(summaries) -> list[dict]:
    """The paper's claims checked on ``summaries`` (every map's runs, one per training
    seed), one dict per line: ``table``, ``claim``, ``scope``, ``effect`` (text),
    ``estimate`` (:class:`ntq_jax.stats.SeedEstimate` or None), ``seeds``, ``spread``,
    ``p`` and ``p_holm``, ``paper_effect`` with ``p_paper`` and ``p_paper_holm`` (the test
    of the paper's magnitude, where the claim has one), ``verdict`` (:data:`VERDICTS`),
    ``evidence`` and ``paper``."""
    seeds = Seeds(summaries)
    out = _claims_pnet_vs_pnet0(seeds)
    out += _claims_point_90(seeds)
    out += _claims_rank(seeds, "II", "PNet_3", ("PNet_0", "PNet_1", "PNet_2"), 1, KINDS,
                        "with steerTo PNet_3 has the highest success (paper: all but rigid/3 "
                        "non-trivial)")
    out += _claims_nlink(seeds)
    out += _claims_nlink_gain(seeds)
    out += _claims_cost(seeds)
    for table in ("I", "II", "IV"):
        out += _claims_uniform_above_nt(seeds, table)
    for table in ("I", "II", "IV"):
        out += _claims_gamma(seeds, (table,), PAPER_TABLES[table]["task"])
    out += _claims_gamma(seeds, ("I", "II", "IV"), "all 11 maps, within robots", "I, II, IV")
    out += _claims_nosteer(seeds)
    family = [c["p"] for c in out] + [c["p_paper"] for c in out]
    adj = holm([float("nan") if x is None else x for x in family])
    n = len(out)
    for i, c in enumerate(out):
        c["p_holm"] = None if c["p"] is None else float(adj[i])
        c["p_paper_holm"] = None if c["p_paper"] is None else float(adj[n + i])
        c["verdict"] = (UNRESOLVED if not c["seed_aware"] else
                        verdict(c["direction"], c["p_holm"], c["p_paper_holm"],
                                magnitude_claim=c["magnitude_claim"]))
    return out


def family_size(cs) -> int:
    """The number of p-values Holm adjusted together."""
    return sum(c["p"] is not None for c in cs) + sum(c["p_paper"] is not None for c in cs)


def headline(cs) -> list[dict]:
    """The claim lines of the one-page summary: PNet_3 >= PNet_0 on non-trivial queries per
    map, per robot and over all maps, in the paper's order."""
    return [c for c in cs if c["claim"] == HEADLINE_CLAIM]
