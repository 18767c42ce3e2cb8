"""Reports of an evaluation: results files, the paper's tables and figures.

:func:`write_report` takes the result rows of :func:`ntq_jax.evaluate.evaluate_env`
and writes, into the run folder (atomically):

* ``results.json`` (rows plus run metadata) and ``results.csv`` (one row per
  environment, model, test query kind and steerTo variant);
* ``tables.md`` and ``tables.tex``: one table per task and steerTo variant laid
  out as the paper's Tables I-IV (model rows PNet_0..PNet_3; uniform and
  non-trivial columns; success ratio and cost ratio), one block per
  environment with gamma_nt in its heading; the Markdown adds the 95% intervals,
  the cost ratio to the exact optimum (point robots), timings and failures;
* ``figures/success_ratio[_nosteer].png`` (bars with 95% intervals),
  ``figures/examples_<env>.png`` (neural paths beside the reference on the map)
  and ``figures/queries_<env>.png`` (the test query distributions).
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ntq_jax import artifacts, plotting
from ntq_jax.evaluate import KINDS, load_npz

TITLES = {"point": "Point robot planning", "rigid": "Rigid body planning",
          "nlink": "n-link manipulator planning"}
KIND_TITLE = {"uniform": "Uniform Query", "nontrivial": "Non-trivial Query"}
CSV_FIELDS = ["task", "env", "model", "query_kind", "steer", "k_test", "successes",
              "success_ratio", "success_ci95_lo", "success_ci95_hi", "cost_ratio", "cost_ratio_n",
              "cost_ratio_opt", "seconds_per_query", "compile_seconds",
              "reference_seconds_per_query", "failures_no_path", "failures_infeasible",
              "failures_invalid_query", "reference_failed", "reference_planner", "gamma_nt",
              "paths_file"]


def _f(x, nd=3) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{nd}f}"


def _groups(rows):
    """``{(task, steer): {env: {(model, kind): row}}}`` in first-seen order."""
    out: dict = {}
    for r in rows:
        g = out.setdefault((r["task"], r["steer"]), {})
        g.setdefault(r["env"], {})[(r["model"], r["query_kind"])] = r
    return out


def _title(task, steer):
    t = TITLES.get(task, task)
    return t if steer else f"{t} without steerTo"


def _models(block):
    return sorted({m for m, _ in block}, key=lambda s: int(s.split("_")[-1]))


def _gamma_heading(env, block) -> tuple[str, str]:
    from ntq_jax.presets import PAPER_GAMMA
    r = next(iter(block.values()))
    g = r.get("gamma_nt")
    paper = PAPER_GAMMA.get(env)
    md = f"Environment {env}, gamma_nt = {_f(g)}"
    if r.get("gamma_nt_ci95"):
        lo, hi = r["gamma_nt_ci95"]
        md += f" [{lo:.3f}, {hi:.3f}]"
    if paper is not None:
        md += f" (paper {paper:.3f})"
    tex = f"Environment {env.replace('_', '-')}, $\\gamma_\\mathrm{{nt}}={_f(g)}$"
    return md, tex


def tables_md(rows) -> str:
    out = ["# Results", ""]
    for (task, steer), envs in _groups(rows).items():
        out += [f"## {_title(task, steer)}", ""]
        for env, block in envs.items():
            md, _ = _gamma_heading(env, block)
            any_row = next(iter(block.values()))
            out += [f"### {md}", "",
                    f"K_test = {any_row['k_test']} per query kind; reference planner: "
                    f"{any_row['reference_planner']}; success ratio with its 95% Wilson interval.", "",
                    "| Model | Uniform success ratio | Uniform cost ratio | Non-trivial success ratio "
                    "| Non-trivial cost ratio |",
                    "|---|---|---|---|---|"]
            for m in _models(block):
                cells = []
                for kind in KINDS:
                    r = block.get((m, kind))
                    if r is None:
                        cells += ["-", "-"]
                        continue
                    lo, hi = r["success_ci95"]
                    cells += [f"{_f(r['success_ratio'])} [{lo:.3f}, {hi:.3f}]", _f(r["cost_ratio"])]
                out.append(f"| {m} | " + " | ".join(cells) + " |")
            out.append("")
            # extras: optimum ratio, timings, failures
            out += ["| Model | kind | cost ratio to optimum | ms / query | compile s | no path | "
                    "infeasible | invalid | reference failed |", "|---|---|---|---|---|---|---|---|---|"]
            for m in _models(block):
                for kind in KINDS:
                    r = block.get((m, kind))
                    if r is None:
                        continue
                    fl = r["failures"]
                    out.append(f"| {m} | {kind} | {_f(r.get('cost_ratio_opt'))} | "
                               f"{r['seconds_per_query'] * 1e3:.2f} | {r['compile_seconds']:.1f} | "
                               f"{fl.get('no_path', 0)} | {fl.get('infeasible', 0)} | "
                               f"{fl.get('invalid_query', 0)} | {r['reference_failed']} |")
            out.append("")
    return "\n".join(out)


def tables_tex(rows) -> str:
    out = ["% Generated by ntq_jax.report; needs \\usepackage{booktabs}", ""]
    for (task, steer), envs in _groups(rows).items():
        cap = _title(task, steer).replace("steerTo", "$\\mathsf{steerTo}$")
        out += ["\\begin{table}", "\t\\caption{" + cap + "}", "\t\\centering"]
        for i, (env, block) in enumerate(envs.items()):
            _, tex = _gamma_heading(env, block)
            if i:
                out += ["\t\\vspace{0.5em}", f"\t\\\\{tex} \\\\"]
            else:
                out += [f"\t{tex} \\\\"]
            out += ["\t\\vspace{0.2em}", "\t\\begin{tabular}{lcccc}", "\t\t\\toprule",
                    "\t\t\\multirow{2}{*}{Model} & \\multicolumn{2}{c}{Uniform Query} & "
                    "\\multicolumn{2}{c}{Non-trivial Query} \\\\",
                    "\t\t& {success ratio} & {cost ratio} & {success ratio} & {cost ratio} \\\\",
                    "\t\t\\midrule"]
            for m in _models(block):
                cells = []
                for kind in KINDS:
                    r = block.get((m, kind))
                    cells += ["-", "-"] if r is None else [_f(r["success_ratio"]), _f(r["cost_ratio"])]
                idx = m.split("_")[-1]
                out.append(f"\t\t$\\mathsf{{PNet}}_{idx}$ & " + " & ".join(cells) + " \\\\")
            out += ["\t\t\\bottomrule", "\t\\end{tabular}"]
        out += ["\\end{table}", ""]
    return "\n".join(out)


def results_csv(rows) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        flat = dict(r)
        flat["success_ci95_lo"], flat["success_ci95_hi"] = r["success_ci95"]
        for k, v in r["failures"].items():
            flat[f"failures_{k}"] = v
        w.writerow(flat)
    return buf.getvalue()


# ---------------------------------------------------------------------------
# Everything
# ---------------------------------------------------------------------------

def write_report(run_dir, rows: list[dict], envs: dict | None = None, meta: dict | None = None,
                 figures: bool = True) -> dict:
    """Writes results.json/csv, tables.md/tex and the figures; returns their paths.

    Args:
        run_dir: the run folder.
        rows: result rows (see :func:`ntq_jax.evaluate.evaluate_env`).
        envs: ``{env_name: Env}`` for the map figures (optional).
        meta: run metadata stored in ``results.json``.
        figures: write the PNG figures.
    """
    from ntq_jax.evaluate import env_slug
    run_dir = Path(run_dir)
    out = {}
    out["results.json"] = run_dir / "results.json"
    artifacts.write_text(out["results.json"], json.dumps({"meta": meta or {}, "rows": rows}, indent=1,
                                               default=str))
    out["results.csv"] = run_dir / "results.csv"
    artifacts.write_text(out["results.csv"], results_csv(rows))
    out["tables.md"] = run_dir / "tables.md"
    artifacts.write_text(out["tables.md"], tables_md(rows))
    out["tables.tex"] = run_dir / "tables.tex"
    artifacts.write_text(out["tables.tex"], tables_tex(rows))
    if figures:
        figs = run_dir / "figures"
        for steer in sorted({r["steer"] for r in rows}, reverse=True):
            p = plotting.success_figure(rows, figs / f"success_ratio{'' if steer else '_nosteer'}.png", steer)
            if p:
                out[p.name] = p
        for name, env in (envs or {}).items():
            slug = env_slug(name)
            models = sorted({r["model"] for r in rows if r["env"] == name},
                            key=lambda s: int(s.split("_")[-1]))
            steer = any(r["steer"] for r in rows if r["env"] == name)
            suffix = "" if steer else "_nosteer"
            saved = {m: load_npz(run_dir / "paths" / slug / f"{m}_nontrivial{suffix}.npz")
                     for m in models}
            p = plotting.examples_figure(env, load_npz(run_dir / "eval" / slug / "reference.npz"),
                                         saved, figs / f"examples_{slug}.png")
            if p:
                out[p.name] = p
            p = plotting.queries_figure(env, load_npz(run_dir / "eval" / slug / "queries.npz"),
                                        figs / f"queries_{slug}.png")
            if p:
                out[p.name] = p
    return out
