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
    results.json, results.csv, tables.md, tables.tex, timings.csv, figures/*.png

Every stage resumes: a rerun verifies the datasets against their checksums
(rewriting only a damaged one), resumes training from its last checkpoint,
reuses every saved evaluation file and rewrites the report. A folder is adopted
as a run only when its ``run.json`` is present, valid and made with the same
config; any other non-empty folder is refused (:class:`PipelineError`) unless
``overwrite=True`` (``train_all.py --overwrite``) deletes it first, which is
done only for a folder holding nothing but a run's files. Nothing is written
before the config and every environment are validated.
"""

from __future__ import annotations

import importlib.resources
import json
import os
import re
import shutil
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Callable

import yaml

from ntq_jax import artifacts, training
from ntq_jax import data as data_mod
from ntq_jax.data.format import ARRAY_SPECS, recorded_checksums
from ntq_jax.data.limits import check_roadmap, check_spacing
from ntq_jax.envs import EnvError, env_slug, resolve_envs
from ntq_jax.experiment import config as C
from ntq_jax.experiment.evaluate import evaluate_env
from ntq_jax.experiment.references import reference_plans, reuse_roadmaps, test_queries
from ntq_jax.experiment.report import write_report
from ntq_jax.planners.jobs import planner_options
from ntq_jax.planners.options import unsupported_robot
from ntq_jax.version import __version__

__all__ = ["DEFAULT", "PipelineError", "load_config", "prepare_run", "run_pipeline"]

#: The embedded default (``default.yaml``, shipped with the package): the four point-robot
#: maps and one rigid-body map at reduced sizes (a few minutes on a CPU). The rigid body's
#: data and reference come from the roadmap planner; its table shows PNet_3 against PNet_0
#: on non-trivial queries, where the paper's gains are clearest, with the paired p-value.
DEFAULT = yaml.safe_load(
    (importlib.resources.files("ntq_jax.experiment") / "default.yaml").read_text("utf-8")
)


#: What a run folder may hold (``--overwrite`` deletes only folders made of these).
RUN_ENTRIES = frozenset(
    {
        ".lock",
        "config.yaml",
        "run.json",
        "data",
        "models",
        "eval",
        "paths",
        "results.json",
        "results.csv",
        "tables.md",
        "tables.tex",
        "timings.csv",
        "figures",
    }
)
#: Every file a run writes, as a pattern of its path in the run folder (``<env>``: one
#: folder name): what ``--overwrite`` may delete. Anything else stops it.
RUN_FILES = re.compile(
    "|".join(
        f"(?:{p})"
        for p in (
            r"(config\.yaml|run\.json|results\.json|results\.csv|tables\.md|tables\.tex|timings\.csv|\.lock)",
            r"figures/[^/]+\.png",
            r"data/[^/]+/(env\.json|config\.yaml|figure\.png)",
            rf"data/[^/]+/D\d+/(({'|'.join(ARRAY_SPECS)})\.npy|meta\.json)",
            r"(data|eval)/[^/]+/roadmap/roadmap_[0-9a-f]+\.npz",
            r"data/[^/]+/\.work/.+",
            r"eval/[^/]+/[a-z_]+\.(npz|json)",
            r"models/[^/]+/(config\.json|curves\.png|history\.csv|history\.jsonl)",
            r"models/[^/]+/(checkpoints|ensemble)/.+",
            r"paths/[^/]+/[A-Za-z0-9_.+-]+\.npz",
            r"(.+/)?\.[^/]+\.tmp-[^/]+(/.+)?",  # an interrupted atomic write (file or folder)
        )
    )
)
_NEW_OUT = "pass a new --out"


class PipelineError(RuntimeError):
    """A run cannot proceed (e.g. a run folder made with another config)."""


def load_config(path: str | Path | None, overrides: list[str]) -> C.Config:
    """The resolved config: the YAML file (or the embedded :data:`DEFAULT`) plus overrides."""
    if path is None:
        where = "embedded default" + (
            f" (with overrides {', '.join(overrides)})" if overrides else ""
        )
        return C.from_dict(C.apply_overrides(DEFAULT, overrides), where)
    return C.load(path, overrides)


def run_folder(cfg: C.Config, out: str | Path | None) -> Path:
    """The run folder: ``out``, or ``<cfg.out_dir>/<task>-<config hash>``."""
    return Path(out) if out else Path(cfg.out_dir) / f"{cfg.task}-{cfg.hash()[:8]}"


def read_run_info(run: Path) -> tuple[dict | None, str]:
    """``(run.json's content, "")`` when valid, else ``(None, why it is not)``."""
    f = run / "run.json"
    if not f.is_file():
        return None, f"no run.json ({f} missing)"
    try:
        info = json.loads(f.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        return None, f"{f} is unreadable ({type(e).__name__}: {e})"
    if (
        not isinstance(info, dict)
        or not isinstance(info.get("config_hash"), str)
        or not isinstance(info.get("stages"), dict)
    ):
        return None, f"{f} is not a run record (config_hash and stages expected)"
    return info, ""


def _refuse_or_clear(run: Path, why: str, overwrite: bool) -> None:
    """Deletes ``run`` for ``overwrite`` (a run's files only), else raises the error ``why``."""
    if not overwrite:
        raise PipelineError(
            f"{run}: {why}; {_NEW_OUT}, or add --overwrite to delete this folder and start over"
        )
    foreign = foreign_files(run)
    if foreign:
        more = f" and {len(foreign) - 5} more" if len(foreign) > 5 else ""
        raise PipelineError(
            f"{run}: {why}, and it holds {', '.join(foreign[:5])}{more}, which "
            f"are not a run's files; --overwrite refuses to delete it: {_NEW_OUT}"
        )
    shutil.rmtree(run)


def foreign_files(run: Path) -> list[str]:
    """The files (and links) under ``run`` that no run writes (:data:`RUN_FILES`), sorted;
    checked over the whole tree before ``--overwrite`` deletes anything."""
    out = []
    for root, dirs, files in os.walk(run):
        rel = Path(root).relative_to(run)
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            path = (rel / name).as_posix()
            if not RUN_FILES.fullmatch(path):
                out.append(path)
    return sorted(out)


def _check_writable(run: Path) -> None:
    """Raises a :class:`PipelineError` when ``run`` cannot be created or written."""
    why = artifacts.unwritable_reason(run)
    if why:
        raise PipelineError(f"{run}: {why}; {_NEW_OUT} in a writable place")


def _lock(run: Path, note: bool = True) -> None:
    """Takes ``run``'s lock for this process (:func:`ntq_jax.artifacts.lock_folder`)."""
    try:
        artifacts.lock_folder(run, note)
    except artifacts.FolderInUse as e:
        raise PipelineError(f"{e}; wait for that run to finish, or {_NEW_OUT}") from None


def prepare_run(cfg: C.Config, out: str | Path | None, *, overwrite: bool = False) -> Path:
    """Creates (or reopens) the run folder after validating every environment of ``cfg``.

    ``out`` defaults to ``<cfg.out_dir>/<task>-<config hash>``. An existing
    folder is adopted only when its ``run.json`` is valid and records this
    config's hash; an empty folder is used as it is. Nothing is written when
    an error is raised.

    Args:
        cfg: the resolved config.
        out: the run folder (``--out``), or None for the default.
        overwrite: delete a non-empty folder that is not this config's run
            (only when it holds nothing but a run's files) and start over.

    Raises:
        EnvError: an environment of ``cfg.envs`` cannot be made, or two of them
            would share a folder.
        PipelineError: an environment's planner cannot plan for its robot.
        PipelineError: ``out`` is a file or not writable, or a non-empty folder
            that is not a run of this config, or another process is using it
            (the message names its pid). The folder's lock is then held by this
            process until :func:`run_pipeline` returns or the process ends
            (:func:`ntq_jax.artifacts.lock_folder`).
    """
    check_planners(cfg, resolve_envs(cfg.envs))  # before anything is written
    run = run_folder(cfg, out)
    _check_writable(run)
    lock = run / artifacts.LOCK_NAME
    made_lock = took_lock = False
    if (run / "run.json").is_file():  # a run's folder: no one may use or delete it under us
        made_lock, took_lock = not lock.exists(), not artifacts.holds_lock(run)
        _lock(run, note=False)
    try:
        if run.is_dir() and any(p.name != artifacts.LOCK_NAME for p in run.iterdir()):
            info, why = read_run_info(run)
            if info is None:
                _refuse_or_clear(run, f"not empty and not a run folder: {why}", overwrite)
            elif info["config_hash"] != cfg.hash():
                _refuse_or_clear(
                    run,
                    f"holds a run with another config (hash "
                    f"{info['config_hash']}, this one {cfg.hash()})",
                    overwrite,
                )
    except PipelineError:
        if took_lock:  # a refused folder is left as it was: unlocked, and without a new file
            artifacts.unlock_folder(run)
        if made_lock:
            lock.unlink(missing_ok=True)
        raise
    run.mkdir(parents=True, exist_ok=True)
    _lock(run)
    info, _ = read_run_info(run)
    if info is None:
        artifacts.write_json(run / "run.json", {"config_hash": cfg.hash(), "stages": {}})
    text = yaml.safe_dump(cfg.to_dict(), sort_keys=False)
    cfg_file = run / "config.yaml"
    if not cfg_file.is_file() or cfg_file.read_text() != text:
        artifacts.write_text(cfg_file, text)
    return run


def check_planners(cfg: C.Config, envs: dict) -> None:
    """Raises a :class:`PipelineError` when an environment's planner cannot plan for its robot
    (``planner.name`` or its ``per_env`` entry; the message names the key and the fix), or
    when a ``per_env`` entry names no environment at all (a typo would be ignored: an entry
    for a map that is not in ``envs`` is kept, so one config serves each of its maps); a
    :class:`ConfigError` for a data-path spacing too fine for a map
    (:func:`ntq_jax.data.limits.check_spacing`)."""
    for section in ("data", "planner"):
        for i, o in enumerate(getattr(cfg, section).per_env):
            if o.env in envs:
                continue
            try:
                resolve_envs([o.env])
            except EnvError as e:
                raise PipelineError(
                    f"{section}.per_env[{i}].env {o.env!r} is not an "
                    f"environment ({e}); the run's are {', '.join(envs)}"
                ) from None
    for name, env in envs.items():
        check_spacing(env, cfg.planner.data_paths_for(name), name)
        planner = cfg.planner.name_for(name)
        if planner == "roadmap":
            check_roadmap(env, planner_options(C.planner_settings(cfg, name), planner), name)
        why = unsupported_robot(planner, env)
        if why:
            key = (
                "planner.per_env"
                if any(o.env == name and o.name for o in cfg.planner.per_env)
                else "planner.name"
            )
            raise PipelineError(f"{key} {planner} for {name}: {why}")


def data_digest(data_dir: Path, names: list[str]) -> str:
    """A digest of the datasets' recorded checksums (what a trained ensemble was trained on)."""
    return artifacts.fingerprint(recorded_checksums(data_dir, names))


def _mark(run: Path, stage: str, **fields) -> None:
    """Records a finished stage in ``run.json``.

    ``seconds`` accumulate over the invocations that finish the stage (a rerun
    that reuses the stage's outputs adds ~0; one that redoes part of it adds
    that part): the compute the stage has cost; ``last_seconds`` is this call's.
    """
    f = run / "run.json"
    info = json.loads(f.read_text())
    old = info["stages"].get(stage, {})
    if "seconds" in fields:
        fields["last_seconds"] = fields["seconds"]
        fields["seconds"] = round(fields["seconds"] + float(old.get("seconds") or 0.0), 1)
    info["stages"][stage] = {"done": True, "time": time.strftime("%Y-%m-%dT%H:%M:%S"), **fields}
    artifacts.write_json(f, info)


def _host_stage(
    cfg: C.Config,
    run: Path,
    name: str,
    env,
    *,
    progress,
    figures: bool,
    log: Callable[[str], None],
    executor=None,
) -> tuple[dict, float]:
    """The host-side work of one environment, ``(data summary, seconds)``: its datasets and,
    with a non-local executor, the evaluation's test queries and reference (which need no
    model), so that they are planned while other environments train."""
    t0 = time.perf_counter()
    log(
        f"[{name}] data: {cfg.data.k_train_for(name)} queries x {len(cfg.data.datasets)} "
        f"datasets ({cfg.planner.name_for(name)})"
    )
    summary = data_mod.generate_datasets(
        env,
        C.data_options(cfg, name),
        run / "data",
        env_name=name,
        progress=progress,
        figure=figures,
        executor=executor,
    )
    if executor is not None and executor.name != "local":
        slug = env_slug(name, env)
        out_dir = run / "eval" / slug
        reuse_roadmaps(Path(summary["env_dir"]) / "roadmap", out_dir)
        reference_plans(
            env, cfg, name, slug, test_queries(env, cfg, slug, out_dir), out_dir, None, executor
        )
    return summary, time.perf_counter() - t0


def _run_env(
    cfg: C.Config,
    run: Path,
    name: str,
    env,
    *,
    progress,
    figures: bool,
    log: Callable[[str], None],
    executor=None,
    host: Future | None = None,
) -> tuple[list[dict], dict]:
    """Data -> training -> evaluation for one environment; returns its rows and timings.

    ``host``: the environment's :func:`_host_stage` already running in a thread (Ray).
    """
    slug = env_slug(name, env)
    # -- data ----------------------------------------------------------------
    t0 = time.perf_counter()
    if host is None:
        summary, _ = _host_stage(
            cfg, run, name, env, progress=progress, figures=figures, log=log, executor=executor
        )
    else:
        summary, seconds = host.result()
        t0 = time.perf_counter() - seconds  # the stage's own time, not the wait for it
    data_dir = Path(summary["env_dir"])
    for ds, why in summary.get("damaged", {}).items():
        log(
            f"[{name}] data: {ds} failed verification ({why}); "
            + ("rewritten" if ds in summary.get("rewritten", []) else "regenerated")
        )
    t1 = time.perf_counter()
    _mark(run, f"data/{slug}", seconds=round(t1 - t0, 1), skipped=bool(summary.get("skipped")))
    # -- training --------------------------------------------------------------
    model_dir = run / "models" / slug
    digest = data_digest(data_dir, data_mod.dataset_names(len(cfg.data.datasets)))
    if (model_dir / "ensemble" / "ensemble.json").is_file():
        trained_on = (read_run_info(run)[0] or {}).get("stages", {}).get(f"train/{slug}", {})
        if trained_on.get("data") not in (None, digest):
            raise PipelineError(
                f"{model_dir} was trained on other data than {data_dir} now holds (a dataset "
                f"was regenerated and differs); delete {model_dir} and {run / 'paths' / slug} "
                "and rerun the same command to retrain and re-evaluate"
            )
        log(f"[{name}] train: complete, loading {model_dir / 'ensemble'}")
    else:
        log(f"[{name}] train: {len(cfg.data.datasets)} PNets, {cfg.train.epochs} epochs")
        training.train_from_folder(data_dir, model_dir, progress=progress, **C.train_args(cfg))
    ens = training.load_ensemble(model_dir)
    t2 = time.perf_counter()
    _mark(run, f"train/{slug}", seconds=round(t2 - t1, 1), data=digest)
    # -- evaluation ------------------------------------------------------------
    log(
        f"[{name}] evaluate: K_test = {cfg.eval.k_test} uniform + {cfg.eval.k_test} "
        f"non-trivial queries, {ens.num_members} models, steerTo {list(cfg.eval.steer)}"
    )
    rows = evaluate_env(
        env, ens, cfg, run, env_name=name, data_env_dir=data_dir, log=log, executor=executor
    )
    t3 = time.perf_counter()
    _mark(run, f"eval/{slug}", seconds=round(t3 - t2, 1))
    return rows, {"data": t1 - t0, "train": t2 - t1, "eval": t3 - t2}


def run_pipeline(
    cfg: C.Config,
    run: Path,
    *,
    progress=True,
    figures: bool = True,
    log: Callable[[str], None] = print,
    executor=None,
) -> dict:
    """Runs every stage for every environment of ``cfg``; returns the report's file paths.

    Args:
        cfg: the resolved config.
        run: the run folder (from :func:`prepare_run`).
        progress: progress bars (see :mod:`ntq_jax.progress`).
        figures: write the PNG figures.
        log: one-line progress messages.
        executor: where the planning chunks run (:mod:`ntq_jax.executors`; None:
            local, every stage of every environment in turn, as always). With a
            non-local executor (Ray) every environment's host-side stage (data,
            test queries, reference) starts at once, one driver thread each
            submitting its chunks as tasks, and the environments are trained and
            evaluated in the config's order as their data arrive: the cluster
            plans while this process trains. The outputs are the same.

    The run folder's lock (taken by :func:`prepare_run`, or here) is held while
    it runs and released when it returns or raises.
    """
    _lock(run)
    try:
        return _run_stages(cfg, run, progress=progress, figures=figures, log=log, executor=executor)
    finally:
        artifacts.unlock_folder(run)


def _run_stages(cfg: C.Config, run: Path, *, progress, figures: bool, log, executor) -> dict:
    """:func:`run_pipeline`'s stages, the folder locked."""
    rows, timings = [], {}
    envs = resolve_envs(cfg.envs)  # every env built, no two sharing a folder
    concurrent = executor is not None and executor.name != "local" and len(cfg.envs) > 1
    if concurrent:
        executor.start()  # in the main thread, before the environments' threads
    pool = (
        ThreadPoolExecutor(len(cfg.envs), thread_name_prefix="ntq_jax-env") if concurrent else None
    )
    try:
        hosts = (
            {
                name: pool.submit(
                    _host_stage,
                    cfg,
                    run,
                    name,
                    envs[name],
                    progress=progress,
                    figures=figures,
                    log=log,
                    executor=executor,
                )
                for name in cfg.envs
            }
            if pool
            else {}
        )
        for name in cfg.envs:
            env_rows, timings[name] = _run_env(
                cfg,
                run,
                name,
                envs[name],
                progress=progress,
                figures=figures,
                log=log,
                executor=executor,
                host=hosts.get(name),
            )
            rows += env_rows
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    meta = {
        "config": cfg.to_dict(),
        "config_hash": cfg.hash(),
        "timings": timings,
        "package_version": __version__,
    }
    out = write_report(run, rows, envs, meta=meta, figures=figures)
    _mark(run, "report")
    return out
