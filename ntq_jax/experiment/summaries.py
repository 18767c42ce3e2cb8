"""Compact per-map summaries of a run, small enough to commit.

A run folder holds datasets, checkpoints and every planned path (hundreds of
MB at the paper's sizes); a summary keeps what a reader of the results needs
and what proves where they came from, for one environment of a finished run
(:func:`ntq_jax.experiment.pipeline.run_pipeline`)::

    <dir>/summary.json   schema, task, env, env_slug, seed, train_seed,
                         package_version, config (the full resolved config) and
                         config_hash, padding (the data padding), rows and
                         comparisons (this map's, as in results.json),
                         fingerprints (per dataset the digest of its arrays'
                         sha256 checksums; one digest of the trained ensemble's
                         weights), datasets (per dataset the planned paths
                         used, samples written and mean states per data
                         path), timings (seconds of data / train / eval),
                         finished, command, outcomes (its file's name, or
                         null when it could not be written)
    <dir>/outcomes.npz   every test query's outcome per model, query kind and
                         steerTo (success bits, cost, cause; the reference's
                         cost and status; the in-band mask), from which every
                         count of the summary is recomputed
                         (:mod:`ntq_jax.experiment.outcomes`)
    <dir>/tables.md, tables.tex, config.yaml   the run's report and exact config
    <dir>/figures/*.png  the success figure and this map's figures

``scripts/reproduce.py`` writes one per map under ``results/paper/``;
:mod:`ntq_jax.experiment.reproduction` renders them into ``REPRODUCTION.md``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from ntq_jax import artifacts
from ntq_jax.data import dataset_names
from ntq_jax.data.format import recorded_checksums
from ntq_jax.envs import env_slug
from ntq_jax.experiment.paper import (
    KINDS,
    MAPS,
    MEMBERS,
    PAPER_DATASETS,
    PAPER_K_TEST,
    PAPER_K_TRAIN,
    PAPER_PADDING,
)
from ntq_jax.version import __version__

SCHEMA = 1

__all__ = [
    "SCHEMA",
    "dataset_fingerprints",
    "dataset_sizes",
    "models_fingerprint",
    "write_summary",
    "read_summary",
]


def dataset_fingerprints(data_env_dir: Path, names: list[str]) -> dict[str, str | None]:
    """Per dataset, a digest of the sha256 checksums its ``meta.json`` records (None if absent)."""
    sums = recorded_checksums(data_env_dir, names)
    return {nm: None if s is None else artifacts.fingerprint(s) for nm, s in sums.items()}


def dataset_sizes(data_env_dir: Path, names: list[str]) -> dict[str, dict | None]:
    """Per dataset ``{"paths", "samples", "states_per_path"}`` from its ``meta.json``'s
    stats (planned paths used, rows written, mean states per data path); None if absent."""
    out = {}
    for nm in names:
        try:
            st = json.loads((Path(data_env_dir) / nm / "meta.json").read_text())["stats"]
            out[nm] = {
                "paths": int(st["paths"]),
                "samples": int(st["samples"]),
                "states_per_path": float(st["mean_waypoints"]),
            }
        except (OSError, ValueError, KeyError, TypeError):
            out[nm] = None
    return out


def models_fingerprint(model_dir: Path) -> str | None:
    """sha256 over the trained ensemble's weights (every parameter array's key path, dtype,
    shape and bytes), None if there is no readable ensemble. The weights, not the files:
    Orbax's files hold timestamps, so equal weights saved twice would differ."""

    from ntq_jax.training import CheckpointError, load_ensemble

    if not (Path(model_dir) / "ensemble").is_dir():
        return None
    try:
        ens = load_ensemble(model_dir)
    except (CheckpointError, OSError, ValueError):
        return None
    return artifacts.tree_digest(ens.params)


def _stage_seconds(run: Path, slug: str) -> dict[str, float | None]:
    try:
        stages = json.loads((run / "run.json").read_text())["stages"]
    except (OSError, ValueError, KeyError):
        stages = {}
    return {s: stages.get(f"{s}/{slug}", {}).get("seconds") for s in ("data", "train", "eval")}


def write_summary(
    run: Path, env_name: str, env, out_dir: Path, *, command: str = "", timings: dict | None = None
) -> Path:
    """Writes the summary of environment ``env_name`` of the finished run ``run`` to ``out_dir``.

    Args:
        run: the run folder (``results.json``, ``run.json``, ``data/``, ``models/``).
        env_name: the name in the run's ``config.envs``.
        env: its :class:`ntq_jax.Env` (the data padding and the folder name).
        out_dir: the summary folder (created; files replaced atomically).
        command: the command that made the run (recorded).
        timings: seconds per stage (default: those ``run.json`` recorded; a
            resumed stage records only its own, short, time, so pass the
            accumulated ones when known).

    Returns:
        The path of ``summary.json``.

    Raises:
        FileNotFoundError: the run has no ``results.json`` (not finished).
    """
    run, out_dir = Path(run), Path(out_dir)
    res = json.loads((run / "results.json").read_text())
    cfg = res["meta"]["config"]
    slug = env_slug(env_name, env)
    rows = [r for r in res["rows"] if r["env"] == env_name]
    comps = [c for c in res.get("comparisons", []) if c["env"] == env_name]
    names = dataset_names(len(cfg["data"]["datasets"]))
    train_seed = cfg["train"].get("seed")
    summary = {
        "schema": SCHEMA,
        "task": cfg["task"],
        "env": env_name,
        "env_slug": slug,
        "seed": cfg["seed"],
        "train_seed": cfg["seed"] if train_seed is None else train_seed,
        "package_version": __version__,
        "config": cfg,
        "config_hash": res["meta"]["config_hash"],
        "padding": float(env.padding),
        "rows": rows,
        "comparisons": comps,
        "fingerprints": {
            "datasets": dataset_fingerprints(run / "data" / slug, names),
            "models": models_fingerprint(run / "models" / slug),
        },
        "datasets": dataset_sizes(run / "data" / slug, names),
        "timings": timings or _stage_seconds(run, slug),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "command": command,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    from ntq_jax.experiment import outcomes

    try:  # the per-query outcomes: a failure here must not lose the summary itself
        outcomes.write(run, env_name, out_dir, env, summary["train_seed"])
        summary["outcomes"] = outcomes.FILE
    except (OSError, KeyError, ValueError, TypeError) as e:
        print(
            f"warning: {env_name}: per-query outcomes not written ({type(e).__name__}: {e}); "
            f"python -m ntq_jax.experiment.outcomes --pack {run} --env {env_name} "
            f"--out {out_dir} writes them later",
            file=sys.stderr,
        )
        summary["outcomes"] = None
    for name in ("tables.md", "tables.tex", "config.yaml"):
        if (run / name).is_file():
            artifacts.write_text(out_dir / name, (run / name).read_text())
    figs = [run / "figures" / "success_ratio.png"] + sorted((run / "figures").glob(f"*_{slug}.png"))
    for f in figs:
        if f.is_file():
            artifacts.write_bytes(out_dir / "figures" / f.name, f.read_bytes())
    path = out_dir / "summary.json"
    artifacts.write_json(path, summary, indent=1, default=str)
    return path


def read_summary(out_dir: Path) -> dict | None:
    """The summary in ``out_dir``, or None when there is none (or it is unreadable)."""
    try:
        return json.loads((Path(out_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return None


# Reading and checking summaries (REPRODUCTION.md's input)


def task_of(env: str) -> str:
    return env.split("/", 1)[0]


def map_key(env: str) -> tuple:
    return (MAPS.index(env), env) if env in MAPS else (len(MAPS), env)


def is_seed_run(summary: dict) -> bool:
    """Whether ``summary`` is a seed-variance run (under ``seeds/``), not a map's main run."""
    return "seeds" in Path(summary.get("_path", "")).parts


class SummaryError(ValueError):
    """A committed summary that cannot be read (the message names the file and the fix)."""


def load_summaries(root) -> list[dict]:
    """Every ``summary.json`` under ``root``: ``<task>/<map>/`` and ``<task>/<map>/seeds/*/``.

    Each summary gets ``_path``, its path relative to ``root`` (POSIX). Sorted by map (the
    paper's order, unknown maps after), main run before seed runs, then train seed and path.
    A missing root gives an empty list.

    Raises:
        SummaryError: a ``summary.json`` that is not valid JSON (or not an object).
    """
    root = Path(root)
    files = list(root.glob("*/*/summary.json")) + list(root.glob("*/*/seeds/*/summary.json"))
    out = []
    for f in files:
        try:
            s = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise SummaryError(
                f"{f}: not a readable summary ({type(e).__name__}: {e}); restore "
                "it from git, or delete it and rerun the map with "
                "scripts/reproduce.py"
            ) from None
        if not isinstance(s, dict):
            raise SummaryError(
                f"{f}: not a summary (a JSON object is expected); restore it "
                "from git, or delete it and rerun the map"
            )
        s["_path"] = f.relative_to(root).as_posix()
        out.append(s)
    return sorted(
        out,
        key=lambda s: (
            map_key(s.get("env", "")),
            is_seed_run(s),
            s.get("train_seed", 0),
            s["_path"],
        ),
    )


def k_train_of(config: dict, env: str):
    data = config.get("data", {})
    for o in data.get("per_env") or ():
        if o.get("env") == env and o.get("k_train") is not None:
            return o["k_train"]
    return data.get("k_train")


def check_summary(summary: dict) -> list[str]:
    """What makes ``summary`` not a paper-size run of its map; empty when it is one.

    Checked: schema 1; a known map of its task; K_train (``config.data``, with its
    ``per_env`` override) = :data:`PAPER_K_TRAIN`; ``config.eval.k_test`` and every row's
    ``k_test`` = :data:`PAPER_K_TEST`; ``padding`` = :data:`PAPER_PADDING` of the task;
    datasets = :data:`PAPER_DATASETS`; a non-empty fingerprint for every dataset D0..D3
    and for the models; timings of the data, train and eval stages; rows of PNet_0..3 on
    both query kinds with steerTo; for a rigid main run, rows without steerTo (Table III).
    """
    out = []
    env = summary.get("env")
    if summary.get("schema") != 1:
        out.append(f"schema is {summary.get('schema')!r}, expected 1")
    if env not in PAPER_K_TRAIN:
        return out + [f"env {env!r} is not one of the paper's maps"]
    task = task_of(env)
    if summary.get("task") != task:
        out.append(f"task {summary.get('task')!r} does not match env {env}")
    config = summary.get("config") or {}
    kt = k_train_of(config, env)
    if kt != PAPER_K_TRAIN[env]:
        out.append(f"K_train is {kt}, the paper's is {PAPER_K_TRAIN[env]}")
    k_test = config.get("eval", {}).get("k_test")
    if k_test != PAPER_K_TEST:
        out.append(f"K_test is {k_test}, the paper's is {PAPER_K_TEST}")
    pad = summary.get("padding")
    if not isinstance(pad, (int, float)) or abs(pad - PAPER_PADDING[task]) > 1e-9:
        out.append(f"padding is {pad}, the paper's is {PAPER_PADDING[task]}")
    ds = [
        {"p_nt": float(d.get("p_nt", -1)), "prune": bool(d.get("prune"))}
        for d in config.get("data", {}).get("datasets") or ()
    ]
    if ds != list(PAPER_DATASETS):
        out.append(f"datasets are {ds}, the paper's are D0..D3 {list(PAPER_DATASETS)}")
    fp = summary.get("fingerprints") or {}
    fd = fp.get("datasets") or {}
    missing = [f"D{i}" for i in range(len(PAPER_DATASETS)) if not fd.get(f"D{i}")]
    if missing:
        out.append(f"dataset fingerprints missing: {', '.join(missing)}")
    if not fp.get("models"):
        out.append("model fingerprint missing")
    tm = summary.get("timings") or {}
    if any(not isinstance(tm.get(k), (int, float)) for k in ("data", "train", "eval")):
        out.append("timings of data/train/eval missing")
    rows = summary.get("rows") or []
    bad_k = sorted({r.get("k_test") for r in rows if r.get("k_test") != PAPER_K_TEST}, key=str)
    if bad_k:
        out.append(f"rows with k_test {bad_k}, the paper's is {PAPER_K_TEST}")
    have = {(r.get("model"), r.get("query_kind"), r.get("steer")) for r in rows}
    need = [(m, k, True) for m in MEMBERS for k in KINDS]
    if task == "rigid" and not is_seed_run(summary):
        need += [(m, k, False) for m in MEMBERS for k in KINDS]
    lack = [
        f"{m} {k}{'' if s else ' without steerTo'}" for m, k, s in need if (m, k, s) not in have
    ]
    if lack:
        out.append(f"rows missing: {', '.join(lack)}")
    return out


def check_seed_runs(summaries) -> list[str]:
    """What is wrong with the seed-variance runs of ``summaries``; empty when fine.

    A seed run (``<task>/<map>/seeds/train_seed_<k>/``) must have ``train_seed`` k, a
    main run of its map, and the main run's dataset fingerprints (same data, another
    training seed).
    """
    out = []
    main = main_runs(summaries)
    for s in summaries:
        if not is_seed_run(s):
            continue
        path, env = s.get("_path", "?"), s.get("env")
        folder = Path(path).parent.name
        if folder != f"train_seed_{s.get('train_seed')}":
            out.append(f"{path}: train_seed {s.get('train_seed')!r} but folder {folder}")
        m = main.get(env)
        if m is None:
            out.append(f"{path}: no main run of {env}")
            continue
        fd = (s.get("fingerprints") or {}).get("datasets")
        if fd != (m.get("fingerprints") or {}).get("datasets"):
            out.append(f"{path}: dataset fingerprints differ from the main run of {env}")
    return out


def main_runs(summaries) -> dict:
    """``{env: summary}`` of the main runs (first one per map)."""
    out = {}
    for s in summaries:
        if not is_seed_run(s):
            out.setdefault(s.get("env"), s)
    return out


def run_cells(summary, steer: bool) -> dict:
    """``{(model, kind): row}`` of ``summary`` with steerTo ``steer``."""
    if summary is None:
        return {}
    return {
        (r["model"], r["query_kind"]): r
        for r in summary.get("rows", [])
        if bool(r.get("steer", True)) == steer
    }
