"""Compact per-map summaries of a run, small enough to commit.

A run folder holds datasets, checkpoints and every planned path (hundreds of
MB at the paper's sizes); a summary keeps what a reader of the results needs
and what proves where they came from, for one environment of a finished run
(:func:`ntq_jax.pipeline.run_pipeline`)::

    <dir>/summary.json   schema, task, env, env_slug, seed, train_seed,
                         package_version, config (the full resolved config) and
                         config_hash, padding (the data padding), rows and
                         comparisons (this map's, as in results.json),
                         fingerprints (per dataset the digest of its arrays'
                         sha256 checksums; one digest of the trained ensemble's
                         weights), datasets (per dataset the planned paths
                         used, samples written and mean states per data
                         path), timings (seconds of data / train / eval),
                         finished, command
    <dir>/tables.md, tables.tex, config.yaml   the run's report and exact config
    <dir>/figures/*.png  the success figure and this map's figures

``scripts/reproduce.py`` writes one per map under ``results/paper/``;
:mod:`ntq_jax.reproduction` renders them into ``REPRODUCTION.md``.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from pathlib import Path

from ntq_jax import artifacts
from ntq_jax.data import dataset_names, env_slug
from ntq_jax.version import __version__

SCHEMA = 1

__all__ = ["SCHEMA", "dataset_fingerprints", "dataset_sizes", "models_fingerprint",
           "write_summary", "read_summary"]


def dataset_fingerprints(data_env_dir: Path, names: list[str]) -> dict[str, str | None]:
    """Per dataset, a digest of the sha256 checksums its ``meta.json`` records (None if absent)."""
    out = {}
    for nm in names:
        try:
            meta = json.loads((Path(data_env_dir) / nm / "meta.json").read_text())
            out[nm] = artifacts.fingerprint({a: v["sha256"] for a, v in meta["arrays"].items()})
        except (OSError, ValueError, KeyError, TypeError):
            out[nm] = None
    return out


def dataset_sizes(data_env_dir: Path, names: list[str]) -> dict[str, dict | None]:
    """Per dataset ``{"paths", "samples", "states_per_path"}`` from its ``meta.json``'s
    stats (planned paths used, rows written, mean states per data path); None if absent."""
    out = {}
    for nm in names:
        try:
            st = json.loads((Path(data_env_dir) / nm / "meta.json").read_text())["stats"]
            out[nm] = {"paths": int(st["paths"]), "samples": int(st["samples"]),
                       "states_per_path": float(st["mean_waypoints"])}
        except (OSError, ValueError, KeyError, TypeError):
            out[nm] = None
    return out


def models_fingerprint(model_dir: Path) -> str | None:
    """sha256 over the trained ensemble's weights (every parameter array's key path, dtype,
    shape and bytes), None if there is no readable ensemble. The weights, not the files:
    Orbax's files hold timestamps, so equal weights saved twice would differ."""
    import jax
    import numpy as np

    from ntq_jax.training import CheckpointError, load_ensemble
    if not (Path(model_dir) / "ensemble").is_dir():
        return None
    try:
        ens = load_ensemble(model_dir)
    except (CheckpointError, OSError, ValueError):
        return None
    h = hashlib.sha256()
    for path, leaf in jax.tree_util.tree_leaves_with_path(ens.params):
        a = np.ascontiguousarray(np.asarray(leaf))
        h.update(f"{jax.tree_util.keystr(path)} {a.dtype.str} {a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _stage_seconds(run: Path, slug: str) -> dict[str, float | None]:
    try:
        stages = json.loads((run / "run.json").read_text())["stages"]
    except (OSError, ValueError, KeyError):
        stages = {}
    return {s: stages.get(f"{s}/{slug}", {}).get("seconds") for s in ("data", "train", "eval")}


def write_summary(run: Path, env_name: str, env, out_dir: Path, *, command: str = "",
                  timings: dict | None = None) -> Path:
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
        "schema": SCHEMA, "task": cfg["task"], "env": env_name, "env_slug": slug,
        "seed": cfg["seed"], "train_seed": cfg["seed"] if train_seed is None else train_seed,
        "package_version": __version__, "config": cfg, "config_hash": res["meta"]["config_hash"],
        "padding": float(env.padding), "rows": rows, "comparisons": comps,
        "fingerprints": {"datasets": dataset_fingerprints(run / "data" / slug, names),
                         "models": models_fingerprint(run / "models" / slug)},
        "datasets": dataset_sizes(run / "data" / slug, names),
        "timings": timings or _stage_seconds(run, slug),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S"), "command": command,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in ("tables.md", "tables.tex", "config.yaml"):
        if (run / name).is_file():
            artifacts.write_text(out_dir / name, (run / name).read_text())
    figs = [run / "figures" / "success_ratio.png"] + sorted(
        (run / "figures").glob(f"*_{slug}.png"))
    for f in figs:
        if f.is_file():
            (out_dir / "figures").mkdir(exist_ok=True)
            tmp = out_dir / "figures" / f".{f.name}.tmp"
            shutil.copyfile(f, tmp)
            tmp.replace(out_dir / "figures" / f.name)
    path = out_dir / "summary.json"
    artifacts.write_json(path, summary, indent=1, default=str)
    return path


def read_summary(out_dir: Path) -> dict | None:
    """The summary in ``out_dir``, or None when there is none (or it is unreadable)."""
    try:
        return json.loads((Path(out_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return None
