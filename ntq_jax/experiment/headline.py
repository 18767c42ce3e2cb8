"""The terminal summary of a run: one compact headline per map, the full tables in files.

``python scripts/train_all.py`` ends with :func:`headline`: for each map, the
success ratio of PNet_0..PNet_3 (and the ensemble rows) on uniform and non-trivial
test queries (with steerTo), the paper's question PNet_3 - PNet_0 on non-trivial
queries with its 95 % interval and McNemar's p, and where the full tables and the
figures are. It reads the run folder's ``results.json`` (:mod:`ntq_jax.experiment.report`),
so it prints what the files hold, nothing recomputed.
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["headline"]

KINDS = ("uniform", "nontrivial")


def _success(rows: list[dict], env: str, model: str, kind: str) -> str:
    for r in rows:
        if (
            r["env"] == env
            and r["model"] == model
            and r["query_kind"] == kind
            and r.get("steer", True)
        ):
            return f"{r['success_ratio']:.3f}"
    return "-"


def _gap(comparisons: list[dict], env: str) -> str:
    for c in comparisons:
        if (
            c["env"] == env
            and c["model"] == "PNet_3"
            and c.get("baseline") == "PNet_0"
            and c["query_kind"] == "nontrivial"
            and c.get("steer", True)
        ):
            lo, hi = c["success_diff_ci95"]
            return (
                f"PNet_3 - PNet_0, non-trivial: {c['success_diff']:+.3f} "
                f"[{lo:+.3f}, {hi:+.3f}], McNemar p={c['mcnemar_p']:.2g} (n={c['n']})"
            )
    return "PNet_3 - PNet_0, non-trivial: not evaluated"


def headline(run: str | Path) -> list[str]:
    """The summary lines of the run folder ``run`` (empty when it has no ``results.json``)."""
    run = Path(run)
    path = run / "results.json"
    if not path.is_file():
        return []
    results = json.loads(path.read_text(encoding="utf-8"))
    rows, comparisons = results.get("rows", []), results.get("comparisons", [])
    models = list(dict.fromkeys(r["model"] for r in rows))
    width = max([len(m) for m in models] + [5])
    lines = []
    for env in dict.fromkeys(r["env"] for r in rows):
        lines += [
            f"{env}: success ratio with steerTo",
            f"  {'model':<{width}}  {'uniform':>8}  {'non-trivial':>11}",
        ]
        lines += [
            f"  {m:<{width}}  {_success(rows, env, m, 'uniform'):>8}  "
            f"{_success(rows, env, m, 'nontrivial'):>11}"
            for m in models
        ]
        lines += [f"  {_gap(comparisons, env)}", ""]
    figures = sorted(p.name for p in (run / "figures").glob("*.png"))
    lines.append(f"full tables: {run / 'tables.md'} (LaTeX: tables.tex; rows: results.csv)")
    if figures:
        lines.append(f"figures: {run / 'figures'} ({', '.join(figures)})")
    return lines
