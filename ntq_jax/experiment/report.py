"""Reports of an evaluation: the paper's tables from the result rows.

:func:`tables_md`, :func:`tables_tex` and :func:`results_csv` turn the result
rows of :func:`ntq_jax.experiment.evaluate.evaluate_env` into text: one table per task and
steerTo variant laid out as the paper's Tables I-IV (model rows PNet_0..PNet_3,
then the ensemble rows PNet_ens, PNet_best-of-4 and PNet_cascade when evaluated;
uniform and non-trivial columns; success ratio and cost ratio), one block per
environment with gamma_nt in its heading; the Markdown adds the 95% intervals,
and a detail table with the cost ratio to the exact optimum (point robots),
failures, and the success of the in-band and out-of-band test queries
apart (both endpoints valid at the environment's data padding, or not; see
:func:`ntq_jax.experiment.evaluate.band_metrics`); the CSV has one line per row.

Wall-clock times (:data:`TIMING_FIELDS`: seconds per query, compile seconds,
the reference planner's seconds per query) are kept apart, in
``timings.csv`` (:func:`timings_csv`, one line per row with the row's key), so
two identical runs write byte-identical ``results.csv``, ``tables.md`` and
``tables.tex``; ``results.json`` keeps every field of the rows, times included.

Paired comparisons of the models on the same queries (McNemar's test, Newcombe's
interval, the cost ratio's paired bootstrap and Wilcoxon test) are computed and tabled
by :mod:`ntq_jax.experiment.paired`: a table after each detail table of ``tables.md``,
one per task and steerTo variant in ``tables.tex``, the ``comparisons`` list of
``results.json``, and the ``vs_*`` columns of ``results.csv`` (a row's first
comparison as the model).

:func:`write_report` writes, into the run folder (atomically), ``results.json``
(rows plus run metadata), ``results.csv``, ``tables.md``, ``tables.tex``, ``timings.csv`` and the
figures of :mod:`ntq_jax.plotting`: ``figures/success_ratio[_nosteer].png``,
``figures/examples_<env>.png`` and ``figures/queries_<env>.png``.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from ntq_jax import artifacts, plotting
from ntq_jax.envs import env_slug
from ntq_jax.experiment.formatting import _tex_model, fixed
from ntq_jax.experiment.paired import (
    COMPARISON_CSV_FIELDS,
    DEFAULT_PAIRS,
    _comparison_csv,
    _comparison_md,
    _comparison_tex,
    comparisons,
)
from ntq_jax.presets import PAPER_GAMMA
from ntq_jax.types import QUERY_KINDS

TITLES = {
    "point": "Point robot planning",
    "rigid": "Rigid body planning",
    "nlink": "n-link manipulator planning",
    "serial_arm": "Serial arm (3-D) planning",
}
CSV_FIELDS = [
    "task",
    "env",
    "model",
    "query_kind",
    "steer",
    "k_test",
    "successes",
    "success_ratio",
    "success_ci95_lo",
    "success_ci95_hi",
    "cost_ratio",
    "cost_ratio_n",
    "cost_ratio_opt",
    "failures_no_path",
    "failures_infeasible",
    "failures_invalid_query",
    "reference_failed",
    "reference_planner",
    "data_planner",
    "gamma_nt",
    "band_padding",
    "n_in_band",
    "n_out_band",
    "success_in_band",
    "success_in_band_ci95_lo",
    "success_in_band_ci95_hi",
    "success_out_band",
    "success_out_band_ci95_lo",
    "success_out_band_ci95_hi",
    "paths_file",
]
#: the wall-clock fields of a row: in timings.csv, not in results.csv or tables.md
TIMING_FIELDS = ["seconds_per_query", "compile_seconds", "reference_seconds_per_query"]
#: the columns of timings.csv: a row's key, then its times
TIMING_CSV_FIELDS = ["task", "env", "model", "query_kind", "steer"] + TIMING_FIELDS


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


def _model_key(name: str):
    """Members ``PNet_<m>`` first, by index; then ``PNet_ens``, ``PNet_best-of-<N>``,
    ``PNet_cascade``, and
    other rows by name (:func:`ntq_jax.plotting.model_order`, the success figure's order)."""
    return plotting.model_order(name)


def _models(block):
    return sorted({m for m, _ in block}, key=_model_key)


def _gamma_heading(env, block) -> tuple[str, str]:
    r = next(iter(block.values()))
    g = r.get("gamma_nt")
    paper = PAPER_GAMMA.get(env)
    md = f"Environment {env}, gamma_nt = {fixed(g)}"
    if r.get("gamma_nt_ci95"):
        lo, hi = r["gamma_nt_ci95"]
        md += f" [{lo:.3f}, {hi:.3f}]"
    if paper is not None:
        md += f" (paper {paper:.3f})"
    tex = f"Environment {env.replace('_', '-')}, $\\gamma_\\mathrm{{nt}}={fixed(g)}$"
    return md, tex


def _cells(block, model, cell) -> list[str]:
    """The table cells of ``model``: ``cell(row)`` (two cells) per query kind, "-" if absent."""
    out = []
    for kind in QUERY_KINDS:
        r = block.get((model, kind))
        out += ["-", "-"] if r is None else cell(r)
    return out


def _md_cells(r) -> list[str]:
    lo, hi = r["success_ci95"]
    return [f"{fixed(r['success_ratio'])} [{lo:.3f}, {hi:.3f}]", fixed(r["cost_ratio"])]


def _band_cells(r) -> list[str]:
    """Detail cells: in-band count, then the in-band and out-of-band success ("-" if absent)."""
    if r.get("n_in_band") is None:
        return ["-", "-", "-"]
    out = [f"{r['n_in_band']} / {r['n_in_band'] + r['n_out_band']}"]
    for part in ("in_band", "out_band"):
        lo, hi = r[f"success_{part}_ci95"]
        out.append(f"{fixed(r[f'success_{part}'])} [{lo:.3f}, {hi:.3f}]" if r[f"n_{part}"] else "-")
    return out


def tables_md(rows, comparisons: list[dict] | None = None) -> str:
    """The Markdown tables; ``comparisons`` (from :func:`comparisons`) adds their tables."""
    out = ["# Results", ""]
    for (task, steer), envs in _groups(rows).items():
        out += [f"## {_title(task, steer)}", ""]
        for env, block in envs.items():
            md, _ = _gamma_heading(env, block)
            any_row = next(iter(block.values()))
            out += [
                f"### {md}",
                "",
                f"K_test = {any_row['k_test']} per query kind; data planner: "
                f"{any_row.get('data_planner', '-')}; reference planner: "
                f"{any_row['reference_planner']}; success ratio with its 95% Wilson interval.",
                "",
                "| Model | Uniform success ratio | Uniform cost ratio | Non-trivial success ratio "
                "| Non-trivial cost ratio |",
                "|---|---|---|---|---|",
            ]
            for m in _models(block):
                out.append(f"| {m} | " + " | ".join(_cells(block, m, _md_cells)) + " |")
            out.append("")
            # extras: optimum ratio, timings, failures, in-band / out-of-band success
            band = any_row.get("band_padding")
            out += [
                (
                    f"Detail. In band: test queries with both endpoints valid at the "
                    f"environment's data padding ({fixed(band, 2)}); out of band: the others."
                ),
                "",
                "| Model | kind | cost ratio to optimum | no path | "
                "infeasible | invalid | reference failed | in band | success in band | "
                "success out of band |",
                "|---|---|---|---|---|---|---|---|---|---|",
            ]
            for m in _models(block):
                for kind in QUERY_KINDS:
                    r = block.get((m, kind))
                    if r is None:
                        continue
                    fl = r["failures"]
                    out.append(
                        f"| {m} | {kind} | {fixed(r.get('cost_ratio_opt'))} | "
                        f"{fl.get('no_path', 0)} | {fl.get('infeasible', 0)} | "
                        f"{fl.get('invalid_query', 0)} | {r['reference_failed']} | "
                        + " | ".join(_band_cells(r))
                        + " |"
                    )
            out.append("")
            out += _comparison_md(
                [
                    c
                    for c in comparisons or ()
                    if (c["task"], c["steer"], c["env"]) == (task, steer, env)
                ]
            )
    return "\n".join(out)


def tables_tex(rows, comparisons: list[dict] | None = None) -> str:
    """The LaTeX tables (the paper's layout); ``comparisons`` (from :func:`comparisons`)
    adds one table of paired comparisons per task and steerTo variant."""
    out = ["% Generated by ntq_jax.experiment.report; needs \\usepackage{booktabs}", ""]
    for (task, steer), envs in _groups(rows).items():
        cap = _title(task, steer).replace("steerTo", "$\\mathsf{steerTo}$")
        out += ["\\begin{table}", "\t\\caption{" + cap + "}", "\t\\centering"]
        for i, (env, block) in enumerate(envs.items()):
            _, tex = _gamma_heading(env, block)
            if i:
                out += ["\t\\vspace{0.5em}", f"\t\\\\{tex} \\\\"]
            else:
                out += [f"\t{tex} \\\\"]
            out += [
                "\t\\vspace{0.2em}",
                "\t\\begin{tabular}{lcccc}",
                "\t\t\\toprule",
                "\t\t\\multirow{2}{*}{Model} & \\multicolumn{2}{c}{Uniform Query} & "
                "\\multicolumn{2}{c}{Non-trivial Query} \\\\",
                "\t\t& {success ratio} & {cost ratio} & {success ratio} & {cost ratio} \\\\",
                "\t\t\\midrule",
            ]
            for m in _models(block):
                cells = _cells(
                    block, m, lambda r: [fixed(r["success_ratio"]), fixed(r["cost_ratio"])]
                )
                out.append(f"\t\t{_tex_model(m)} & " + " & ".join(cells) + " \\\\")
            out += ["\t\t\\bottomrule", "\t\\end{tabular}"]
        out += ["\\end{table}", ""]
        out += _comparison_tex(
            cap, [c for c in comparisons or () if (c["task"], c["steer"]) == (task, steer)]
        )
    return "\n".join(out)


def results_csv(rows, comparisons: list[dict] | None = None) -> str:
    """One CSV line per row; the ``vs_*`` columns hold the row's first comparison as the model."""
    first: dict = {}
    for c in comparisons or ():
        first.setdefault((c["task"], c["env"], c["steer"], c["query_kind"], c["model"]), c)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS + COMPARISON_CSV_FIELDS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        flat = dict(r)
        c = first.get((r["task"], r["env"], r["steer"], r["query_kind"], r["model"]))
        if c is not None:
            flat.update(_comparison_csv(c))
        flat["success_ci95_lo"], flat["success_ci95_hi"] = r["success_ci95"]
        for part in ("in_band", "out_band"):
            if f"success_{part}_ci95" in r:
                lo_hi = r[f"success_{part}_ci95"]
                flat[f"success_{part}_ci95_lo"], flat[f"success_{part}_ci95_hi"] = lo_hi
        for k, v in r["failures"].items():
            flat[f"failures_{k}"] = v
        w.writerow(flat)
    return buf.getvalue()


def timings_csv(rows) -> str:
    """The wall-clock times of the rows (:data:`TIMING_CSV_FIELDS`), one CSV line per row."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=TIMING_CSV_FIELDS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    return buf.getvalue()


# ---------------------------------------------------------------------------
# Everything
# ---------------------------------------------------------------------------


def write_report(
    run_dir,
    rows: list[dict],
    envs: dict | None = None,
    meta: dict | None = None,
    figures: bool = True,
    pairs=DEFAULT_PAIRS,
) -> dict:
    """Writes results.json/csv, tables.md/tex, timings.csv and the figures; returns their paths.

    Args:
        run_dir: the run folder.
        rows: result rows (see :func:`ntq_jax.experiment.evaluate.evaluate_env`).
        envs: ``{env_name: Env}`` for the map figures (optional).
        meta: run metadata stored in ``results.json``.
        figures: write the PNG figures.
        pairs: the paired comparisons, ``[(model, baseline), ...]`` (see :func:`comparisons`).
    """
    run_dir = Path(run_dir)
    out = {
        name: run_dir / name
        for name in ("results.json", "results.csv", "tables.md", "tables.tex", "timings.csv")
    }
    comps = comparisons(run_dir, rows, pairs)
    artifacts.write_json(
        out["results.json"],
        {"meta": meta or {}, "rows": rows, "comparisons": comps},
        indent=1,
        default=str,
    )
    artifacts.write_text(out["results.csv"], results_csv(rows, comps))
    artifacts.write_text(out["tables.md"], tables_md(rows, comps))
    artifacts.write_text(out["tables.tex"], tables_tex(rows, comps))
    artifacts.write_text(out["timings.csv"], timings_csv(rows))
    if figures:
        out.update(_figures(run_dir, rows, envs or {}))
    return out


def _figures(run_dir: Path, rows: list[dict], envs: dict) -> dict:
    """The report's figures (:mod:`ntq_jax.plotting`): ``{file name: path}`` of those written."""
    figs = run_dir / "figures"
    written = []
    for steer in sorted({r["steer"] for r in rows}, reverse=True):
        written.append(
            plotting.success_figure(
                rows, figs / f"success_ratio{'' if steer else '_nosteer'}.png", steer
            )
        )
    for name, env in envs.items():
        slug = env_slug(name, env)
        steer = any(r["steer"] for r in rows if r["env"] == name)
        mine = [
            r
            for r in rows
            if r["env"] == name and r["steer"] == steer and r["query_kind"] == "nontrivial"
        ]
        saved = {
            r["model"]: artifacts.load_npz(run_dir / r["paths_file"])
            for r in sorted(mine, key=lambda r: _model_key(r["model"]))
        }
        eval_dir = run_dir / "eval" / slug
        written.append(
            plotting.examples_figure(
                env,
                artifacts.load_npz(eval_dir / "reference.npz"),
                saved,
                figs / f"examples_{slug}.png",
            )
        )
        written.append(
            plotting.queries_figure(
                env, artifacts.load_npz(eval_dir / "queries.npz"), figs / f"queries_{slug}.png"
            )
        )
    return {p.name: p for p in written if p}
