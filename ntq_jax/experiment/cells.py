"""The files of a factor study's cells (``scripts/factor_study.py``): done, damaged, paired.

A finished cell's folder under the study's results holds ``summary.json``
(:mod:`ntq_jax.experiment.summaries`) and ``paired.json`` (written last: the cell
is done when it is there and readable). A cell whose ``paired.json`` or
``summary.json`` cannot be read is damaged: not done (the queue redoes it), and
a report that would read it stops first with one line naming the file.
"""

from __future__ import annotations

import json
from pathlib import Path

from ntq_jax.errors import UsageError

__all__ = ["damaged", "is_done", "check_cells", "paired"]


def damaged(folder: Path) -> str | None:
    """Why the cell's ``paired.json`` or ``summary.json`` in ``folder`` cannot be read, or None
    (a missing file is not damage)."""
    for f, keys in ((folder / "paired.json", ("cell", "paired")), (folder / "summary.json", ())):
        try:
            obj = json.loads(f.read_text(encoding="utf-8"))
            if isinstance(obj, dict) and all(k in obj for k in keys):
                continue
            return f"{f}: not a cell's {f.name} (expected a JSON object" + (
                f" with {' and '.join(keys)})" if keys else ")"
            )
        except FileNotFoundError:
            continue
        except (OSError, UnicodeDecodeError, ValueError) as e:
            return f"{f}: unreadable ({type(e).__name__}: {e})"
    return None


def is_done(folder: Path) -> bool:
    """Whether the cell whose results are in ``folder`` is finished: its readable ``paired.json``."""
    return (folder / "paired.json").is_file() and damaged(folder) is None


def check_cells(results: Path) -> None:
    """One :class:`UsageError` naming the first damaged cell file under ``results`` (before a
    report reads them) and the command that redoes the cell."""
    for f in sorted(results.rglob("paired.json")) if results.is_dir() else ():
        why = damaged(f.parent)
        if why:
            key = f.parent.relative_to(results).as_posix()
            raise UsageError(
                f"{why}; redo the cell: python scripts/factor_study.py --cell {key} "
                "(--next redoes it first), or restore the file from git"
            )


def paired(run: Path, cell, env) -> list[dict]:
    """PNet_k - PNet_0 per query kind, steerTo and band, from the run's saved paths."""
    import numpy as np

    from ntq_jax.experiment.metrics import in_band
    from ntq_jax.stats import mcnemar_exact, paired_success_difference

    res = json.loads((run / "results.json").read_text())
    qs = np.load(run / "eval" / cell.slug / "queries.npz")
    out = []
    rows = {(r["model"], r["query_kind"], r["steer"]): r for r in res["rows"]}
    pairs = [(f"PNet_{k}", "PNet_0") for k in (1, 2, 3, 4)] + [("PNet_4", "PNet_3")]
    for (model, kind, steer), r in sorted(rows.items(), key=str):
        for baseline in [b for a, b in pairs if a == model]:
            base = rows.get((baseline, kind, steer))
            if base is None:
                continue
            a = np.load(run / r["paths_file"])["success"]
            b = np.load(run / base["paths_file"])["success"]
            band = in_band(env, qs[kind])
            for part, mask in (("all", np.ones_like(band)), ("in_band", band), ("out_band", ~band)):
                row = {
                    "model": model,
                    "baseline": baseline,
                    "query_kind": kind,
                    "steer": steer,
                    "band": part,
                    "n": int(mask.sum()),
                }
                if mask.any():
                    d = paired_success_difference(a[mask], b[mask])
                    row.update(
                        success=float(a[mask].mean()),
                        baseline_success=float(b[mask].mean()),
                        only_a=d["only_a"],
                        only_b=d["only_b"],
                        success_diff=d["diff"],
                        success_diff_ci95=d["ci"],
                        mcnemar_p=mcnemar_exact(d["only_a"], d["only_b"]),
                    )
                out.append(row)
    return out
