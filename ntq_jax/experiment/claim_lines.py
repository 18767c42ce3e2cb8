"""One line of a claim of the paper: our effect, its test, the paper's value.

A claim line is a dict (:func:`claim_line`): ``table``, ``claim``, ``scope``, ``effect``
(text, :func:`effect_text`), ``estimate`` (a :class:`ntq_jax.seed_effects.SeedEstimate`
or None), ``seeds``, ``spread``, ``p`` and ``direction`` (the sign of our effect
against the claim's), ``paper_effect`` with ``p_paper`` (the test of the paper's
magnitude, where the claim has one), ``magnitude_claim``, ``seed_aware``, ``evidence``
and ``paper``. :func:`parts_line` is the line of a claim of several parts (its p by
:func:`ntq_jax.experiment.verdicts.several_parts`), :func:`pooled_line` the line of
a mean over maps, :func:`not_run` the line of a claim whose maps are not run yet.
:func:`ntq_jax.experiment.verdicts.decide` then adds the Holm-adjusted p-values and
the verdict; the claims themselves: :mod:`ntq_jax.experiment.claims`.
"""

from __future__ import annotations

from ntq_jax.experiment.formatting import fixed, num, p_value, signed
from ntq_jax.experiment.verdicts import several_parts
from ntq_jax.seed_effects import SeedEstimate, combine

__all__ = ["effect_text", "claim_line", "not_run", "parts_line", "pooled_line"]


def effect_text(e: SeedEstimate | None, null: float = 0.0) -> str:
    """``+0.069 [+0.011, +0.128], 3 seeds, sd 0.024`` (``1 seed, sd borrowed``)."""
    if e is None:
        return "-"
    lo, hi = e.ci()
    seeds = f"{e.seeds} seed{'s' if e.seeds != 1 else ''}"
    sd = (
        "sd borrowed"
        if e.borrowed and not num(e.spread)
        else "no sd (one seed)"
        if not num(e.spread)
        else f"sd {fixed(e.spread)}"
        + (" (one-seed maps borrow)" if e.borrowed else "")
        + ("" if e.seed_aware else " (a one-seed map without)")
    )
    return f"{signed(e.estimate)} [{signed(lo)}, {signed(hi)}], {seeds}, {sd}"


def claim_line(
    table,
    claim,
    scope,
    *,
    est=None,
    null=0.0,
    sign=1,
    p=None,
    direction=None,
    paper_effect=None,
    magnitude_claim=False,
    evidence="",
    paper="",
    effect=None,
    aware=None,
) -> dict:
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
        evidence = (
            "one training seed and no map of this robot with more: the between-seed "
            "variance is unknown; " + evidence
        )
    p_paper = est.p(paper_effect) if est is not None and aware and num(paper_effect) else None
    return {
        "table": table,
        "claim": claim,
        "scope": scope,
        "estimate": est,
        "effect": effect if effect is not None else effect_text(est, null),
        "p": p if num(p) else None,
        "direction": direction or 0,
        "paper_effect": paper_effect,
        "p_paper": p_paper,
        "magnitude_claim": magnitude_claim,
        "evidence": evidence,
        "paper": paper,
        "seed_aware": aware,
        "seeds": None if est is None else est.seeds,
        "spread": None if est is None else est.spread,
    }


def not_run(table, claim, scope, evidence, paper) -> dict:
    """The line of a claim not run yet (no effect, no p-value)."""
    return claim_line(table, claim, scope, evidence=evidence, paper=paper, effect="-")


def parts_line(table, claim, scope, parts, sign, paper, need="all") -> dict:
    """The line of a claim of several parts (not run if a part is missing)."""
    if any(e is None for _, e, _ in parts):
        return not_run(table, claim, scope, "not run", paper)
    direction, p, i = several_parts(parts, sign, need)
    label, e, null = parts[i]
    ev = "; ".join(
        f"{lab} {fixed(x.estimate) if nl else signed(x.estimate)} (p {p_value(x.p(nl))})"
        for lab, x, nl in parts
    )
    text = effect_text(e)
    if null:  # a level against a threshold: the level itself, not its distance
        text = text.split(" [", 1)
        lo, hi = e.ci()
        text = (
            f"{fixed(e.estimate)} [{fixed(lo)}, {fixed(hi)}]"
            + text[1].split("]", 1)[1]
            + f"; vs {null}"
        )
    return claim_line(
        table,
        claim,
        scope,
        est=e,
        null=null,
        sign=sign,
        p=p,
        direction=direction,
        evidence=f"parts: {ev}",
        paper=paper,
        effect=f"{label}: {text}",
        aware=all(x.seed_aware for _, x, _ in parts),
    )


def pooled_line(table, claim, scope, ests, paper_diffs, model) -> dict:
    """The line of a mean over maps of their estimates ``ests`` (not run if a map is
    missing); ``paper_diffs``: the paper's effect on each map (``model`` ahead or not)."""
    paper = (
        f"mean diff {signed(sum(paper_diffs) / len(paper_diffs))}; {model} ahead in "
        f"{sum(d > 0 for d in paper_diffs)} of {len(paper_diffs)}"
    )
    if any(e is None for e in ests):
        n_run = sum(e is not None for e in ests)
        return not_run(table, claim, scope, f"not run ({n_run} of {len(ests)} maps present)", paper)
    e = combine(ests)
    return claim_line(
        table,
        claim,
        scope,
        est=e,
        paper_effect=sum(paper_diffs) / len(paper_diffs),
        paper=paper,
        evidence="mean of the maps' estimates"
        + (" (one-seed maps borrow their robot's between-seed variance)" if e.borrowed else ""),
    )
