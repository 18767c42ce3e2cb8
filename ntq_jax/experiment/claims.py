"""The paper's claims checked against our summaries, with training seeds as a random effect.

Every claim is one line with an effect, its 95 % interval, a p-value, the spread
between training seeds, a Holm-adjusted p-value and a verdict. The claims, their tests
and the rule are written once, here and in the modules below; ``REPRODUCTION.md`` and
``docs/guide/reproducing-the-paper.md`` quote them.

The claims are defined here, one function per claim of the paper's Results section
(:func:`claims` lists them all); what they stand on:

* **the test**: the quantities measured in every training seed and their estimates
  over a map's seeds, the training seed a random effect
  (:mod:`ntq_jax.experiment.quantities`, on :mod:`ntq_jax.seed_effects`);
* **the line**: our effect, its test and the paper's value as one dict
  (:mod:`ntq_jax.experiment.claim_lines`);
* **the verdict**: claims of several parts, Holm's correction over every p-value a
  verdict uses, and the rule (holds, contradicted, the paper's magnitude excluded,
  unresolved, not run): :mod:`ntq_jax.experiment.verdicts`, whose names
  (:data:`ALPHA`, :data:`VERDICTS`, :func:`verdict`, ...) are importable from here too.

**Trends over maps** (maps are the units; each map's value is its mean over
seeds): "success falls as gamma_nt rises" is Kendall's tau with its exact p,
within a robot, and over all 11 maps stratified by robot
(:func:`ntq_jax.stats.stratified_kendall`: robots differ in level, so a pooled
trend would compare robots, not gamma_nt); "the cost ratio is lower for the rigid
body and the 6-link arm" is the exact Mann-Whitney test of the maps' mean cost
ratios. Their p-values are two-sided (twice the smaller one-sided p).
"""

from __future__ import annotations

import math

from ntq_jax.experiment.claim_lines import claim_line, effect_text, not_run, parts_line, pooled_line
from ntq_jax.experiment.formatting import fixed, kind_name, num, p_value, signed
from ntq_jax.experiment.paper import KINDS, MEMBERS, PAPER, PAPER_TABLES
from ntq_jax.experiment.quantities import (
    Quantity,
    Seeds,
    q_diff,
    q_diff_kinds,
    q_kind_gap,
    q_level,
    q_members,
    q_steer_gap,
)
from ntq_jax.experiment.summaries import run_cells
from ntq_jax.experiment.verdicts import (
    ALPHA,
    CONTRADICTED,
    FAILS,
    HOLDS,
    MAGNITUDE,
    NOT_RUN,
    UNRESOLVED,
    VERDICTS,
    decide,
    family_size,
    verdict,
)
from ntq_jax.seed_effects import combine
from ntq_jax.stats import stratified_kendall

__all__ = [
    "ALPHA",
    "HOLDS",
    "CONTRADICTED",
    "FAILS",
    "MAGNITUDE",
    "UNRESOLVED",
    "NOT_RUN",
    "VERDICTS",
    "verdict",
    "Seeds",
    "Quantity",
    "claims",
    "headline",
    "HEADLINE_CLAIM",
    "effect_text",
    "family_size",
]

HEADLINE_CLAIM = "PNet_3 >= PNet_0 in success on non-trivial queries"


def _paper_s(table: str, env: str, model: str, kind: str) -> float:
    return PAPER[table][env]["models"][model][kind]["success"]


def _paper_diff(table, env, a, b, kind) -> float:
    return _paper_s(table, env, a, kind) - _paper_s(table, env, b, kind)


def _seed_list(seeds: Seeds, env: str, q: Quantity) -> str:
    vals = seeds.values(env, q)
    return ", ".join(f"{signed(x)}" for _, x, _ in vals)


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
            paper = (
                f"{fixed(_paper_s(table, env, 'PNet_3', 'nontrivial'))} vs "
                f"{fixed(_paper_s(table, env, 'PNet_0', 'nontrivial'))} ({signed(pd)})"
            )
            if e is None:
                out.append(not_run(table, HEADLINE_CLAIM, env, "not run", paper))
                continue
            out.append(
                claim_line(
                    table,
                    HEADLINE_CLAIM,
                    env,
                    est=e,
                    paper_effect=pd,
                    paper=paper,
                    evidence=f"per seed {_seed_list(seeds, env, q)}",
                )
            )
        every += ests
        every_paper += pds
        out.append(
            pooled_line(
                table,
                HEADLINE_CLAIM,
                f"{spec['task']}, pooled over {len(ests)} maps",
                ests,
                pds,
                "PNet_3",
            )
        )
        for model in ("PNet_2", "PNet_3"):
            qk = q_diff_kinds(model, "PNet_0")
            pk = [_paper_diff(table, e, model, "PNet_0", k) for e in spec["envs"] for k in KINDS]
            out.append(
                pooled_line(
                    table,
                    f"{model} >= PNet_0 in success (both kinds)",
                    f"{spec['task']}, pooled over {len(spec['envs'])} maps",
                    [seeds.estimate(env, qk) for env in spec["envs"]],
                    pk,
                    model,
                )
            )
    out.append(
        pooled_line(
            "I, II, IV",
            HEADLINE_CLAIM,
            f"all {len(every)} maps, pooled",
            every,
            every_paper,
            "PNet_3",
        )
    )
    return out


def _claims_point_90(seeds: Seeds) -> list[dict]:
    """ "For the case of point robot planning, all models perform well with a success rate of
    over 90%": every member on both kinds above 0.9, per map."""
    out = []
    text = "every model succeeds on over 90% of queries"
    for env in PAPER_TABLES["I"]["envs"]:
        pmin = min(_paper_s("I", env, m, k) for m in MEMBERS for k in KINDS)
        paper = f"min {pmin:.3f}" + ("" if pmin > 0.9 else " (not so in the paper)")
        parts = [
            (f"{m} {kind_name(k)}", seeds.estimate(env, q_level(m, k)), 0.9)
            for m in MEMBERS
            for k in KINDS
        ]
        out.append(parts_line("I", text, env, parts, 1, paper))
    return out


def _claims_rank(seeds: Seeds, table, model, others, sign, kinds, text) -> list[dict]:
    """``model`` above (sign +1) or below (sign -1) each of ``others`` on each map and kind."""
    spec = PAPER_TABLES[table]
    out = []
    for env in spec["envs"]:
        for kind in kinds:
            parts = [
                (f"vs {o}", seeds.estimate(env, q_diff(model, o, kind, spec["steer"])), 0.0)
                for o in others
            ]
            ps = _paper_s(table, env, model, kind)
            paper = ", ".join(
                f"{m} {fixed(_paper_s(table, env, m, kind))}" for m in (model,) + tuple(others)
            )
            ok = all(sign * (ps - _paper_s(table, env, o, kind)) >= 0 for o in others)
            out.append(
                parts_line(
                    table,
                    text,
                    f"{env}, {kind_name(kind)}",
                    parts,
                    sign,
                    paper + ("" if ok else " (not so in the paper)"),
                )
            )
    return out


def _claims_nlink(seeds: Seeds) -> list[dict]:
    """Table IV: uniform success about 0.9, 0.8, 0.7 for 2, 4, 6 links (tested as falling
    with the number of links) and PNet_3 about 25% above PNet_0 on 6-link non-trivial."""
    envs = PAPER_TABLES["IV"]["envs"]
    q = q_members("uniform")
    lv = [seeds.estimate(e, q) for e in envs]
    paper = "; ".join(
        f"{e} {sum(_paper_s('IV', e, m, 'uniform') for m in MEMBERS) / 4:.3f}" for e in envs
    )
    text = (
        "uniform success about 0.9, 0.8, 0.7 for 2, 4, 6 links (falls with the number of "
        "links; mean of PNet_0..3)"
    )
    parts = [
        (
            f"{envs[i]} minus {envs[i + 1]}",
            None if lv[i] is None or lv[i + 1] is None else combine([lv[i], lv[i + 1]], [1, -1]),
            0.0,
        )
        for i in (0, 1)
    ]
    line = parts_line("IV", text, "nlink", parts, 1, paper)
    if all(x is not None for x in lv):
        line["evidence"] += "; levels " + ", ".join(
            f"{e} {fixed(x.estimate)}" for e, x in zip(envs, lv)
        )
    out = [line]
    e = seeds.estimate("nlink/6", q_diff("PNet_3", "PNet_0", "nontrivial"))
    p0 = seeds.estimate("nlink/6", q_level("PNet_0", "nontrivial"))
    pp0, pp3 = (_paper_s("IV", "nlink/6", m, "nontrivial") for m in ("PNet_0", "PNet_3"))
    paper = f"{pp3:.3f} vs {pp0:.3f} ({pp3 / pp0 - 1:+.1%})"
    text = "PNet_3 about 25% above PNet_0 in success on non-trivial queries"
    scope = "nlink/6 (claimed diff = 0.25 x our PNet_0)"
    if e is None or p0 is None or p0.estimate <= 0:
        out.append(not_run("IV", text, scope, "not run", paper))
        return out
    claimed = 0.25 * p0.estimate
    gain = "our gain is smaller" if e.estimate < claimed else "our gain is larger"
    line = claim_line(
        "IV",
        text,
        scope,
        est=e,
        paper_effect=claimed,
        magnitude_claim=True,
        paper=paper,
        evidence=f"ours {e.estimate / p0.estimate:+.1%} of our "
        f"PNet_0 {fixed(p0.estimate)}; claimed diff {signed(claimed)}, p of the "
        f"claimed diff {p_value(e.p(claimed))} ({gain})",
    )
    out.append(line)
    return out


def _claims_nlink_gain(seeds: Seeds) -> list[dict]:
    """ "For the relatively simpler 2-link planning case ... only small gains ... much more
    evident for the higher dimensional 4 and 6-link cases": the gain PNet_3 - PNet_0
    (non-trivial) of the 4- and of the 6-link arm each above the 2-link arm's."""
    envs = PAPER_TABLES["IV"]["envs"]
    q = q_diff("PNet_3", "PNet_0", "nontrivial")
    g = [seeds.estimate(e, q) for e in envs]
    pd = [_paper_diff("IV", e, "PNet_3", "PNet_0", "nontrivial") for e in envs]
    paper = ", ".join(f"{e} {signed(d)}" for e, d in zip(envs, pd))
    parts = [
        (
            f"{envs[i]} minus {envs[0]}",
            None if g[i] is None or g[0] is None else combine([g[i], g[0]], [1, -1]),
            0.0,
        )
        for i in (1, 2)
    ]
    return [
        parts_line(
            "IV",
            "PNet_3's gain over PNet_0 (non-trivial) larger for 4 and 6 links than for 2 links",
            "nlink",
            parts,
            1,
            paper,
        )
    ]


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
_OTHER_COST = tuple(("I", e) for e in PAPER_TABLES["I"]["envs"]) + (
    ("IV", "nlink/2"),
    ("IV", "nlink/4"),
)


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
    scope = (
        "rigid/0-3 + nlink/6 vs point/0-3 + nlink/2, nlink/4; ours against our "
        f"reference planners ({_references(seeds)}), not the paper's BIT*"
    )
    if any(x is None for x in low + other):
        n = sum(x is not None for x in low + other)
        return [not_run("I, II, IV", text, scope, f"{n} of 11 maps run", paper)]
    p_less = float(mannwhitneyu(low, other, alternative="less", method="exact").pvalue)
    p_greater = float(mannwhitneyu(low, other, alternative="greater", method="exact").pvalue)
    ml, mo = sum(low) / len(low), sum(other) / len(other)
    eff = f"{signed(ml - mo)} (mean {ml:.3f} vs {mo:.3f}, maps as units)"
    return [
        claim_line(
            "I, II, IV",
            text,
            scope,
            p=min(1.0, 2 * min(p_less, p_greater)),
            direction=1 if p_less < p_greater else -1 if p_greater < p_less else 0,
            effect=eff,
            paper=paper,
            evidence=f"exact Mann-Whitney, one-sided p {p_value(p_less)} (lower) / "
            f"{p_value(p_greater)} (higher)",
        )
    ]


def _claims_uniform_above_nt(seeds: Seeds, table) -> list[dict]:
    """ "The success ratio for all PNet models is naturally higher over uniform test queries
    rather than non-trivial test queries": per model, uniform minus non-trivial success
    pooled over the task's maps; every model needed."""
    spec = PAPER_TABLES[table]
    parts, paper = [], []
    for m in MEMBERS:
        es = [seeds.estimate(e, q_kind_gap(m, spec["steer"])) for e in spec["envs"]]
        parts.append((m, None if any(x is None for x in es) else combine(es), 0.0))
        pu = [
            _paper_s(table, e, m, "uniform") - _paper_s(table, e, m, "nontrivial")
            for e in spec["envs"]
        ]
        paper.append(f"{m} {sum(d > 0 for d in pu)}/{len(pu)} maps")
    return [
        parts_line(
            table,
            "success higher on uniform than on non-trivial queries, every model",
            f"{spec['task']}, pooled over {len(spec['envs'])} maps",
            parts,
            1,
            "uniform above in " + ", ".join(paper),
        )
    ]


def _gamma(seeds: Seeds, env: str, steer=True):
    cells = run_cells(seeds.main.get(env), steer)
    r = cells.get(("PNet_0", "uniform")) or next(iter(cells.values()), None)
    return None if r is None else r.get("gamma_nt")


def _trend(points_by_task: dict):
    """Kendall's tau of (gamma_nt, success) within each task, combined over tasks."""
    strata = [(list(x), list(y)) for x, y in points_by_task.values() if len(x) >= 2]
    return stratified_kendall(strata)


def _claims_gamma(seeds: Seeds, tables, scope, label: str | None = None) -> list[dict]:
    """ "The success ratio also generally has an inverse relation with gamma_nt": Kendall's
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
        paper_txt = (
            f"tau {ptau:+.2f}{strat} over {sum(len(x) for x, _ in paper.values())} "
            f"maps (two-sided p {p_value(min(1.0, 2 * min(pl, pg_)))})"
        )
        text = f"success falls as gamma_nt rises ({kind_name(kind)} queries, mean of PNet_0..3)"
        n_maps = sum(len(x) for x, _ in ours.values())
        need = sum(len(PAPER_TABLES[t]["envs"]) for t in tables)
        pts_txt = ", ".join(f"{g:.3f}: {s:.3f}" for g, s in sorted(pts))
        if n_maps < need:
            out.append(
                not_run(
                    label or tables[0],
                    text,
                    scope,
                    f"{n_maps} of {need} maps run"
                    + (f" (gamma_nt: success {pts_txt})" if pts else ""),
                    paper_txt,
                )
            )
            continue
        tau, p_less, p_greater = _trend(ours)
        p = min(1.0, 2 * min(p_less, p_greater))
        few = (
            f" ({n_maps} maps: the smallest two-sided p is {2 / math.factorial(n_maps):.3f})"
            if len(tables) == 1 and n_maps <= 4
            else ""
        )
        direction = 1 if p_less < p_greater else -1 if p_greater < p_less else 0
        out.append(
            claim_line(
                label or tables[0],
                text,
                scope,
                p=p,
                direction=direction,
                effect=f"Kendall tau {tau:+.2f}{strat} over {n_maps} maps{few}",
                paper=paper_txt,
                evidence=f"gamma_nt: success {pts_txt}",
            )
        )
    return out


def _claims_nosteer(seeds: Seeds) -> list[dict]:
    """Table III: PNet_3 worst, PNet_0 best on uniform, PNet_1/2 better on non-trivial in some
    cases, and every model below its steerTo success."""
    out = _claims_rank(
        seeds,
        "III",
        "PNet_3",
        ("PNet_0", "PNet_1", "PNet_2"),
        -1,
        KINDS,
        "without steerTo PNet_3 is the worst",
    )
    out += _claims_rank(
        seeds,
        "III",
        "PNet_0",
        ("PNet_1", "PNet_2", "PNet_3"),
        1,
        ("uniform",),
        "without steerTo PNet_0 is the best on uniform queries",
    )
    envs = PAPER_TABLES["III"]["envs"]
    parts = [
        (f"{e} {m}", seeds.estimate(e, q_diff(m, "PNet_0", "nontrivial", False)), 0.0)
        for e in envs
        for m in ("PNet_1", "PNet_2")
    ]
    paper = "; ".join(
        f"{e} {m} {signed(_paper_diff('III', e, m, 'PNet_0', 'nontrivial'))}"
        for e in envs
        for m in ("PNet_1", "PNet_2")
    )
    out.append(
        parts_line(
            "III",
            "without steerTo PNet_1 or PNet_2 beats PNet_0 on non-trivial queries in some cases",
            "rigid, any map",
            parts,
            1,
            paper,
            need="any",
        )
    )
    for m in MEMBERS:
        es = [seeds.estimate(e, q_steer_gap(m)) for e in envs]
        pp = [_paper_s("II", e, m, k) - _paper_s("III", e, m, k) for e in envs for k in KINDS]
        paper = f"below in {sum(d > 0 for d in pp)}/{len(pp)} (mean {signed(-sum(pp) / len(pp))})"
        text = "the success of every model falls without steerTo"
        scope = f"rigid, {m}, pooled over maps and kinds"
        if any(x is None for x in es):
            out.append(not_run("III", text, scope, "not run", paper))
            continue
        e = combine(es)
        out.append(
            claim_line(
                "III",
                text,
                scope,
                est=e,
                paper=paper,
                effect=f"with minus without steerTo {effect_text(e)}",
            )
        )
    return out


def claims(summaries) -> list[dict]:
    """The paper's claims checked on ``summaries`` (every map's runs, one per training
    seed), one dict per line: ``table``, ``claim``, ``scope``, ``effect`` (text),
    ``estimate`` (:class:`ntq_jax.seed_effects.SeedEstimate` or None), ``seeds``,
    ``spread``, ``p`` and ``p_holm``, ``paper_effect`` with ``p_paper`` and ``p_paper_holm``
    (the test of the paper's magnitude, where the claim has one), ``verdict``
    (:data:`VERDICTS`), ``evidence`` and ``paper``."""
    seeds = Seeds(summaries)
    out = _claims_pnet_vs_pnet0(seeds)
    out += _claims_point_90(seeds)
    out += _claims_rank(
        seeds,
        "II",
        "PNet_3",
        ("PNet_0", "PNet_1", "PNet_2"),
        1,
        KINDS,
        "with steerTo PNet_3 has the highest success (paper: all but rigid/3 non-trivial)",
    )
    out += _claims_nlink(seeds)
    out += _claims_nlink_gain(seeds)
    out += _claims_cost(seeds)
    for table in ("I", "II", "IV"):
        out += _claims_uniform_above_nt(seeds, table)
    for table in ("I", "II", "IV"):
        out += _claims_gamma(seeds, (table,), PAPER_TABLES[table]["task"])
    out += _claims_gamma(seeds, ("I", "II", "IV"), "all 11 maps, within robots", "I, II, IV")
    out += _claims_nosteer(seeds)
    return decide(out)


def headline(cs) -> list[dict]:
    """The claim lines of the one-page summary: PNet_3 >= PNet_0 on non-trivial queries per
    map, per robot and over all maps, in the paper's order."""
    return [c for c in cs if c["claim"] == HEADLINE_CLAIM]
