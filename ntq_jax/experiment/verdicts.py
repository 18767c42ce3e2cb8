"""The verdict of a claim line: a claim's p-value, the multiplicity correction and the rule.

The verdicts of ``REPRODUCTION.md`` (:mod:`ntq_jax.experiment.claims` builds the
lines; each line's effect, estimate and test: :mod:`ntq_jax.experiment.quantities`,
:mod:`ntq_jax.experiment.claim_lines`).

**Claims of several parts.** "PNet_3 is the best / the worst" and "every model ..."
need every part: their p-value is the largest of the parts' when every part has the
claimed sign (an intersection-union test), and the smallest part's p times the
number of parts (Bonferroni) for a part of the opposite sign, which would contradict
the claim. "In some cases" needs one part: the smallest p of a part with the claimed
sign times the number of parts. The line shows the part that decides.
:func:`several_parts` applies it.

**Multiplicity.** Every p-value a verdict uses (one per claim line, and for the
claims with a magnitude in the paper the test of that magnitude) is one family:
:func:`ntq_jax.multiplicity.holm` adjusts them together, and the verdicts use the
adjusted values (:func:`decide`; :func:`family_size` counts them).

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

from ntq_jax.experiment.formatting import num
from ntq_jax.multiplicity import holm

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
    "several_parts",
    "decide",
    "family_size",
]

ALPHA = 0.05  #: significance level of every verdict (on Holm-adjusted p-values)
HOLDS, CONTRADICTED, MAGNITUDE, UNRESOLVED, NOT_RUN = (
    "holds",
    "contradicted",
    "paper's magnitude excluded",
    "unresolved",
    "not run",
)
FAILS = CONTRADICTED  #: the former name of a claim our data contradict
VERDICTS = (HOLDS, CONTRADICTED, MAGNITUDE, UNRESOLVED, NOT_RUN)


def verdict(
    direction: int, p, p_paper=None, *, magnitude_claim: bool = False, alpha: float = ALPHA
) -> str:
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


def several_parts(parts, sign: int, need: str = "all"):
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


def decide(lines: list[dict]) -> list[dict]:
    """Holm's adjustment over the family of ``lines`` (every line's ``p`` and ``p_paper``)
    and each line's verdict: sets ``p_holm``, ``p_paper_holm`` and ``verdict`` (a line
    without a seed-aware test is *unresolved*) and returns ``lines``."""
    family = [c["p"] for c in lines] + [c["p_paper"] for c in lines]
    adj = holm([float("nan") if x is None else x for x in family])
    n = len(lines)
    for i, c in enumerate(lines):
        c["p_holm"] = None if c["p"] is None else float(adj[i])
        c["p_paper_holm"] = None if c["p_paper"] is None else float(adj[n + i])
        c["verdict"] = (
            UNRESOLVED
            if not c["seed_aware"]
            else verdict(
                c["direction"], c["p_holm"], c["p_paper_holm"], magnitude_claim=c["magnitude_claim"]
            )
        )
    return lines


def family_size(cs) -> int:
    """The number of p-values Holm adjusted together."""
    return sum(c["p"] is not None for c in cs) + sum(c["p_paper"] is not None for c in cs)
