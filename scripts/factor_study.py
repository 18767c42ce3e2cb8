#!/usr/bin/env python
"""What decides PNet_3 vs PNet_0: a factor study over data paths, planner budgets and test band.

Examples::

    python scripts/factor_study.py --list               # every cell and whether it is done
    python scripts/factor_study.py --next               # run the first pending cell
                                                        # (one worker per core: each claims its own)
    python scripts/factor_study.py --cell rigid_0/density/ours
    python scripts/factor_study.py --report-only        # results/factors/README.md only

Factors, on point/0, point/3, rigid/0, rigid/2 and nlink/4 at the paper's sizes
(``configs/<task>.yaml``):

* data paths (``planner.data_paths``): ``shortcut`` (a few corners: the point
  robot's default), ``density`` (the shortcut resampled to BIT*'s states per
  path: the rigid body's and the arms' default),
  ``raw`` (the planner's own waypoints) and, on rigid/0 and nlink/4, ``bitstar``
  (the committed BIT* records at the paper's budgets, 3 s and 4 s,
  ``results/data_paths/bitstar/<map>``; nlink/4's with training seeds 1 and 2);
* neural planner budgets: ``ours`` (the config's) and ``mpnet`` (MPNet's: 80
  coarse steps, 10 replanning rounds, 50 steps per reconnection), evaluated on
  the same trained PNets of the default data paths;
* without steerTo (Table III, the rigid maps): the paper's goal test
  (``||pi_end - x_g||_2`` on the raw state vector), its unchecked paths ("only
  the lines 8 and 9"), and both, against ours (robot metric, paths checked by the
  certified check), the paths checked by the paper's discretised check instead, and
  the paper's goal test with only the paths' states checked (``nosteer_states``),
  and the paper's goal test in place of line 4's steerTo only, the rest of Alg. 1
  (the goal appended, Feasible, Replan) as with steerTo (``nosteer_replan``);
* test band: every test query, in band (both endpoints valid at the data
  padding, where training states lie) and out of band, from the same runs;
* pruning that keeps each path's last step (beyond the paper): the default data
  with a fifth dataset ``D4`` (``p_nt`` 1, ``prune: keep_last``), its PNet_4
  compared with PNet_0 and with PNet_3 (data mode ``<default>+keep_last``).

A cell is one map, data mode and budget: its run in ``<runs>/<map>/<data>/<budget>/``
(resumable), its summary (:mod:`ntq_jax.experiment.summaries`) and ``paired.json`` (PNet_k
- PNet_0 per query kind, steerTo and band: Newcombe interval, McNemar p) in
``<results>/<map>/<data>/<budget>/``. ``--seeds`` cells retrain the same data with
training seeds 1 and 2 (``.../seeds/train_seed_<k>/``). Commit each cell as it
finishes; ``README.md`` is regenerated from every finished cell. The cells of a
task's default data paths with its budgets are ``scripts/reproduce.py``'s runs
(``--paper-runs``): either script resumes the other's. The paper's six other maps
(:data:`PAPER_ONLY`) get their default cell and its training seeds 1 and 2, so one queue
of ``--next`` workers also re-runs Tables I-IV on all eleven maps, each with three
training seeds, and five on the maps where three left the verdict open
(:data:`MORE_SEEDS`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import NamedTuple

from ntq_jax.experiment.cells import check_cells, damaged, is_done, paired
from ntq_jax.experiment.cli import UsageError, run_cli

MAPS = {
    "rigid/0": "rigid",
    "point/0": "point",
    "nlink/4": "nlink",
    "rigid/2": "rigid",
    "point/3": "point",
}  # the factor maps, in the order --next runs them
#: The paper's other maps: only their default cell (the task's reproduction of the map,
#: Tables I-IV), queued after the factor maps' cells and before the cells beyond the paper
PAPER_ONLY = ("rigid/1", "rigid/3", "nlink/6", "nlink/2", "point/1", "point/2")
#: The maps whose PNet_3 - PNet_0 interval (non-trivial queries, three training seeds,
#: the seed-aware test of results/paper/REPRODUCTION.md) still contained zero: they get
#: training seeds 3 and 4 as well (five in all), the last cells of the queue.
MORE_SEEDS = ("point/1", "point/2", "point/3", "rigid/0", "rigid/1", "rigid/2", "rigid/3")
EXTRA_SEEDS = (3, 4)
#: evaluation variants on the same trained PNets (a cell's ``budget``): MPNet's budgets, and
#: the paper's variant without steerTo (Table III): its goal test ||pi_end - x_g||_2 <= delta
#: on the raw state vector, and "only the lines 8 and 9" (the path's segments not checked)
EVAL_VARIANTS = {
    "ours": [],
    "mpnet": ["eval.n_plan=80", "eval.replan_rounds=10", "eval.replan_steps=50"],
    "nosteer_l2": ["eval.delta_norm=l2"],
    "nosteer_unchecked": ["eval.nosteer_check=false"],
    "nosteer_paper": ["eval.delta_norm=l2", "eval.nosteer_check=false"],
    # the paper's own (discretised) motion check judges the paths: checked, but coarser
    "nosteer_discretized": ["eval.motion_check=discretized"],
    # the paper's goal test, and "Feasible" read as every state of the path valid (its
    # segments not checked): between the checked and the unchecked variants
    "nosteer_states": ["eval.delta_norm=l2", "eval.nosteer_check=states"],
    # the paper's goal test in place of line 4's steerTo only: the goal appended once it
    # passes, then Alg. 1's lines 10-14 as with steerTo (Feasible, else Replan)
    "nosteer_replan": ["eval.delta_norm=l2", "eval.nosteer_check=replan"],
}
MPNET_BUDGETS = EVAL_VARIANTS["mpnet"]
#: The committed BIT* records (``scripts/record_paths.py``, the paper's budget and pool
#: sizes) the ``bitstar`` cells train on, per map.
BITSTAR_RECORDS = {
    "rigid/0": "results/data_paths/bitstar/rigid_0",
    "nlink/4": "results/data_paths/bitstar/nlink_4",
}
#: BIT*-like spacings where the task config's default is not a spacing (see README.md)
#: (the point robot: BIT* at 2 s on 200 non-trivial point/0 queries, mean segment 0.34,
#: results/data_paths/density_point_0.json; its default stays the shortcut)
DENSITY: dict[str, float] = {"point/0": 0.34, "point/3": 0.34}


def default_data(map_name: str) -> str:
    """The data mode of the task's config: the cells the headline reads (three seeds)."""
    return "shortcut" if task_of(map_name) == "point" else "density"


def task_of(map_name: str) -> str:
    """The task (``configs/<task>.yaml``) of a preset map: ``rigid/2`` -> ``rigid``."""
    return map_name.split("/")[0]


class Cell(NamedTuple):
    map: str
    data: str
    budget: str
    train_seed: int = 0

    @property
    def slug(self) -> str:
        return self.map.replace("/", "_")

    @property
    def key(self) -> str:
        base = f"{self.slug}/{self.data}/{self.budget}"
        return base + (f"/seeds/train_seed_{self.train_seed}" if self.train_seed else "")


KEEP_LAST = "+keep_last"
#: the paper's four datasets and D4: D2's queries pruned, each path keeping its last step
KEEP_LAST_DATASETS = (
    "data.datasets=[{p_nt: 0.0}, {p_nt: 0.5}, {p_nt: 1.0}, "
    "{p_nt: 1.0, prune: true}, {name: D4, p_nt: 1.0, prune: keep_last}]"
)


def data_overrides(cell: Cell, cfg) -> list[str]:
    """The ``--set`` overrides of the cell's data paths (``cfg``: the map's task config)."""
    if cell.data.endswith(KEEP_LAST):
        base = Cell(cell.map, cell.data[: -len(KEEP_LAST)], cell.budget, cell.train_seed)
        return data_overrides(base, cfg) + [KEEP_LAST_DATASETS]
    if cell.data.endswith(FULL_EPOCHS):
        base = Cell(cell.map, cell.data[: -len(FULL_EPOCHS)], cell.budget, cell.train_seed)
        return data_overrides(base, cfg)
    if cell.data == "bitstar":
        return [
            f"planner.per_env=[{{env: {cell.map}, name: roadmap, data_paths: raw}}]",
            f"data.per_env=[{{env: {cell.map}, paths_from: {BITSTAR_RECORDS[cell.map]}}}]",
        ]
    if cell.data in ("shortcut", "raw"):
        return [f"planner.data_paths={cell.data}"] + _per_env_data_paths(cfg, cell.map, cell.data)
    spacing = DENSITY.get(cell.map, cfg.planner.data_paths_for(cell.map))
    if isinstance(spacing, bool) or not isinstance(spacing, (int, float)):
        raise UsageError(
            f"{cell.map}: no resampling spacing for the density cells (set "
            "planner.data_paths in its task config)"
        )
    return [f"planner.data_paths={spacing}"]


def _per_env_data_paths(cfg, map_name: str, mode) -> list[str]:
    """``planner.per_env`` with ``map_name``'s own ``data_paths`` (which would override the
    global key) set to ``mode``; ``[]`` when the task config gives that map none."""
    rows = [dict(e) for e in cfg.to_dict()["planner"]["per_env"]]
    if not any(r["env"] == map_name and r.get("data_paths") is not None for r in rows):
        return []
    for r in rows:
        if r["env"] == map_name:
            r["data_paths"] = mode
    items = ", ".join(
        "{" + ", ".join(f"{k}: {v}" for k, v in r.items() if v is not None) + "}" for r in rows
    )
    return [f"planner.per_env=[{items}]"]


#: Data modes of the point maps queued last: dense A* paths give 20-50x the shortcut
#: paths' samples, so at the config's 100 epochs one of these cells trains for hours
#: (point/0 density: epoch 21-42 of 100 after 1.5 h on one core); the data-path factor is
#: measured first where it is cheaper (rigid/0, with BIT*'s own paths; nlink/4; rigid/2)
COSTLY = ("density", "raw")
#: Training epochs of the point maps' :data:`COSTLY` cells. An epoch of their data is
#: 19x (density, 45 samples per path) and 50x (raw, 119) the shortcut paths' (2.4 samples
#: per path; results/data_paths/density_point_0.json), so 10 epochs give every PNet 1.9x
#: and 5x the optimizer steps of the shortcut cells' 100 epochs at the same batch size:
#: the comparison within a cell (PNet_k vs PNet_0, one protocol) is unchanged, and each
#: cell's ``history.csv`` records its PNets' validation loss per epoch (flattened or not).
COSTLY_EPOCHS = 10
#: Data-mode suffix of the check on that choice: the point maps' density cells at the
#: config's 100 epochs (the same data), so that the two trainings' PNet_3 - PNet_0 can be
#: compared.
FULL_EPOCHS = "+full_epochs"


def cells(seeds: bool = True) -> list[Cell]:
    """Every cell, in the order ``--next`` runs them: per factor map, each data mode with
    the config's budgets, then MPNet's budgets on the default data, then the default's
    training seeds 1 and 2 (one factor varied at a time around the task's default); then
    the default cell of each of the paper's other maps (:data:`PAPER_ONLY`) and, with
    ``seeds``, their training seeds 1 and 2; then the pruning beyond the paper (``+keep_last``)
    on the factor maps; then the point maps'
    :data:`COSTLY` data modes; then their density cells at the config's epochs
    (:data:`FULL_EPOCHS`); last, with ``seeds``, training seeds 3 and 4 of
    :data:`MORE_SEEDS`."""
    out, costly = [], []
    for m in MAPS:
        modes = ("density", "shortcut", "raw") + (("bitstar",) if m in BITSTAR_RECORDS else ())
        for data in modes:
            last = task_of(m) == "point" and data in COSTLY
            (costly if last else out).append(Cell(m, data, "ours"))
        out.append(Cell(m, default_data(m), "mpnet"))
        if task_of(m) == "rigid":  # Table III: the rigid body without steerTo
            out += [
                Cell(m, default_data(m), v)
                for v in (
                    "nosteer_l2",
                    "nosteer_unchecked",
                    "nosteer_paper",
                    "nosteer_discretized",
                    "nosteer_states",
                    "nosteer_replan",
                )
            ]
        if seeds:
            out += [Cell(m, default_data(m), "ours", k) for k in (1, 2)]
    out += [Cell(m, default_data(m), "ours") for m in PAPER_ONLY]
    out += [Cell(m, default_data(m) + KEEP_LAST, "ours") for m in MAPS]
    if seeds:  # after every cell already committed, so --next runs them next
        out += [Cell(m, default_data(m), "ours", k) for k in (1, 2) for m in PAPER_ONLY]
    out += costly + [Cell(m, "density" + FULL_EPOCHS, "ours") for m in DENSITY]
    if seeds:  # BIT*'s own data on an arm, like its default cell: three training seeds
        out += [Cell("nlink/4", "bitstar", "ours", k) for k in (1, 2)]
    if seeds:  # five seeds where three left the verdict open, after everything else
        out += [Cell(m, default_data(m), "ours", k) for k in EXTRA_SEEDS for m in MORE_SEEDS]
    return out


def record_rows(record: Path, pool: str) -> int:
    """Queries of ``pool`` the record's chunk files cover, from row 0 without a gap."""
    import re

    spans = sorted(
        (int(m.group(1)), int(m.group(2)))
        for f in (record / pool).glob("*.npz")
        if (m := re.fullmatch(r"plan_(\d+)_(\d+)\.npz", f.name))
    )
    end = 0
    for lo, hi in spans:
        if lo > end:
            break
        end = max(end, hi)
    return end


def ready(cell: Cell) -> str | None:
    """Why the cell cannot run yet, or None."""
    if cell.data.startswith("density") and task_of(cell.map) == "point" and cell.map not in DENSITY:
        return "no BIT*-like spacing measured for the point robot yet (DENSITY)"
    if cell.data == "bitstar":
        rec = Path(BITSTAR_RECORDS[cell.map])
        try:
            pools = json.loads((rec / "record.json").read_text())["pools"]
        except (OSError, ValueError, KeyError):
            return f"no BIT* record in {rec}"
        have = {p: record_rows(rec, p) for p in ("U", "N")}
        if any(have[p] < pools[p] for p in ("U", "N")):
            return (
                f"the BIT* record covers U {have['U']}/{pools['U']}, N {have['N']}/"
                f"{pools['N']} (resume: python scripts/record_paths.py --config "
                f"configs/{task_of(cell.map)}.yaml --env {cell.map} --planner bitstar "
                f"--pools N,U --workers 1 --out {rec})"
            )
    return None


def claim(cell: Cell, runs: Path) -> bool:
    """Claims ``cell`` for this process (False: another ``--next`` worker runs it), so that
    one worker per core can run ``--next`` side by side."""
    from ntq_jax import artifacts

    folder = runs / ".claims" / cell.key.replace("/", "__")
    folder.mkdir(parents=True, exist_ok=True)
    try:
        artifacts.lock_folder(folder)
    except artifacts.FolderInUse:
        return False
    return True


def next_cell(all_cells: list[Cell], results: Path, runs: Path) -> list[Cell]:
    """The first pending, ready cell whose base cell is done, claimed for this process
    (``[]`` if none is free). Only that one cell is claimed: a claim is held until the
    process exits, so claiming more would starve the other workers."""
    done = lambda c: is_done(results / c.key)  # noqa: E731
    base_done = lambda c: (
        c.budget == "ours"
        and not c.train_seed
        or done(  # noqa: E731
            Cell(c.map, c.data, "ours")
        )
    )
    todo = [c for c in all_cells if not done(c) and ready(c) is None and base_done(c)]
    todo.sort(key=lambda c: damaged(results / c.key) is None)  # a damaged cell is redone first
    return next(([c] for c in todo if claim(c, runs)), [])


def cell_config(cell: Cell, extra: list[str] = ()):
    """The cell's resolved config and its ``--set`` overrides (``extra`` last)."""
    from ntq_jax.experiment.pipeline import load_config

    task = task_of(cell.map)
    path = f"configs/{task}.yaml"
    base = load_config(path, [f"envs=[{cell.map}]", *extra])
    sets = [f"envs=[{cell.map}]", *data_overrides(cell, base)]
    sets += EVAL_VARIANTS[cell.budget]
    if (
        task == "point"
        and cell.data.split("+")[0] in COSTLY
        and not cell.data.endswith(FULL_EPOCHS)
    ):
        sets.append(f"train.epochs={COSTLY_EPOCHS}")
    if cell.train_seed:
        sets.append(f"train.seed={cell.train_seed}")
    sets += list(extra)
    return load_config(path, sets), sets


def run_folder(cell: Cell, runs: Path, paper_runs: Path | None) -> Path:
    """The cell's run folder. The density cells with the config's budgets are the task's
    default runs: with ``paper_runs`` they live where ``scripts/reproduce.py`` keeps its
    runs (``<paper_runs>/<task>/<map>[-train_seed_<k>]``), so that either script resumes
    the other's run (their configs are the same)."""
    if paper_runs is None or cell.data != default_data(cell.map) or cell.budget != "ours":
        return runs / cell.key
    name = cell.slug + (f"-train_seed_{cell.train_seed}" if cell.train_seed else "")
    return paper_runs / task_of(cell.map) / name


def run_cell(
    cell: Cell,
    runs: Path,
    results: Path,
    progress: bool,
    extra: list[str] = (),
    paper_runs: Path | None = None,
    paper_results: Path | None = None,
) -> None:
    from ntq_jax import make_env
    from ntq_jax.experiment.pipeline import prepare_run, run_pipeline
    from ntq_jax.experiment.summaries import read_summary, write_summary

    cfg, sets = cell_config(cell, extra)
    out = results / cell.key
    old = read_summary(out)
    if old is not None and old.get("config_hash") == cfg.hash() and is_done(out):
        print(f"[{cell.key}] up to date", flush=True)
        return
    why = ready(cell)
    if why:
        raise UsageError(f"{cell.key}: {why}")
    env = make_env(cell.map)
    run = prepare_run(cfg, run_folder(cell, runs, paper_runs))
    from ntq_jax import artifacts

    if cell.budget != "ours" or cell.train_seed:  # the same data (and models for a budget)
        base = run_folder(Cell(cell.map, cell.data, "ours"), runs, paper_runs)
        if (base / "results.json").is_file():
            artifacts.link_tree(base / "data" / cell.slug, run / "data" / cell.slug)
            if not cell.train_seed:
                artifacts.link_tree(base / "models" / cell.slug, run / "models" / cell.slug)
                artifacts.link_tree(base / "eval" / cell.slug, run / "eval" / cell.slug)
        else:  # a fresh machine: the base cell's run folder is gone; its data (and, for a
            # budget cell, its models) are made again from the same config and seeds
            print(
                f"[{cell.key}] no run of {Cell(cell.map, cell.data, 'ours').key} here: "
                "its data (and models) are made again",
                flush=True,
            )
    t0 = time.perf_counter()
    print(f"[{cell.key}] run folder {run}", flush=True)
    run_pipeline(cfg, run, progress=progress, figures=False)
    cmd = f"python scripts/factor_study.py --cell {cell.key}"
    write_summary(run, cell.map, env, out, command=cmd)
    if paper_results is not None and run == run_folder(cell, runs, paper_runs) != runs / cell.key:
        # a default cell is also the task's reproduction of this map (Tables I-IV)
        task = task_of(cell.map)
        dest = paper_results / task / cell.slug
        rcmd = f"python scripts/reproduce.py --config configs/{task}.yaml --env {cell.map}"
        if cell.train_seed:
            dest, rcmd = (
                dest / "seeds" / f"train_seed_{cell.train_seed}",
                rcmd + f" --train-seeds {cell.train_seed}",
            )
        write_summary(run, cell.map, env, dest, command=rcmd)
        check_cells(results)  # REPRODUCTION.md reads the factor cells too
        from ntq_jax.experiment import reproduction

        print(f"report: {reproduction.write(paper_results)}", flush=True)
    from ntq_jax import artifacts

    history = run / "models" / cell.slug / "history.csv"
    if cell.budget == "ours" and history.is_file():  # the loss per epoch of the cell's PNets
        artifacts.write_text(out / "history.csv", history.read_text())
    artifacts.write_json(
        out / "paired.json",
        {"cell": cell._asdict(), "sets": sets, "paired": paired(run, cell, env)},
    )
    print(f"[{cell.key}] done in {time.perf_counter() - t0:.0f} s", flush=True)


def report(results: Path) -> Path:
    """``<results>/README.md``: PNet_k - PNet_0 per cell (every finished one)."""
    check_cells(results)
    lines = [
        "# Factor study: what decides PNet_3 vs PNet_0",
        "",
        "Generated by `python scripts/factor_study.py --report-only` from the cells below",
        "(`python scripts/factor_study.py --list`). Success difference PNet_k - PNet_0 (or the",
        "baseline named in the model column) on the",
        "same test queries (K_test per kind: the task config's), with its 95 % Newcombe interval,",
        "McNemar's exact p (this training only) and its Benjamini-Hochberg q over every p-value",
        "of the study (the false-discovery rate; read q, not p, when scanning many rows);",
        "`in`/`out`: test queries with both endpoints valid at the data padding (in band) or not.",
        "",
        "The rigid/0 `density` cells made before a trivial query's data path kept its two",
        "ends (as BIT* returns it) are in `results/ablations/density_trivial_resampled/`.",
        "",
        f"The point maps' `density` and `raw` cells train {COSTLY_EPOCHS} epochs, not the config's",
        "100: their data have 19x and 50x the shortcut paths' samples per path, so that is",
        "1.9x and 5x the optimizer steps of the `shortcut` cells (`COSTLY_EPOCHS` in the",
        "script); each such cell's `history.csv` has its PNets' losses per epoch, and",
        "the `density+full_epochs` cells train the same data for the 100 epochs.",
        "",
        "| map | data paths | budgets | seed | kind | steerTo | model | all | in band | out of band |",
        "|---|---|---|---:|---|---|---|---|---|---|",
    ]
    from ntq_jax.experiment import factor_table

    cells = factor_table.load_cells(results)  # each comparison with its BH q
    for p in cells:
        c = p["cell"]
        by = {}
        for r in p["paired"]:
            label = r["model"] + (
                "" if r.get("baseline", "PNet_0") == "PNet_0" else f" vs {r['baseline']}"
            )
            by.setdefault((r["query_kind"], r["steer"], label), {})[r["band"]] = r
        for (kind, steer, model), parts in sorted(by.items(), key=str):
            cellf = []
            for band in ("all", "in_band", "out_band"):
                r = parts.get(band)
                cellf.append(
                    "-"
                    if not r or "success_diff" not in r
                    else f"{factor_table.diff_text(r)} (n={r['n']})"
                )
            lines.append(
                f"| {c['map']} | {c['data']} | {c['budget']} | {c['train_seed']} | "
                f"{kind} | {'yes' if steer else 'no'} | {model} | " + " | ".join(cellf) + " |"
            )
    from ntq_jax import artifacts

    lines += [""] + factor_table.decomposition(cells)
    path = results / "README.md"
    artifacts.write_text(path, "\n".join(lines).rstrip("\n") + "\n")
    return path


def main(argv=None) -> int:
    return run_cli(lambda: _main(argv))


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--list", action="store_true", help="list the cells and their state")
    ap.add_argument("--next", action="store_true", help="run the first pending, ready cell")
    ap.add_argument("--cell", action="append", default=[], help="run this cell (repeatable)")
    ap.add_argument("--report-only", action="store_true", help="only regenerate README.md")
    ap.add_argument("--runs", default="runs/factors")
    ap.add_argument("--results", default="results/factors")
    ap.add_argument(
        "--paper-runs",
        default="runs/paper",
        help="scripts/reproduce.py's run folders, shared by the default cells "
        "('none': keep them under --runs)",
    )
    ap.add_argument(
        "--paper-results",
        default="results/paper",
        help="where a default cell also writes its map's reproduction summary "
        "and REPRODUCTION.md (as scripts/reproduce.py would)",
    )
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override for every cell (smaller sizes for a trial run)",
    )
    args = ap.parse_args(argv)
    runs, results = Path(args.runs), Path(args.results)
    all_cells = {c.key: c for c in cells()}
    if args.report_only:
        print(f"report: {report(results)}")
        return 0
    if args.list or not (args.next or args.cell):
        from ntq_jax.artifacts import lock_holder

        for c in all_cells.values():
            done, why = is_done(results / c.key), damaged(results / c.key)
            held = None if done else lock_holder(runs / ".claims" / c.key.replace("/", "__"))
            note = (
                f"{why}; --next redoes it"
                if why
                else f"claimed by {held}"
                if held
                else None
                if done
                else ready(c)
            )
            print(
                f"{'done   ' if done else 'running' if held else 'pending'} {c.key}"
                + (f"  ({note})" if note else "")
            )
        return 0
    todo = [all_cells[k] for k in args.cell if k in all_cells]
    unknown = [k for k in args.cell if k not in all_cells]
    if unknown:
        raise UsageError(f"--cell {unknown[0]}: not a cell (see --list)")
    if args.next:
        todo = next_cell(list(all_cells.values()), results, runs)
        if not todo:
            print("nothing to run")
            return 0
    for c in todo:
        if not claim(c, runs):
            raise UsageError(f"--cell {c.key}: another factor_study.py process is running it")
        paper = args.paper_runs != "none"
        run_cell(
            c,
            runs,
            results,
            not args.no_progress,
            args.set,
            Path(args.paper_runs) if paper else None,
            Path(args.paper_results) if paper else None,
        )
        print(f"report: {report(results)}", flush=True)
        if paper and (Path(args.paper_results) / "REPRODUCTION.md").is_file():
            from ntq_jax.experiment import reproduction  # its factor section reads results

            print(f"report: {reproduction.write(Path(args.paper_results))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
