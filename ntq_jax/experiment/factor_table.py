"""The factor study's section of ``REPRODUCTION.md``: what decides PNet_3 vs PNet_0.

Input: a factor-study folder (``results/factors``, written by
``scripts/factor_study.py``) holding one ``paired.json`` per cell, at
``<root>/<map>/<data paths>/<budgets>[/seeds/train_seed_<k>]/paired.json``. A
cell's file has ``cell`` (``map``, ``data``, ``budget``, ``train_seed``) and
``paired``: the paired comparisons of its run, each with ``model``,
``baseline``, ``query_kind``, ``steer``, ``band`` (``all``, ``in_band``,
``out_band``), ``n``, ``success_diff``, ``success_diff_ci95`` (Newcombe) and
``mcnemar_p``. An optional hand-written ``<root>/CONCLUSION.md`` (the study's
reading, with its numbers) is quoted at the end of the section.

Functions (pure, data only):

* :func:`load_cells` reads every cell, sorted by map, data paths, budgets, seed.
* :func:`sign_of` is a comparison's verdict: ``+`` or ``-`` (its sign, McNemar
  p < :data:`ALPHA`) or ``0`` (not resolvable at this size).
* :func:`section` is the Markdown section: one row per cell (PNet_3 - PNet_0
  with steerTo, on non-trivial queries in all three bands and on uniform
  queries), then per factor level the cells' verdicts on non-trivial queries.
"""

from __future__ import annotations

import json
from pathlib import Path

from ntq_jax.experiment.claims import ALPHA
from ntq_jax.experiment.formatting import fixed, num, p_value, signed

__all__ = ["CONCLUSION", "load_cells", "sign_of", "section"]

CONCLUSION = "CONCLUSION.md"
BANDS = ("all", "in_band", "out_band")


def load_cells(root) -> list[dict]:
    """Every cell's ``paired.json`` under ``root`` (empty if there is none), in a fixed order."""
    root = Path(root)
    if not root.is_dir():
        return []
    cells = [json.loads(f.read_text(encoding="utf-8")) for f in root.rglob("paired.json")]
    return sorted(cells, key=lambda p: (p["cell"]["map"], p["cell"]["data"],
                                        p["cell"]["budget"], p["cell"]["train_seed"]))


def _find(cell: dict, kind: str, band: str, model: str = "PNet_3", steer: bool = True):
    for r in cell["paired"]:
        if (r["model"] == model and r.get("baseline", "PNet_0") == "PNet_0"
                and r["query_kind"] == kind and bool(r["steer"]) == steer and r["band"] == band):
            return r
    return None


def sign_of(r) -> str:
    """``+``/``-``: the difference's sign, significant at :data:`ALPHA` (McNemar); ``0``:
    not resolvable; ``?``: no such comparison."""
    if not r or not num(r.get("success_diff")) or not num(r.get("mcnemar_p")):
        return "?"
    if r["mcnemar_p"] >= ALPHA or r["success_diff"] == 0:
        return "0"
    return "+" if r["success_diff"] > 0 else "-"


def _diff(r) -> str:
    if not r or not num(r.get("success_diff")):
        return "-"
    lo, hi = r["success_diff_ci95"]
    return f"{signed(r['success_diff'])} [{signed(lo)}, {signed(hi)}] p={p_value(r['mcnemar_p'])}"


def _by_factor(cells: list[dict]) -> list[str]:
    """Per factor level: the maps' verdicts on non-trivial queries (all test queries)."""
    out = ["Verdicts of PNet_3 - PNet_0 on non-trivial queries with steerTo (`+`/`-`: "
           f"significant at p < {ALPHA}, `0`: not resolvable), per factor level:", ""]
    levels = {}
    for c in cells:
        cell = c["cell"]
        tag = f"{cell['map']}" + (f" seed {cell['train_seed']}" if cell["train_seed"] else "")
        for factor, level in (("data paths", cell["data"]), ("budgets", cell["budget"])):
            levels.setdefault((factor, level), []).append(
                f"{tag} {sign_of(_find(c, 'nontrivial', 'all'))}")
    for (factor, level), got in sorted(levels.items()):
        out.append(f"- {factor} = `{level}`: " + ", ".join(got))
    bands = {b: [sign_of(_find(c, "nontrivial", b)) for c in cells] for b in BANDS[1:]}
    for b, signs in bands.items():
        out.append(f"- test band = `{b}`: " + ", ".join(f"{s} {signs.count(s)}" for s in "+-0?"
                                                       if signs.count(s)) + " cells")
    return out + [""]


def section(root, label: str = "results/factors") -> list[str]:
    """The section's Markdown lines (empty when ``root`` holds no cell)."""
    cells = load_cells(root)
    if not cells:
        return []
    out = ["## What decides PNet_3 vs PNet_0", "",
           f"The factor study (`{label}/`, `python scripts/factor_study.py --list`): each cell "
           "changes one factor of its map's default run: the data planner's paths (`shortcut`, "
           "`density` (BIT*-like spacing), `raw`, `bitstar`: OMPL BIT*'s own paths), the neural "
           "planner's budgets (`ours`, `mpnet`, and Table III's variants `nosteer_*`) or the "
           "training seed; the test band splits the same test queries by whether both ends lie "
           "in the data padding's band. PNet_3 - PNet_0 success on the same test queries with "
           "steerTo, with its 95 % Newcombe interval and McNemar's exact p.", "",
           "Columns: PNet_0's success on non-trivial queries with / without steerTo; the "
           "difference on non-trivial queries (all, in band, out of band), on non-trivial "
           "queries without steerTo (Table III), and on uniform queries.", "",
           "| map | data paths | budgets | seed | PNet_0 | non-trivial | in band | out of band "
           "| without steerTo | uniform |",
           "|---|---|---|---:|---|---|---|---|---|---|"]
    for c in cells:
        cell = c["cell"]
        base = [_find(c, "nontrivial", "all", steer=s) for s in (True, False)]
        base = " / ".join(fixed(r["baseline_success"]) if r else "-" for r in base)
        nt = [_diff(_find(c, "nontrivial", b)) for b in BANDS]
        nt.append(_diff(_find(c, "nontrivial", "all", steer=False)))
        out.append(f"| {cell['map']} | {cell['data']} | {cell['budget']} | {cell['train_seed']} | "
                   f"{base} | " + " | ".join(nt) + f" | {_diff(_find(c, 'uniform', 'all'))} |")
    out += [""] + _by_factor(cells)
    conclusion = Path(root) / CONCLUSION
    if conclusion.is_file():
        out += [conclusion.read_text(encoding="utf-8").strip(), ""]
    return out
