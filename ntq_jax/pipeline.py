"""The whole pipeline for a config: datasets D0..D3 -> PNet ensemble -> evaluation -> report.

:func:`load_config` resolves a config (a YAML file or the embedded
:data:`DEFAULT`, plus ``--set`` overrides); :func:`prepare_run` creates or
reopens the run folder; :func:`run_pipeline` runs every stage for every
environment and writes the report. ``scripts/train_all.py`` is the command line
over these three.

A run folder holds::

    config.yaml, run.json          the resolved config and the stage log
    data/<env>/env.json, D0..D3/   datasets (ntq_jax.data)
    models/<env>/                  training output, ensemble/ (ntq_jax.training)
    eval/<env>/                    test queries, reference paths
    paths/<env>/<model>_<kind>[_nosteer].npz   every planned path
    results.json, results.csv, tables.md, tables.tex, figures/*.png

Every stage resumes: a rerun skips complete datasets, resumes training from its
last checkpoint, reuses every saved evaluation file and rewrites the report. A
run folder made with a different config is refused.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable

import yaml

from ntq_jax import artifacts, config as C
from ntq_jax import data as data_mod
from ntq_jax import training
from ntq_jax.data import env_slug
from ntq_jax.evaluate import evaluate_env
from ntq_jax.report import write_report
from ntq_jax.version import __version__

__all__ = ["DEFAULT", "PipelineError", "load_config", "prepare_run", "run_pipeline"]

#: The embedded default: the four point-robot maps at reduced sizes (a few minutes on a CPU).
DEFAULT = {
    "task": "point",
    "envs": ["point/0", "point/1", "point/2", "point/3"],
    "seed": 0,
    "data": {"k_train": 600, "gamma_queries": 200_000},
    "planner": {"name": "astar", "resolution": 0.1},
    "model": {"hidden": [256, 256, 128, 64]},
    "train": {"epochs": 40, "batch_size": 100},
    "eval": {"k_test": 200, "n_plan": 50, "steer": [True]},
}


class PipelineError(RuntimeError):
    """A run cannot proceed (e.g. a run folder made with another config)."""


def load_config(path: str | Path | None, overrides: list[str]) -> C.Config:
    """The resolved config: the YAML file (or the embedded :data:`DEFAULT`) plus overrides."""
    if path is None:
        where = "embedded default" + (f" (with overrides {', '.join(overrides)})"
                                      if overrides else "")
        return C.from_dict(C.apply_overrides(DEFAULT, overrides), where)
    return C.load(path, overrides)


def prepare_run(cfg: C.Config, out: str | Path | None) -> Path:
    """Creates (or reopens) the run folder; refuses a folder made with another config.

    ``out`` defaults to ``<cfg.out_dir>/<task>-<config hash>``.
    """
    run = Path(out) if out else Path(cfg.out_dir) / f"{cfg.task}-{cfg.hash()[:8]}"
    run.mkdir(parents=True, exist_ok=True)
    info_f = run / "run.json"
    info = {}
    if info_f.is_file():
        try:
            info = json.loads(info_f.read_text())
        except json.JSONDecodeError:
            info = {}
        if info.get("config_hash") not in (None, cfg.hash()):
            raise PipelineError(
                f"{run} holds a run with another config (hash {info.get('config_hash')}, this one "
                f"{cfg.hash()}); pass a new --out, or delete the folder to start over")
    info.update({"config_hash": cfg.hash(), "stages": info.get("stages", {})})
    artifacts.write_json(info_f, info)
    artifacts.write_text(run / "config.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    return run


def _mark(run: Path, stage: str, **fields) -> None:
    """Records a finished stage in ``run.json``."""
    f = run / "run.json"
    info = json.loads(f.read_text())
    info["stages"][stage] = {"done": True, "time": time.strftime("%Y-%m-%dT%H:%M:%S"), **fields}
    artifacts.write_json(f, info)


def _run_env(cfg: C.Config, run: Path, name: str, env, *, progress, figures: bool,
             log: Callable[[str], None]) -> tuple[list[dict], dict]:
    """Data -> training -> evaluation for one environment; returns its rows and timings."""
    slug = env_slug(name, env)
    # -- data ----------------------------------------------------------------
    t0 = time.perf_counter()
    log(f"[{name}] data: {cfg.data.k_train_for(name)} queries x {len(cfg.data.datasets)} "
        f"datasets ({cfg.planner.name})")
    summary = data_mod.generate_datasets(env, cfg, run / "data", env_name=name,
                                         progress=progress, figure=figures)
    data_dir = Path(summary["env_dir"])
    t1 = time.perf_counter()
    _mark(run, f"data/{slug}", seconds=round(t1 - t0, 1), skipped=bool(summary.get("skipped")))
    # -- training --------------------------------------------------------------
    model_dir = run / "models" / slug
    if (model_dir / "ensemble" / "ensemble.json").is_file():
        log(f"[{name}] train: complete, loading {model_dir / 'ensemble'}")
    else:
        log(f"[{name}] train: {len(cfg.data.datasets)} PNets, {cfg.train.epochs} epochs")
        training.train_from_folder(data_dir, cfg, model_dir, progress=progress)
    ens = training.load_ensemble(model_dir)
    t2 = time.perf_counter()
    _mark(run, f"train/{slug}", seconds=round(t2 - t1, 1))
    # -- evaluation ------------------------------------------------------------
    log(f"[{name}] evaluate: K_test = {cfg.eval.k_test} uniform + {cfg.eval.k_test} "
        f"non-trivial queries, {ens.num_members} models, steerTo {list(cfg.eval.steer)}")
    rows = evaluate_env(env, ens, cfg, run, env_name=name, data_env_dir=data_dir, log=log)
    t3 = time.perf_counter()
    _mark(run, f"eval/{slug}", seconds=round(t3 - t2, 1))
    return rows, {"data": t1 - t0, "train": t2 - t1, "eval": t3 - t2}


def run_pipeline(cfg: C.Config, run: Path, *, progress=True, figures: bool = True,
                 log: Callable[[str], None] = print) -> dict:
    """Runs every stage for every environment of ``cfg``; returns the report's file paths.

    Args:
        cfg: the resolved config.
        run: the run folder (from :func:`prepare_run`).
        progress: progress bars (see :mod:`ntq_jax.progress`).
        figures: write the PNG figures.
        log: one-line progress messages.
    """
    rows, timings = [], {}
    envs = data_mod.resolve_envs(cfg.envs)  # every env built, no two sharing a folder
    for name in cfg.envs:
        env_rows, timings[name] = _run_env(cfg, run, name, envs[name], progress=progress,
                                           figures=figures, log=log)
        rows += env_rows
    meta = {"config": cfg.to_dict(), "config_hash": cfg.hash(), "timings": timings,
            "package_version": __version__}
    out = write_report(run, rows, envs, meta=meta, figures=figures)
    _mark(run, "report")
    return out
