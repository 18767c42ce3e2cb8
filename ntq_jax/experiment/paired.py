"""Paired comparisons of an evaluation's models, and their tables (:mod:`ntq_jax.experiment.report`).

Paired comparisons (:func:`comparisons`, statistics in :mod:`ntq_jax.stats`):
every model is tested on the same queries, so models are compared query by
query, per (environment, query kind, steerTo), from the per-query arrays of the
saved paths files: McNemar's exact test and the success-ratio difference with
Newcombe's paired interval; over the queries both solve, the mean difference of
cost ratio with a paired bootstrap interval and the Wilcoxon signed-rank
p-value. Which models are compared is data (:data:`DEFAULT_PAIRS`: PNet_1..3 vs
PNet_0, the ensemble rows vs the best member; a baseline :data:`BEST_MEMBER` is
the single member with the highest success in that cell). They are a table after each detail table of
``tables.md``, the ``comparisons`` list of ``results.json``, and the ``vs_*``
columns of ``results.csv`` (a row's first comparison as the model).

Their tables are made here too (Markdown, LaTeX, and the ``vs_*`` columns
:data:`COMPARISON_CSV_FIELDS`), and placed by the report's
:func:`~ntq_jax.experiment.report.tables_md`,
:func:`~ntq_jax.experiment.report.tables_tex` and
:func:`~ntq_jax.experiment.report.results_csv`.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

from ntq_jax import artifacts, stats
from ntq_jax.experiment.formatting import _tex_model, estimate, p_value
from ntq_jax.types import QUERY_KINDS

# a row's first paired comparison (as the model; see comparisons()), after CSV_FIELDS
COMPARISON_CSV_FIELDS = [
    "vs_model",
    "vs_only_model",
    "vs_only_baseline",
    "vs_success_diff",
    "vs_success_diff_ci95_lo",
    "vs_success_diff_ci95_hi",
    "vs_mcnemar_p",
    "vs_cost_n",
    "vs_cost_ratio_diff",
    "vs_cost_ratio_diff_ci95_lo",
    "vs_cost_ratio_diff_ci95_hi",
    "vs_wilcoxon_p",
]

#: Baseline placeholder of a pair: the single member (``PNet_<m>``) with the most
#: successes in the (environment, query kind, steerTo) cell (ties: the lower index).
BEST_MEMBER = "best member"
#: The paired comparisons of the report, ``(model, baseline)``: PNet_1..3 vs PNet_0, and
#: the ensemble rows (``eval.ensemble``; best-of-4, or of 5 with a D4 member; the cascade)
#: vs their best member. Pairs whose model has no row are left out.
DEFAULT_PAIRS: tuple[tuple[str, str], ...] = (
    ("PNet_1", "PNet_0"),
    ("PNet_2", "PNet_0"),
    ("PNet_3", "PNet_0"),
    ("PNet_ens", BEST_MEMBER),
    ("PNet_best-of-4", BEST_MEMBER),
    ("PNet_best-of-5", BEST_MEMBER),
    ("PNet_cascade", BEST_MEMBER),
)
_MEMBER = re.compile(r"PNet_(\d+)")


def best_member(cell: dict) -> str | None:
    """The single member (``PNet_<m>``) of ``cell`` (``{model: row}``) with the most successes.

    Ties go to the lower member index; None if the cell has no single member.
    """
    members = [
        (-r["successes"], int(mt.group(1)), m)
        for m, r in cell.items()
        if (mt := _MEMBER.fullmatch(m))
    ]
    return min(members)[2] if members else None


def _nan_to_none(v):
    if isinstance(v, float) and math.isnan(v):
        return None
    if isinstance(v, list):
        return [_nan_to_none(x) for x in v]
    return v


def comparisons(
    run_dir,
    rows,
    pairs=DEFAULT_PAIRS,
    *,
    n_boot: int = stats.N_BOOT,
    seed: int = stats.SEED,
    load=artifacts.load_npz,
) -> list[dict]:
    """Paired comparisons of models tested on the same queries (:func:`ntq_jax.stats.paired_comparison`).

    For every (task, environment, steerTo, query kind) cell of ``rows`` and every
    ``(model, baseline)`` of ``pairs`` whose models both have a row there, the
    per-query arrays of their paths files (``row["paths_file"]`` under
    ``run_dir``: ``success``, ``costs``, ``ref_costs``, ``ref_status``,
    ``queries``) are compared, model minus baseline. A baseline
    :data:`BEST_MEMBER` is resolved per cell by :func:`best_member`. Pairs with
    a missing model or an unreadable paths file are left out (one warning per
    call for the files), as are pairs whose files hold different queries
    (a warning each).

    Args:
        run_dir: the run folder.
        rows: the result rows.
        pairs: ``[(model, baseline), ...]``.
        n_boot, seed: the cost bootstrap (:func:`ntq_jax.stats.paired_cost_difference`).
        load: ``path -> dict of arrays | None`` (default :func:`ntq_jax.artifacts.load_npz`).

    Returns:
        One dict per comparison, in the order (task, steerTo, environment) as
        first seen in ``rows``, then ``pairs``, then query kind: ``task``,
        ``env``, ``steer``, ``query_kind``, ``model``, ``baseline``,
        ``baseline_rule`` (``BEST_MEMBER`` or None), ``n_boot``, ``seed`` and
        the fields of :func:`ntq_jax.stats.paired_comparison` (NaN as None).
    """
    run_dir = Path(run_dir)
    cells: dict = {}
    for r in rows:
        cells.setdefault((r["task"], r["steer"], r["env"]), {}).setdefault(r["query_kind"], {})[
            r["model"]
        ] = r
    cache: dict = {}
    missing: list[str] = []

    def arrays(row):
        f = row.get("paths_file")
        if f not in cache:
            cache[f] = load(run_dir / f) if f else None
            if cache[f] is None:
                missing.append(str(f))
        return cache[f]

    out = []
    for (task, steer, env), kinds in cells.items():
        for model, base in pairs:
            for kind in [k for k in QUERY_KINDS if k in kinds] + sorted(
                set(kinds) - set(QUERY_KINDS)
            ):
                cell = kinds[kind]
                base_name = best_member(cell) if base == BEST_MEMBER else base
                if model not in cell or base_name not in cell or base_name == model:
                    continue
                a, b = arrays(cell[model]), arrays(cell[base_name])
                if a is None or b is None:
                    continue
                try:
                    cmp = stats.paired_comparison(a, b, n_boot=n_boot, seed=seed)
                except ValueError as e:
                    warnings.warn(
                        f"paired comparison {model} vs {base_name} ({env}, {kind}, "
                        f"steer={steer}) left out: {e}",
                        stacklevel=2,
                    )
                    continue
                out.append(
                    {
                        "task": task,
                        "env": env,
                        "steer": bool(steer),
                        "query_kind": kind,
                        "model": model,
                        "baseline": base_name,
                        "baseline_rule": base if base == BEST_MEMBER else None,
                        "n_boot": n_boot,
                        "seed": seed,
                        **{k: _nan_to_none(v) for k, v in cmp.items()},
                    }
                )
    if missing:
        warnings.warn(
            f"paired comparisons: {len(missing)} paths file(s) missing or unreadable "
            f"under {run_dir} (e.g. {missing[0]}); their pairs are left out",
            stacklevel=2,
        )
    return out


# ---------------------------------------------------------------------------
# The tables: Markdown, LaTeX and the CSV columns
# ---------------------------------------------------------------------------


def _comparison_md(comps) -> list[str]:
    """The paired-comparison table of one environment block (empty if no comparison)."""
    if not comps:
        return []
    out = [
        "Detail, paired comparisons on the same test queries (model minus baseline): "
        "queries solved by both / only the model / only the baseline / neither; success "
        "ratio difference with Newcombe's paired 95% interval and McNemar's exact p; over "
        "the queries both solve, the mean difference of cost ratio with a paired bootstrap "
        "95% interval and the Wilcoxon signed-rank p.",
        "",
        "| Model | vs | kind | both / only model / only vs / neither | success diff [95%] | "
        "McNemar p | both solved | cost ratio diff [95%] | Wilcoxon p |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in comps:
        vs = c["baseline"] + (f" ({c['baseline_rule']})" if c.get("baseline_rule") else "")
        out.append(
            f"| {c['model']} | {vs} | {c['query_kind']} | "
            f"{c['both']} / {c['only_a']} / {c['only_b']} / {c['neither']} | "
            f"{estimate(c['success_diff'], c['success_diff_ci95'])} | {p_value(c['mcnemar_p'])} | "
            f"{c['cost_n']} | {estimate(c['cost_ratio_diff'], c['cost_ratio_diff_ci95'])} | "
            f"{p_value(c['wilcoxon_p'])} |"
        )
    return out + [""]


def _tex_p(p) -> str:
    return p_value(p).replace("<", "$<$")


def _comparison_tex(title: str, comps) -> list[str]:
    """The paired comparisons of one task and steerTo variant as one LaTeX table."""
    if not comps:
        return []
    out = [
        "\\begin{table}",
        "\t\\caption{" + title + ": paired comparisons on the same test queries (model "
        "minus baseline). Success difference with Newcombe's paired 95\\% interval and "
        "McNemar's exact $p$; cost ratio difference over the queries both solve, with a "
        "paired bootstrap 95\\% interval and the Wilcoxon signed-rank $p$.}",
        "\t\\centering",
        "\t\\begin{tabular}{llllcccc}",
        "\t\t\\toprule",
        "\t\tEnv. & Model & vs & Query & success diff. & McNemar $p$ & cost ratio diff. & "
        "Wilcoxon $p$ \\\\",
        "\t\t\\midrule",
    ]
    for c in comps:
        vs = _tex_model(c["baseline"]) + (" (best)" if c.get("baseline_rule") else "")
        kind = "non-trivial" if c["query_kind"] == "nontrivial" else c["query_kind"]
        out.append(
            f"\t\t{c['env']} & {_tex_model(c['model'])} & {vs} & {kind} & "
            f"{estimate(c['success_diff'], c['success_diff_ci95'])} & "
            f"{_tex_p(c['mcnemar_p'])} & "
            f"{estimate(c['cost_ratio_diff'], c['cost_ratio_diff_ci95'])} & "
            f"{_tex_p(c['wilcoxon_p'])} \\\\"
        )
    return out + ["\t\t\\bottomrule", "\t\\end{tabular}", "\\end{table}", ""]


def _comparison_csv(c: dict) -> dict:
    out = {
        "vs_model": c["baseline"],
        "vs_only_model": c["only_a"],
        "vs_only_baseline": c["only_b"],
        "vs_success_diff": c["success_diff"],
        "vs_mcnemar_p": c["mcnemar_p"],
        "vs_cost_n": c["cost_n"],
        "vs_cost_ratio_diff": c["cost_ratio_diff"],
        "vs_wilcoxon_p": c["wilcoxon_p"],
    }
    out["vs_success_diff_ci95_lo"], out["vs_success_diff_ci95_hi"] = c["success_diff_ci95"]
    out["vs_cost_ratio_diff_ci95_lo"], out["vs_cost_ratio_diff_ci95_hi"] = c["cost_ratio_diff_ci95"]
    return out
