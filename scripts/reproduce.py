#!/usr/bin/env python
"""The paper's Tables I-IV at the paper's sizes, one map at a time, with committed summaries.

Examples::

    python scripts/reproduce.py --config configs/point.yaml            # the 4 point maps
    python scripts/reproduce.py --config configs/rigid.yaml --env rigid/0
    python scripts/reproduce.py --config configs/nlink.yaml --env nlink/4 --train-seeds 1,2
    python scripts/reproduce.py --report-only                           # REPRODUCTION.md only
    python scripts/reproduce.py --report-only --check   # exit 1 if REPRODUCTION.md is stale

Every map of the config (or each ``--env``) is its own resumable unit: the
whole pipeline (data, the four PNets, evaluation on K_test uniform + K_test
non-trivial queries, report) runs for that map alone in
``<runs>/<task>/<map>/`` (rerun the same command after an interruption to
resume it), then its compact summary (:mod:`ntq_jax.experiment.summaries`: results,
tables, figures, the exact config, package version, dataset and model
fingerprints, time per stage; no large arrays) is written to
``<results>/<task>/<map>/`` and ``<results>/REPRODUCTION.md`` is regenerated
from every summary there (:mod:`ntq_jax.experiment.reproduction`). A map whose summary
was made from the same config is skipped, so an interrupted reproduction keeps
every finished map; commit each summary as it lands.

A map that is a MotionBenchMaker problem (``panda/<scene>/<n>``, ``configs/panda.yaml``)
also gets ``problems.json`` beside its summary: the scene's 100 problems planned by its
PNets and by OMPL's RRT-Connect (:mod:`ntq_jax.experiment.problems`); it needs the map's
run folder (its PNets). For a root of Panda runs the page is "Beyond the paper: a 7-DoF
arm" (:mod:`ntq_jax.experiment.panda_page`) instead of the paper's tables.

``--train-seeds 1,2`` also trains the map's PNets again with those training
seeds on the same data (the datasets are hard-linked from the map's run) and
writes their summaries to ``<results>/<task>/<map>/seeds/train_seed_<k>/``, for
the spread over training seeds. Expected errors are one ``error:`` line, exit
code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ntq_jax.experiment.cli import (
    UsageError,
    add_run_options,
    check_writable_folder,
    run_cli,
    start_run,
)


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise UsageError(f"--train-seeds must be comma-separated integers, got {text!r}")
    if any(s < 0 for s in seeds):
        raise UsageError(f"--train-seeds must be >= 0, got {text!r}")
    return seeds


def _one(
    cfg, name: str, env, run: Path, out: Path, *, args, command: str, data_from: Path | None = None
) -> None:
    """Runs the pipeline for one map (unless its summary is current) and writes its summary."""
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment.pipeline import prepare_run, run_pipeline
    from ntq_jax.experiment.summaries import read_summary, write_summary

    old = read_summary(out)
    if old is not None and old.get("config_hash") == cfg.hash():
        print(f"[{name}] summary up to date: {out / 'summary.json'}", flush=True)
        _problems(cfg, name, env, run, out)
        return
    from ntq_jax.experiment.cli import executor_of

    executor = executor_of(args, cfg)  # an unreachable Ray cluster: refused before any write
    run = prepare_run(cfg, run)
    if data_from is not None:  # the same data: hard links to the map's datasets
        from ntq_jax import artifacts

        slug = env_slug(name, env)
        artifacts.link_tree(data_from / "data" / slug, run / "data" / slug)
    print(f"[{name}] run folder: {run}", flush=True)
    t0 = time.perf_counter()
    run_pipeline(
        cfg, run, progress=not args.no_progress, figures=not args.no_figures, executor=executor
    )
    path = write_summary(run, name, env, out, command=command)
    print(f"[{name}] done in {time.perf_counter() - t0:.0f} s; summary: {path}", flush=True)
    _problems(cfg, name, env, run, out)


def _problems(cfg, name: str, env, run: Path, out: Path) -> None:
    """A MotionBenchMaker problem's map: its scene's 100 problems as a third query kind
    (:mod:`ntq_jax.experiment.problems`), ``<out>/problems.json``. Needs the map's run
    folder (its PNets); without it (a fresh machine, the summary committed) it is skipped
    with a note, unless ``problems.json`` is there already."""
    from ntq_jax import artifacts
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment import problems
    from ntq_jax.experiment.summaries import models_fingerprint

    if problems.scene_of(name) is None:
        return
    slug = env_slug(name, env)
    model_dir = run / "models" / slug
    target = out / "problems.json"
    fp = models_fingerprint(model_dir)
    if target.is_file():
        if fp is None or json.loads(target.read_text()).get("models_fingerprint") == fp:
            print(f"[{name}] problems up to date: {target}", flush=True)
            return
    if fp is None:
        print(f"[{name}] problems: no PNets in {model_dir}; skipped", flush=True)
        return
    from ntq_jax.experiment.evaluate import model_name
    from ntq_jax.models import member_pnets
    from ntq_jax.training import load_ensemble

    ens = load_ensemble(model_dir)
    t0 = time.perf_counter()
    got = problems.evaluate_problems(
        name, member_pnets(ens), cfg, run / "eval" / slug, model_fingerprint=fp
    )
    names = [model_name(m) for m in range(ens.num_members)]
    summary = problems.summarize(got, names, cfg.planner.eval_time_budget)
    summary.update(models_fingerprint=fp, seconds=round(time.perf_counter() - t0, 1))
    artifacts.write_json(target, summary)
    print(f"[{name}] problems: {target}", flush=True)


def _report(results: Path) -> None:
    from ntq_jax.experiment import reproduction

    print(f"report: {reproduction.write(results)}", flush=True)


def _check(results: Path) -> int:
    from ntq_jax.experiment import reproduction

    problem = reproduction.check(results)
    print(problem or f"{results / reproduction.DOC_NAME} is up to date", flush=True)
    return 1 if problem else 0


def _report_only(args, results: Path) -> int:
    """``--report-only [--check]``: REPRODUCTION.md from the summaries under ``results``."""
    if args.env or args.train_seeds or args.config:
        raise UsageError(
            "--report-only regenerates REPRODUCTION.md from every summary in "
            "--results; it takes no --config, --env or --train-seeds"
        )
    if args.check:
        return _check(results)
    check_writable_folder(results, "--results")
    _report(results)
    return 0


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--env",
        action="append",
        default=None,
        help="a map of the config (repeatable; default: every map)",
    )
    ap.add_argument(
        "--train-seeds",
        default="",
        metavar="K,K",
        help="extra training seeds per map, same data (e.g. 1,2)",
    )
    ap.add_argument("--runs", default="runs/paper", help="run folders (default runs/paper)")
    ap.add_argument(
        "--results",
        default="results/paper",
        help="summary folders and REPRODUCTION.md (default results/paper)",
    )
    ap.add_argument(
        "--report-only",
        action="store_true",
        help="only regenerate REPRODUCTION.md from the summaries",
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="with --report-only: write nothing, exit 1 if REPRODUCTION.md is stale",
    )
    add_run_options(
        ap,
        set_example="eval.k_test=100",
        figures_help="skip the PNG figures",
        cpu_devices_help="JAX CPU devices to create (one per core); default 1",
        executor=True,
    )
    args = ap.parse_args(argv)
    results = Path(args.results)
    if args.report_only:
        return _report_only(args, results)
    if args.check:
        raise UsageError("--check goes with --report-only")
    if args.config is None:
        raise UsageError(
            "--config is required (configs/point.yaml, configs/rigid.yaml, "
            "configs/nlink.yaml or configs/panda.yaml), unless --report-only"
        )
    seeds = _seeds(args.train_seeds)
    check_writable_folder(results, "--results")
    check_writable_folder(args.runs, "--runs")
    start_run(args)  # before any JAX operation
    from ntq_jax.envs import env_slug, resolve_envs
    from ntq_jax.experiment.pipeline import load_config

    base = load_config(args.config, args.set)
    names = args.env or list(base.envs)
    unknown = [n for n in names if n not in base.envs]
    if unknown:
        raise UsageError(
            f"--env {unknown[0]} is not a map of {args.config} ({', '.join(base.envs)})"
        )
    envs = resolve_envs(names)
    command = "python scripts/reproduce.py " + " ".join(sys.argv[1:] if argv is None else argv)
    for name in names:
        env, slug = envs[name], env_slug(name, envs[name])
        cfg = load_config(args.config, [*args.set, f"envs=[{name}]"])
        run = Path(args.runs) / cfg.task / slug
        out = results / cfg.task / slug
        _one(cfg, name, env, run, out, args=args, command=command)
        _report(results)
        for k in seeds:
            cfg_k = load_config(args.config, [*args.set, f"envs=[{name}]", f"train.seed={k}"])
            if cfg_k.train.seed_for(cfg_k.seed) == cfg.train.seed_for(cfg.seed):
                continue  # the map's own run
            _one(
                cfg_k,
                name,
                env,
                run.with_name(f"{slug}-train_seed_{k}"),
                out / "seeds" / f"train_seed_{k}",
                args=args,
                command=command,
                data_from=run,
            )
            _report(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
