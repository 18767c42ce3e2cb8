#!/usr/bin/env python
"""The whole pipeline: generate D0..D3 -> train the PNet ensemble -> evaluate -> report.

Examples::

    python scripts/train_all.py                                 # embedded default (4 point maps)
    python scripts/train_all.py --config configs/rigid_small.yaml
    python scripts/train_all.py --config configs/point.yaml --out runs/point_paper
    python scripts/train_all.py --set eval.k_test=100 --set envs=[point/0]

Without ``--config`` the embedded default runs: the four point-robot maps at
reduced sizes (K_train 600, a 256-256-128-64 PNet, 40 epochs, K_test 200;
about 2-3 minutes on an idle 2-core CPU). ``--set KEY=VALUE`` overrides any config
key (YAML values).

The run folder (``--out``, default ``<out_dir>/<task>-<config hash>``) holds::

    config.yaml, run.json          the resolved config and the stage log
    data/<env>/env.json, D0..D3/   datasets (ntq_jax.data)
    models/<env>/                  training output, ensemble/ (ntq_jax.train)
    eval/<env>/                    test queries, reference paths
    paths/<env>/<model>_<kind>[_nosteer].npz   every planned path
    results.json, results.csv, tables.md, tables.tex, figures/*.png

Every stage resumes: rerunning the same command after an interruption skips
complete datasets, resumes training from its last checkpoint, reuses every
saved evaluation file and rewrites the report. A run folder made with a
different config is refused (use another ``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


from ntq_jax import artifacts


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
    """A stage cannot run (missing module, foreign run folder, ...)."""


def load_config(path, overrides):
    """The resolved config: the YAML file (or the embedded default) plus overrides."""
    from ntq_jax import config as C
    if path is None:
        data = C.apply_overrides(DEFAULT, overrides)
        return C.from_dict(data, "embedded default" + (f" (with overrides {', '.join(overrides)})"
                                                       if overrides else ""))
    return C.load(path, overrides)


def prepare_run(cfg, out) -> Path:
    """Creates (or reopens) the run folder; refuses a folder made with another config."""
    import yaml
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
    artifacts.write_text(info_f, json.dumps(info, indent=1))
    artifacts.write_text(run / "config.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    return run


def _mark(run: Path, stage: str, **fields):
    f = run / "run.json"
    info = json.loads(f.read_text())
    info["stages"][stage] = {"done": True, "time": time.strftime("%Y-%m-%dT%H:%M:%S"), **fields}
    artifacts.write_text(f, json.dumps(info, indent=1))


def run_pipeline(cfg, run: Path, *, progress: bool = True, figures: bool = True,
                 log=print) -> dict:
    """Runs every stage for every environment; returns the report's file paths."""
    from ntq_jax import make_env
    from ntq_jax.data import env_slug
    from ntq_jax.evaluate import evaluate_env
    from ntq_jax.report import write_report
    try:
        from ntq_jax import data as data_mod
        from ntq_jax import train as train_mod
    except ImportError as e:  # pragma: no cover - the modules exist in a full checkout
        raise PipelineError(f"a pipeline module is missing: {e}") from None

    rows, envs, timings = [], {}, {}
    for name in cfg.envs:
        slug = env_slug(name)
        env = make_env(name)
        envs[name] = env
        t0 = time.perf_counter()
        log(f"[{name}] data: {cfg.data.k_train_for(name) if hasattr(cfg.data, 'k_train_for') else cfg.data.k_train} "
            f"queries x {len(cfg.data.datasets)} datasets ({cfg.planner.name})")
        summary = data_mod.generate_datasets(env, cfg, run / "data", env_name=name,
                                             progress=progress, figure=figures)
        data_dir = Path(summary["env_dir"])
        t1 = time.perf_counter()
        _mark(run, f"data/{slug}", seconds=round(t1 - t0, 1), skipped=bool(summary.get("skipped")))

        model_dir = run / "models" / slug
        if (model_dir / "ensemble" / "ensemble.json").is_file():
            log(f"[{name}] train: complete, loading {model_dir / 'ensemble'}")
        else:
            log(f"[{name}] train: {len(cfg.data.datasets)} PNets, {cfg.train.epochs} epochs")
            train_mod.train_from_folder(data_dir, cfg, model_dir, progress=progress)
        ens = train_mod.load_ensemble(model_dir)
        t2 = time.perf_counter()
        _mark(run, f"train/{slug}", seconds=round(t2 - t1, 1))

        log(f"[{name}] evaluate: K_test = {cfg.eval.k_test} uniform + {cfg.eval.k_test} "
            f"non-trivial queries, {ens.num_members} models, steerTo {list(cfg.eval.steer)}")
        rows += evaluate_env(env, ens, cfg, run, env_name=name, data_env_dir=data_dir, log=log)
        t3 = time.perf_counter()
        _mark(run, f"eval/{slug}", seconds=round(t3 - t2, 1))
        timings[name] = {"data": t1 - t0, "train": t2 - t1, "eval": t3 - t2}

    meta = {"config": cfg.to_dict(), "config_hash": cfg.hash(), "timings": timings,
            "package_version": _version()}
    out = write_report(run, rows, envs, meta=meta, figures=figures)
    _mark(run, "report")
    return out


def _version() -> str:
    try:
        import ntq_jax
        return ntq_jax.__version__
    except Exception:  # noqa: BLE001
        return "unknown"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=None, help="YAML config (default: the embedded default)")
    ap.add_argument("--out", default=None,
                    help="run folder (default: <out_dir>/<task>-<config hash>; rerun to resume)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="config override, e.g. --set eval.k_test=100 (repeatable)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    ap.add_argument("--no-compile-cache", action="store_true",
                    help="do not use JAX's persistent compilation cache")
    ap.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    ap.add_argument("--cpu-devices", type=int, default=1,
                    help="JAX CPU devices to create (one per core, e.g. 2 on 2 cores): the "
                         "four PNets then train on separate cores; measured 1.17x faster at "
                         "small widths, no gain at the paper's (BENCHMARKS.md); results differ "
                         "from a one-device run at float level. Default 1")
    args = ap.parse_args(argv)
    from ntq_jax.train import use_cpu_devices
    use_cpu_devices(args.cpu_devices)  # before any JAX operation
    if not args.no_compile_cache:
        artifacts.enable_compile_cache()

    from ntq_jax.config import ConfigError
    try:
        cfg = load_config(args.config, args.set)
        run = prepare_run(cfg, args.out)
    except (ConfigError, PipelineError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"run folder: {run}", flush=True)
    t0 = time.perf_counter()
    try:
        out = run_pipeline(cfg, run, progress=not args.no_progress, figures=not args.no_figures)
    except PipelineError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print()
    print((run / "tables.md").read_text())
    print(f"done in {time.perf_counter() - t0:.0f} s; run folder: {run}")
    for k, v in out.items():
        print(f"  {k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
