"""The verdicts in ``REPRODUCTION.md``: its one-page summary and its section of claims.

Both render the claim lines of :func:`ntq_jax.experiment.claims.claims` (each with its
estimate, p-value, Holm-adjusted p-value and verdict):

* :func:`summary_page`, the document's first section: PNet_3 - PNet_0 on non-trivial
  queries per map, per robot and over all maps, the paper's value beside ours with the
  seed-aware interval, the spread over seeds, p, Holm's p and the verdict (the lines of
  :func:`ntq_jax.experiment.claims.headline`);
* :func:`claims_section`, the last section: the test and the rule in words
  (:mod:`ntq_jax.experiment.verdicts`), the verdicts' counts and every claim's line.

Both return Markdown lines; :func:`summary_page` is also importable from
:mod:`ntq_jax.experiment.reproduction`.
"""

from __future__ import annotations

from ntq_jax.experiment.claims import headline
from ntq_jax.experiment.formatting import fixed, num, p_value, signed
from ntq_jax.experiment.paper import PAPER_TABLES
from ntq_jax.experiment.verdicts import ALPHA, NOT_RUN, VERDICTS, family_size

__all__ = ["summary_page", "claims_section"]


def _verdict_counts(cs) -> str:
    return ", ".join(
        f"{v} {sum(c['verdict'] == v for c in cs)}"
        for v in VERDICTS
        if v != NOT_RUN or any(c["verdict"] == v for c in cs)
    )


def summary_page(cs) -> list[str]:
    """The first section: the central claim per map, robot and over all maps (one screen)."""
    rows = headline(cs)
    if not rows:
        return []
    out = [
        "## Summary: does PNet_3 beat PNet_0?",
        "",
        "The paper's central claim: PNet_3 (trained on non-trivial queries, includeData's "
        "pruning) solves more non-trivial test queries than PNet_0 (uniform queries). Ours: "
        "PNet_3 - PNet_0 on the same 500 non-trivial test queries with steerTo, the mean over "
        "a map's training seeds (the same data trained again), with the 95 % interval of the "
        "seed-aware test (the training seed a random effect; a map with one seed borrows its "
        "robot's between-seed variance), the standard deviation of the per-seed "
        "differences, the p-value, the p-value Holm-adjusted over all "
        f"{family_size(cs)} tests of this page's verdicts, and the verdict. A pooled row is "
        'the mean over its maps. Test, rule and coverage: the section "Claims of the '
        'paper" and `seed_test_coverage.md`.',
        "",
        "| robot | scope | seeds | paper | ours [95 %] | sd over seeds | p | Holm p | verdict |",
        "|---|---|---:|---:|---|---:|---:|---:|---|",
    ]
    for c in rows:
        e = c["estimate"]
        robot = {t: spec["task"] for t, spec in PAPER_TABLES.items()}.get(c["table"], "all")
        scope = c["scope"]
        if "pooled" in scope:
            n_maps = sum(
                "pooled" not in x["scope"] and (robot == "all" or x["table"] == c["table"])
                for x in rows
            )
            scope = f"**pooled, {n_maps} maps**"
        if e is None:
            out.append(
                f"| {robot} | {scope} | - | {signed(c['paper_effect'])} | not run | - | - "
                f"| - | {c['verdict']} |"
            )
            continue
        lo, hi = e.ci()
        sd = "borrowed" if e.borrowed and not num(e.spread) else fixed(e.spread)
        out.append(
            f"| {robot} | {scope} | {e.seeds} | {signed(c['paper_effect'])} | "
            f"{signed(e.estimate)} [{signed(lo)}, {signed(hi)}] | {sd} | "
            f"{p_value(c['p'])} | {p_value(c['p_holm'])} | **{c['verdict']}** |"
        )
    out += ["", f"All {len(cs)} claim lines of the paper checked below: {_verdict_counts(cs)}.", ""]
    return out


def claims_section(cs) -> list[str]:
    """The last section, "Claims of the paper": the test and the rule in words, the
    verdicts' counts and one table row per claim line."""
    n = family_size(cs)
    out = [
        "## Claims of the paper",
        "",
        "Each line: our effect with its 95 % interval over training seeds and test queries "
        "(the training seed a random effect: the mean over a map's seeds, the between-seed "
        "variance added to the query variance, Student's t; a map with one seed borrows the "
        "between-seed variance of the same quantity from its robot's maps with several "
        "seeds; a pooled line is the mean of its maps), the number of seeds, the standard "
        "deviation of the per-seed values, the p-value and the p-value Holm-adjusted over "
        f"all {n} tests the verdicts use (each line's test and, where the paper gives the "
        "effect's size, the test of that size). The test's coverage by simulation: "
        "`seed_test_coverage.md`. The method: `ntq_jax/stats.py`; the claims, their tests "
        "and the rule: `ntq_jax/experiment/claims.py`.",
        "",
        f"Rule (level {ALPHA}, on the Holm-adjusted p-values), in this order: "
        "**contradicted** if our effect has the sign opposite to the claim's with p < 0.05 "
        "(a claim about a magnitude: that magnitude's test p < 0.05); **holds** if it has the "
        "claimed sign with p < 0.05; **paper's magnitude excluded** if neither and the test of "
        "the paper's own effect has p < 0.05 (the paper's effect lies outside what our seeds "
        'allow); **unresolved** otherwise. A claim of several parts ("the best", "every '
        'model") takes its largest part p when every part has the claimed sign, and its '
        'smallest opposite part p times the number of parts otherwise ("in some cases": the '
        "smallest claimed-sign part p times the number of parts); the line shows the "
        "deciding part. Trends over maps use the maps' means over seeds: Kendall's tau (over "
        "several robots stratified by robot, since robots differ in level) and the exact "
        "Mann-Whitney test, two-sided.",
        "",
        "Verdicts: " + _verdict_counts(cs) + ".",
        "",
        "| Table | Claim | Scope | Verdict | Ours [95 %], seeds, sd over seeds | p | Holm p | "
        "Paper | Details |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in cs:
        pp = (
            ""
            if c["p_paper"] is None
            else f" (paper's size: p {p_value(c['p_paper'])}, Holm {p_value(c['p_paper_holm'])})"
        )
        out.append(
            f"| {c['table']} | {c['claim']} | {c['scope']} | **{c['verdict']}** | "
            f"{c['effect']} | {p_value(c['p'])} | {p_value(c['p_holm'])} | "
            f"{c['paper']}{pp} | {c['evidence']} |"
        )
    return out + [""]
