"""The paper's Tables I-IV beside ours: ``results/paper/REPRODUCTION.md`` from committed summaries.

The paper reproduced here is

    Sagar Suhas Joshi and Panagiotis Tsiotras, "Non-Trivial Query Sampling For
    Efficient Learning To Plan" (Georgia Institute of Technology).

Its numbers are transcribed in :data:`PAPER` (Tables I-IV: per environment
gamma_nt, and per model PNet_0..PNet_3 the success ratio and cost ratio on
uniform and on non-trivial test queries) and its experiment sizes in
:data:`PAPER_K_TRAIN`, :data:`PAPER_K_TEST` and :data:`PAPER_PADDING` (each with
the sentence of Section V it comes from).

Input: ``scripts/reproduce.py`` runs the pipeline one map at a time at the paper's
sizes and writes one folder per map, ``<root>/<task>/<map>/summary.json`` (task
``point``, ``rigid`` or ``nlink``; map like ``point_0``), and for its other
training seeds the same schema under
``<root>/<task>/<map>/seeds/train_seed_<k>/summary.json`` (same data, another
training seed). A summary holds ``task``, ``env``, ``train_seed``, the resolved
``config``, the environment's data ``padding``, the result ``rows`` and paired
``comparisons`` of that map exactly as in a run's ``results.json``, the
``fingerprints`` of its datasets and models, per-stage ``timings`` and the
``command`` that made it.

Functions (pure, data only; this module computes nothing with JAX):

* :func:`load_summaries` reads every summary under a root, sorted by task, map
  (the paper's order), main run before seed runs, train seed.
* :func:`check_summary` lists what makes a summary not a paper-size run
  (K_train, K_test, padding, datasets D0..D3, fingerprints, timings, rows);
  empty when fine. :func:`check_seed_runs` checks that each seed run has its
  folder's train seed and the main run's dataset fingerprints (same data).
* :func:`ntq_jax.experiment.claims.claims` checks the trend claims of the paper's
  Results section, each one line with a verdict and the numbers (see "Claims" and
  "Verdicts" below).
* :func:`summary_page` is the document's first section: PNet_3 - PNet_0 on
  non-trivial queries per map, per robot and over all maps, the paper's value
  beside ours with the seed-aware interval, the spread over seeds, p, Holm's p
  and the verdict (:mod:`ntq_jax.experiment.verdict_tables`, with the last
  section, every claim's line).
* :func:`seed_variance` and :func:`seed_variance_diffs`: mean and range over a
  map's training seeds of every row (success, cost ratio) and of every paired
  success difference (with how many seeds reach p < 0.05)
  (:mod:`ntq_jax.experiment.seed_tables`, with the section "Seed variance").
* :func:`render` turns a root into the whole Markdown document: how it was
  made, coverage (which of the 11 maps and of Table III are present, which are
  missing), Tables I-IV (ours with the 95% interval next to the paper's; the
  ensemble rows, ours only; the paired differences PNet_1/2/3 - PNet_0 and
  ensemble - best member with their 95% interval and McNemar p; the reference
  planner and time per query), the time per stage and map, the seed variance
  (mean and range over the training seeds found for a map), and the claims.
  The output depends only on the summaries (no clock, fixed float formats).
* :func:`write` writes ``<root>/REPRODUCTION.md`` atomically.

Command line: ``python scripts/reproduce.py --report-only [--results ROOT]`` writes the
document; ``--check`` with it writes nothing and exits 1 with a one-line message
if the file on disk differs from what :func:`render` gives.

Claims (the paper's words in quotes; "with steerTo" = Tables I, II, IV; what each
is measured on, its test and its verdict: :mod:`ntq_jax.experiment.claims`):

* "In most cases, PNet_2 and PNet_3 outperform PNet_0": PNet_3 >= PNet_0 on
  non-trivial queries per map, per task and over all 11 maps, PNet_2 and
  PNet_3 >= PNet_0 per task over both kinds;
* point: "all models perform well with a success rate of over 90%", per map;
* rigid: "The PNet_3 model has the highest success ratio in all cases except
  one (Environment 3, Non-trivial Query)", per map and kind;
* n-link: "The success ratio over uniform queries is in the range of 0.9, 0.8
  and 0.7 for the case of 2, 4 and 6-link" (as falling from 2 to 4 to 6
  links), "about a 25% increase in the success ratio over PNet_0 for the 6-link
  (non-trivial queries) case", and the gain on 4 and 6 links larger than on 2
  links ("much more evident");
* "The cost ratio is relatively lower for the rigid body and 6-link case" (ours
  against our reference planners, the paper's against BIT*);
* "The success ratio for all PNet models is naturally higher over uniform test
  queries", per task and model;
* "The success ratio also generally has an inverse relation with gamma_nt",
  per task, per query kind, and over all 11 maps within robots;
* without steerTo (Table III): "the performance of PNet_3 is the worst" and
  "The PNet_0 model performs best on uniform queries in all environments" per
  map; "PNet_1 or PNet_2 show better performance over non-trivial queries in
  some cases"; "The success ratio of all PNet models is adversely affected",
  per model.

Verdicts: the test (training seeds as a random effect), the multiplicity
correction (Holm over every p-value a verdict uses) and the rule (holds,
contradicted, the paper's magnitude excluded, unresolved) are written once, in
:mod:`ntq_jax.experiment.claims` (with :mod:`~ntq_jax.experiment.quantities`, the
test, and :mod:`~ntq_jax.experiment.verdicts`, Holm and the rule); the document
opens with the one-page summary of the central claim (:func:`summary_page`) and ends
with every claim's line.
"""

from __future__ import annotations

from pathlib import Path

from ntq_jax import artifacts
from ntq_jax.experiment import factor_table, seed_tables
from ntq_jax.experiment.claims import claims
from ntq_jax.experiment.formatting import (
    fixed,
    interval,
    kind_name,
    model_key,
    ms,
    num,
    p_value,
    signed,
    stale_page,
)
from ntq_jax.experiment.formatting import root_label as _root_label
from ntq_jax.experiment.paper import KINDS, MAPS, MEMBERS, PAPER, PAPER_TABLES
from ntq_jax.experiment.seed_tables import seed_variance, seed_variance_diffs
from ntq_jax.experiment.summaries import (
    check_seed_runs,
    check_summary,
    is_seed_run,
    k_train_of,
    load_summaries,
    main_runs,
    run_cells,
)
from ntq_jax.experiment.verdict_tables import claims_section, summary_page

__all__ = [
    "DOC_NAME",
    "seed_variance",
    "seed_variance_diffs",
    "summary_page",
    "render",
    "write",
    "check",
]

DOC_NAME = "REPRODUCTION.md"


def _header(summaries, label: str = "results/paper") -> list[str]:
    cmds = sorted({s.get("command") for s in summaries if s.get("command")})
    out = [
        "# Reproduction of the paper's Tables I-IV",
        "",
        'Paper: Sagar Suhas Joshi and Panagiotis Tsiotras, "Non-Trivial Query Sampling For '
        'Efficient Learning To Plan". Its numbers and sizes are transcribed in '
        "`ntq_jax/experiment/paper.py` (`PAPER`, `PAPER_K_TRAIN`, `PAPER_K_TEST`, `PAPER_PADDING`).",
        "",
        "Generated from the committed summaries (`<task>/<map>/summary.json`, seed runs in "
        "`<task>/<map>/seeds/train_seed_<k>/summary.json`) by "
        f"`python scripts/reproduce.py --report-only --results {label}` (do not edit by hand; "
        "add `--check` to tell whether it is current). "
        "The summaries were made with:",
        "",
    ]
    out += [f"    {c}" for c in cmds] or ["    (no summary yet: `python scripts/reproduce.py ...`)"]
    out += [
        "",
        "Success ratio: successes / K_test, with its 95% Wilson interval. Cost ratio: "
        "neural cost / reference planner cost, mean over the queries both solve. Paired "
        "differences in Tables I-IV are those of the main run (training seed 0) on the same "
        "test queries: model minus baseline, Newcombe's 95% interval and McNemar's exact p, "
        "which account for the test queries only, not for training; the verdicts (the "
        "summary above and the claims at the end) use the seed-aware test instead.",
        "",
        "Test queries: every query sampled at padding 0 (the evaluation geometry), the "
        "population the headline tables use, since the paper's padding \"was propagated "
        "during the data generation step, and was relaxed during the final performance "
        'evaluation step" (Section V). Some of them have an endpoint inside the data '
        "padding's band, where no training state lies: the queries in band (both ends "
        "valid at the data padding) and out of band are reported apart in the factor "
        "study's section below, where the results have one.",
        "",
    ]
    return out


def _coverage(summaries) -> list[str]:
    main = main_runs(summaries)
    out = [
        "## Coverage",
        "",
        "| Table | Map | status | K_train | K_test | padding | train seed | package | "
        "config hash | finished | check |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    missing = []
    for tid, spec in PAPER_TABLES.items():
        for env in spec["envs"]:
            s = main.get(env)
            present = s is not None and bool(run_cells(s, spec["steer"]))
            if not present:
                missing.append(f"{tid} {env}")
                out.append(f"| {tid} | {env} | missing | - | - | - | - | - | - | - | - |")
                continue
            probs = check_summary(s)
            cfg = s.get("config") or {}
            out.append(
                f"| {tid} | {env} | present | {k_train_of(cfg, env)} | "
                f"{cfg.get('eval', {}).get('k_test')} | {s.get('padding')} | "
                f"{s.get('train_seed')} | {s.get('package_version', '-')} | "
                f"{s.get('config_hash', '-')} | {s.get('finished', '-')} | "
                f"{'ok' if not probs else '; '.join(probs)} |"
            )
    n_maps = sum(1 for e in MAPS if e in main and run_cells(main[e], True))
    n3 = sum(1 for e in PAPER_TABLES["III"]["envs"] if e in main and run_cells(main[e], False))
    out += [
        "",
        f"Maps with steerTo: {n_maps} of {len(MAPS)}; Table III (rigid without "
        f"steerTo): {n3} of {len(PAPER_TABLES['III']['envs'])}.",
    ]
    out.append("Missing: " + (", ".join(missing) if missing else "none") + ".")
    extra = sorted({s.get("env") for s in summaries if s.get("env") not in MAPS}, key=str)
    if extra:
        out.append("Not maps of the paper (ignored): " + ", ".join(map(str, extra)) + ".")
    seeds = []
    for env in MAPS:
        ks = sorted({s.get("train_seed") for s in summaries if s.get("env") == env}, key=str)
        if ks:
            seeds.append(f"{env} {len(ks)} ({', '.join(map(str, ks))})")
    bad = [
        f"`{s['_path']}`: {'; '.join(p)}."
        for s in summaries
        if is_seed_run(s) and (p := check_summary(s))
    ] + [f"{p}." for p in check_seed_runs(summaries)]
    out += [f"Training seeds per map (the same data; `seeds/train_seed_<k>`): {'; '.join(seeds)}."]
    if bad:
        out += ["Seed-run problems: " + " ".join(bad)]
    return out + [""]


def _table_block(tid: str, env: str, s) -> list[str]:
    spec = PAPER_TABLES[tid]
    paper = PAPER[tid][env]
    cell = run_cells(s, spec["steer"])
    r0 = cell.get(("PNet_0", "uniform")) or next(iter(cell.values()), None)
    g = None if r0 is None else r0.get("gamma_nt")
    out = [
        f"### {env}: gamma_nt {fixed(g)}{interval(None if r0 is None else r0.get('gamma_nt_ci95'))} "
        f"(paper {paper['gamma_nt']:.3f})",
        "",
    ]
    if not cell:
        return out + ["Not run yet.", ""]
    out += [
        "| Model | uniform success [95%] | paper | uniform cost ratio | paper | "
        "non-trivial success [95%] | paper | non-trivial cost ratio | paper |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    models = sorted({m for m, _ in cell} | set(MEMBERS), key=model_key)
    for m in models:
        cells = []
        for kind in KINDS:
            r = cell.get((m, kind))
            pm = paper["models"].get(m, {}).get(kind)
            cells += [
                ("-" if r is None else fixed(r["success_ratio"]) + interval(r.get("success_ci95"))),
                "-" if pm is None else fixed(pm["success"]),
                "-" if r is None else fixed(r.get("cost_ratio")),
                "-" if pm is None else fixed(pm["cost"]),
            ]
        out.append(f"| {m} | " + " | ".join(cells) + " |")
    refs = sorted(
        {(r.get("reference_planner"), r.get("data_planner")) for r in cell.values()}, key=str
    )
    out += [
        "",
        "Reference planner (cost ratio denominator): "
        + ", ".join(f"{a} (data: {b})" for a, b in refs)
        + ".",
    ]
    comps = sorted(
        (c for c in s.get("comparisons", []) if bool(c.get("steer", True)) == spec["steer"]),
        key=lambda c: (
            model_key(c["model"]),
            KINDS.index(c["query_kind"]) if c["query_kind"] in KINDS else 9,
        ),
    )
    if comps:
        out += [
            "",
            "| Model | vs | kind | success diff [95%] | McNemar p | paper diff | "
            "cost ratio diff [95%] | Wilcoxon p |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for c in comps:
            pm, pb = paper["models"].get(c["model"]), paper["models"].get(c["baseline"])
            pdiff = (
                "-"
                if pm is None or pb is None or c.get("baseline_rule")
                else signed(pm[c["query_kind"]]["success"] - pb[c["query_kind"]]["success"])
            )
            vs = c["baseline"] + (f" ({c['baseline_rule']})" if c.get("baseline_rule") else "")
            out.append(
                f"| {c['model']} | {vs} | {kind_name(c['query_kind'])} | "
                f"{signed(c['success_diff'])}{interval(c.get('success_diff_ci95'))} | "
                f"{p_value(c.get('mcnemar_p'))} | {pdiff} | "
                f"{signed(c.get('cost_ratio_diff'))}{interval(c.get('cost_ratio_diff_ci95'))} | "
                f"{p_value(c.get('wilcoxon_p'))} |"
            )
    return out + [""]


def _tables(summaries) -> list[str]:
    main = main_runs(summaries)
    out = []
    for tid, spec in PAPER_TABLES.items():
        out += [f"## Table {tid}: {spec['title']}", ""]
        for env in spec["envs"]:
            out += _table_block(tid, env, main.get(env))
    return out


def _datasets(summaries) -> list[str]:
    """Per map, each dataset's planned paths, samples and mean states per data path (the
    summaries that record them)."""
    main = main_runs(summaries)
    rows = [
        (env, main[env]["datasets"])
        for env in MAPS
        if env in main and isinstance(main[env].get("datasets"), dict)
    ]
    if not rows:
        return []
    names = sorted({n for _, d in rows for n in d}, key=lambda n: (len(n), n))
    out = [
        "## Datasets",
        "",
        "Per dataset: planned paths used / samples written (includeData, Alg. 4) / mean "
        "states per data path; D3's samples are D2's paths after pruning.",
        "",
        "| Map | data paths | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for env, d in rows:
        cfg = (main[env].get("config") or {}).get("planner") or {}
        mode = next(
            (
                o.get("data_paths")
                for o in cfg.get("per_env") or ()
                if o.get("env") == env and o.get("data_paths") is not None
            ),
            cfg.get("data_paths"),
        )
        cells = [
            f"{v['paths']} / {v['samples']} / {v['states_per_path']:.1f}" if v else "-"
            for v in (d.get(n) for n in names)
        ]
        out.append(f"| {env} | {'default' if mode is None else mode} | " + " | ".join(cells) + " |")
    return out + [""]


def _times(summaries) -> list[str]:
    main = main_runs(summaries)
    out = [
        "## Time per query (ms)",
        "",
        "Neural planner per model, and the reference planner, per test query (mean).",
        "",
        "| Map | steerTo | kind | " + " | ".join(MEMBERS) + " | ensemble rows | reference |",
        "|---|---|---|" + "---|" * len(MEMBERS) + "---|---|",
    ]
    for env in MAPS:
        s = main.get(env)
        for steer in (True, False):
            cell = run_cells(s, steer)
            for kind in KINDS:
                rows = {m: r for (m, k), r in cell.items() if k == kind}
                if not rows:
                    continue
                ens = (
                    ", ".join(
                        f"{m} {ms(rows[m].get('seconds_per_query'))}"
                        for m in sorted(rows, key=model_key)
                        if m not in MEMBERS
                    )
                    or "-"
                )
                ref = next((r.get("reference_seconds_per_query") for r in rows.values()), None)
                out.append(
                    f"| {env} | {'yes' if steer else 'no'} | {kind_name(kind)} | "
                    + " | ".join(
                        ms(rows[m].get("seconds_per_query")) if m in rows else "-" for m in MEMBERS
                    )
                    + f" | {ens} | {ms(ref)} |"
                )
    out += [
        "",
        "## Time per stage (s)",
        "",
        "| Run | data | train | eval | total |",
        "|---|---|---|---|---|",
    ]
    tot = {"data": 0.0, "train": 0.0, "eval": 0.0}
    for s in summaries:
        tm = s.get("timings") or {}
        vals = [tm.get(k) for k in tot]
        for k, v in zip(tot, vals):
            tot[k] += v if num(v) else 0.0
        run = s.get("env", "?") + (f" (train seed {s.get('train_seed')})" if is_seed_run(s) else "")
        out.append(
            f"| {run} | "
            + " | ".join(fixed(v, 1) for v in vals)
            + f" | {fixed(sum(v for v in vals if num(v)), 1)} |"
        )
    out.append(
        "| total | "
        + " | ".join(fixed(v, 1) for v in tot.values())
        + f" | {fixed(sum(tot.values()), 1)} |"
    )
    return out + [""]


def render(root, factors=None) -> str:
    """The whole ``REPRODUCTION.md`` of the summaries under ``root`` (deterministic).

    ``factors``: the factor study's folder for the section "What decides PNet_3 vs
    PNet_0" (:mod:`ntq_jax.experiment.factor_table`); None = ``<root>/../factors``
    (the section is left out when it holds no cell).
    """
    summaries = load_summaries(root)
    factors = Path(root).parent / "factors" if factors is None else Path(factors)
    cs = claims(summaries)
    head = _header(summaries, _root_label(root))
    lines = (
        head[:2]
        + summary_page(cs)
        + head[2:]
        + _coverage(summaries)
        + _tables(summaries)
        + factor_table.section(factors, _root_label(factors))
        + _datasets(summaries)
        + _times(summaries)
        + seed_tables.section(summaries)
        + claims_section(cs)
    )
    return "\n".join(lines).rstrip("\n") + "\n"


def write(root) -> Path:
    """Writes ``<root>/REPRODUCTION.md`` (atomically) and returns its path: the paper's
    tables, or for a root of Panda runs (``<root>/panda/``) the page of
    :mod:`ntq_jax.experiment.panda_page`."""
    from ntq_jax.experiment import panda_page

    if panda_page.is_panda_root(root):
        return panda_page.write(root)
    return artifacts.write_text(Path(root) / DOC_NAME, render(root))


def check(root) -> str | None:
    """None if ``<root>/REPRODUCTION.md`` is what :func:`render` (or, for a root of Panda
    runs, :func:`ntq_jax.experiment.panda_page.render`) gives, else why not (one line)."""
    from ntq_jax.experiment import panda_page

    if panda_page.is_panda_root(root):
        return panda_page.check(root)
    return stale_page(Path(root) / DOC_NAME, render(root), root)
