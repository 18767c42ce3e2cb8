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

Multiplicity: the study holds about two thousand McNemar p-values (every cell,
comparison, query kind, steerTo variant and band). :func:`load_cells` adds to
each comparison its Benjamini-Hochberg q-value over all of them (``q``, the
false-discovery rate; :func:`ntq_jax.stats.benjamini_hochberg`), shown beside
the raw p, and the verdicts of the section use q.

Functions (pure, data only):

* :func:`load_cells` reads every cell, sorted by map, data paths, budgets, seed,
  with the q-values added.
* :func:`sign_of` is a comparison's verdict: ``+`` or ``-`` (its sign, q (or,
  without one, McNemar p) < :data:`ALPHA`) or ``0`` (not resolvable at this size).
* :func:`section` is the Markdown section: one row per cell (PNet_3 - PNet_0
  with steerTo, on non-trivial queries in all three bands and on uniform
  queries), then per factor level the cells' verdicts on non-trivial queries,
  then (:func:`decomposition`) PNet_3 - PNet_0 split into the gain from
  non-trivial queries (PNet_2 - PNet_0) and the cost of pruning (PNet_3 - PNet_2)
  per cell of the config's budgets, beside its data paths' density and the
  samples pruning kept (from the cell's ``summary.json``, where present).
"""

from __future__ import annotations

import json
from pathlib import Path

from ntq_jax.experiment.claims import ALPHA
from ntq_jax.experiment.formatting import fixed, num, p_value, signed
from ntq_jax.stats import benjamini_hochberg

__all__ = ["CONCLUSION", "load_cells", "sign_of", "diff_text", "decomposition", "section"]

CONCLUSION = "CONCLUSION.md"
BANDS = ("all", "in_band", "out_band")


def load_cells(root) -> list[dict]:
    """Every cell's ``paired.json`` under ``root`` (empty if there is none), in a fixed order,
    each comparison with its Benjamini-Hochberg ``q`` over every p-value of the study."""
    root = Path(root)
    if not root.is_dir():
        return []
    cells = []
    for f in root.rglob("paired.json"):
        cell = json.loads(f.read_text(encoding="utf-8"))
        summary = f.with_name("summary.json")
        if summary.is_file():  # the datasets' sizes (``datasets`` of the run's summary)
            cell["datasets"] = json.loads(summary.read_text(encoding="utf-8")).get("datasets")
        cells.append(cell)
    cells = sorted(
        cells,
        key=lambda p: (
            p["cell"]["map"],
            p["cell"]["data"],
            p["cell"]["budget"],
            p["cell"]["train_seed"],
        ),
    )
    add_q(cells)
    return cells


def add_q(cells: list[dict]) -> int:
    """Adds ``q`` (Benjamini-Hochberg over every comparison of ``cells`` with a McNemar p)
    to each such comparison; returns the family's size."""
    rows = [r for c in cells for r in c["paired"] if num(r.get("mcnemar_p"))]
    for r, q in zip(rows, benjamini_hochberg([r["mcnemar_p"] for r in rows])):
        r["q"] = float(q)
    return len(rows)


def _find(cell: dict, kind: str, band: str, model: str = "PNet_3", steer: bool = True):
    for r in cell["paired"]:
        if (
            r["model"] == model
            and r.get("baseline", "PNet_0") == "PNet_0"
            and r["query_kind"] == kind
            and bool(r["steer"]) == steer
            and r["band"] == band
        ):
            return r
    return None


def sign_of(r) -> str:
    """``+``/``-``: the difference's sign, significant at :data:`ALPHA` (its BH ``q``, or
    McNemar's p when it has no q); ``0``: not resolvable; ``?``: no such comparison."""
    if not r or not num(r.get("success_diff")) or not num(r.get("mcnemar_p")):
        return "?"
    if r.get("q", r["mcnemar_p"]) >= ALPHA or r["success_diff"] == 0:
        return "0"
    return "+" if r["success_diff"] > 0 else "-"


def diff_text(r) -> str:
    """``+0.096 [+0.054, +0.139] p=1.4e-05 q=0.0003``: a comparison's difference, its 95 %
    interval, McNemar's p and (when it has one) its Benjamini-Hochberg q; ``-`` if none."""
    if not r or not num(r.get("success_diff")):
        return "-"
    lo, hi = r["success_diff_ci95"]
    q = f" q={p_value(r['q'])}" if num(r.get("q")) else ""
    return (
        f"{signed(r['success_diff'])} [{signed(lo)}, {signed(hi)}] p={p_value(r['mcnemar_p'])}{q}"
    )


def _by_factor(cells: list[dict]) -> list[str]:
    """Per factor level: the maps' verdicts on non-trivial queries (all test queries)."""
    out = [
        "Verdicts of PNet_3 - PNet_0 on non-trivial queries with steerTo (`+`/`-`: "
        f"significant at q < {ALPHA}, Benjamini-Hochberg over every p-value of the study; "
        "`0`: not resolvable), per factor level:",
        "",
    ]
    levels = {}
    for c in cells:
        cell = c["cell"]
        tag = f"{cell['map']}" + (f" seed {cell['train_seed']}" if cell["train_seed"] else "")
        for factor, level in (("data paths", cell["data"]), ("budgets", cell["budget"])):
            levels.setdefault((factor, level), []).append(
                f"{tag} {sign_of(_find(c, 'nontrivial', 'all'))}"
            )
    for (factor, level), got in sorted(levels.items()):
        out.append(f"- {factor} = `{level}`: " + ", ".join(got))
    bands = {b: [sign_of(_find(c, "nontrivial", b)) for c in cells] for b in BANDS[1:]}
    for b, signs in bands.items():
        out.append(
            f"- test band = `{b}`: "
            + ", ".join(f"{s} {signs.count(s)}" for s in "+-0?" if signs.count(s))
            + " cells"
        )
    return out + [""]


def decomposition(cells: list[dict]) -> list[str]:
    """PNet_3 - PNet_0 = (PNet_2 - PNet_0) + (PNet_3 - PNet_2) on non-trivial queries with
    steerTo, per cell of the config's budgets (``ours``), with the mean states per D2 data
    path and D3's share of D2's samples (empty when no cell has both comparisons)."""
    rows = []
    for c in cells:
        cell = c["cell"]
        r2, r3 = (_find(c, "nontrivial", "all", model=m) for m in ("PNet_2", "PNet_3"))
        if cell["budget"] != "ours" or not r2 or not r3:
            continue
        p0, p2, p3 = r2["baseline_success"], r2["success"], r3["success"]
        ds = c.get("datasets") or {}
        d2, d3 = ds.get("D2") or {}, ds.get("D3") or {}
        spp = fixed(d2.get("states_per_path"), 2)
        kept = (
            fixed(d3["samples"] / d2["samples"], 2)
            if num(d3.get("samples")) and num(d2.get("samples")) and d2["samples"]
            else "-"
        )
        rows.append(
            f"| {cell['map']} | {cell['data']} | {cell['train_seed']} | {spp} | {kept} | "
            f"{fixed(p0)} | {fixed(p2)} | {fixed(p3)} | {signed(p2 - p0)} | "
            f"{signed(p3 - p2)} | {signed(p3 - p0)} | {p_value(r3.get('mcnemar_p'))} | "
            f"{p_value(r3.get('q'))} |"
        )
    if not rows:
        return []
    return [
        "Where PNet_3 - PNet_0 comes from (non-trivial queries with steerTo, the config's "
        "budgets): the gain from non-trivial queries (PNet_2 - PNet_0) plus the cost of "
        "includeData's pruning (PNet_3 - PNet_2, the same queries pruned). `states/path`: "
        "mean states per D2 data path; `D3/D2`: the share of D2's samples pruning kept; `p`: "
        "McNemar's exact p of PNet_3 - PNet_0 (this training only); `q`: its "
        "Benjamini-Hochberg q-value over every p-value of the factor study (the "
        "false-discovery rate).",
        "",
        "| map | data paths | seed | states/path | D3/D2 | PNet_0 | PNet_2 | PNet_3 "
        "| PNet_2 - PNet_0 | PNet_3 - PNet_2 | PNet_3 - PNet_0 | p | q |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
    ]


def section(root, label: str = "results/factors") -> list[str]:
    """The section's Markdown lines (empty when ``root`` holds no cell)."""
    cells = load_cells(root)
    if not cells:
        return []
    out = [
        "## What decides PNet_3 vs PNet_0",
        "",
        f"The factor study (`{label}/`, `python scripts/factor_study.py --list`): each cell "
        "changes one factor of its map's default run: the data planner's paths (`shortcut`, "
        "`density` (BIT*-like spacing), `raw`, `bitstar`: OMPL BIT*'s own paths), the neural "
        "planner's budgets (`ours`, `mpnet`, and Table III's variants `nosteer_*`) or the "
        "training seed; the test band splits the same test queries by whether both ends lie "
        "in the data padding's band. PNet_3 - PNet_0 success on the same test queries with "
        "steerTo, with its 95 % Newcombe interval, McNemar's exact p and its "
        f"Benjamini-Hochberg q over all {add_q(cells)} p-values of the study (the "
        "false-discovery rate; `results/factors/README.md` lists them all). These account for "
        "the test queries of one training; the training seed's spread is in the seed cells "
        "and, for the default cells, in the summary at the top.",
        "",
        "Columns: PNet_0's success on non-trivial queries with / without steerTo; the "
        "difference on non-trivial queries (all, in band, out of band), on non-trivial "
        "queries without steerTo (Table III), and on uniform queries.",
        "",
        "| map | data paths | budgets | seed | PNet_0 | non-trivial | in band | out of band "
        "| without steerTo | uniform |",
        "|---|---|---|---:|---|---|---|---|---|---|",
    ]
    for c in cells:
        cell = c["cell"]
        base = [_find(c, "nontrivial", "all", steer=s) for s in (True, False)]
        base = " / ".join(fixed(r["baseline_success"]) if r else "-" for r in base)
        nt = [diff_text(_find(c, "nontrivial", b)) for b in BANDS]
        nt.append(diff_text(_find(c, "nontrivial", "all", steer=False)))
        out.append(
            f"| {cell['map']} | {cell['data']} | {cell['budget']} | {cell['train_seed']} | "
            f"{base} | " + " | ".join(nt) + f" | {diff_text(_find(c, 'uniform', 'all'))} |"
        )
    out += [""] + _by_factor(cells) + decomposition(cells)
    conclusion = Path(root) / CONCLUSION
    if conclusion.is_file():
        out += [conclusion.read_text(encoding="utf-8").strip(), ""]
    return out
