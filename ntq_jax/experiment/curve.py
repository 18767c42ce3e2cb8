"""Data-efficiency curve: each dataset trained at several K_train on one map.

``scripts/learning_curve.py`` is the command line over :func:`run_curve`.

The datasets are generated once, at the largest size ``K_max``; size ``K`` uses
the prefix of the first ``K`` queries of every dataset (:func:`prefix_dataset`),
so only training and evaluation repeat.

The prefix property. Every dataset's queries come from pools sampled as
streams (:mod:`ntq_jax.data.pools`: the uniform and the non-trivial samplers
draw fixed key-indexed blocks, and the mixing bits are ``jax.random.uniform``
under JAX's partitionable threefry, the default since JAX 0.5), so the first
``K`` queries of a ``K_max`` run are the queries of a ``K`` run, in order.
``includeData`` emits samples in path order, so the samples of the first
``K`` queries are a prefix of the samples: those whose ``path_index`` (an
index into the dataset's *solved* paths, not into its queries) is below
``P_K = solved[:K].sum()``; probabilistic pruning draws one number per
segment in order, so its draws are a prefix too. Hence, for a planner that is
deterministic per query (grid A*, JPS, the visibility graph), the prefix is
bit for bit the dataset a run with ``data.k_train = K`` writes (checked by
``tests/test_learning_curve.py``). With a seeded planner (OMPL, PRM) the queries
and the sample layout are the same, but a path is the one planned in the
``K_max`` run: the pools are planned in chunks seeded by their first row, and
the non-trivial pool's rows are offset by the uniform pool's size, which grows
with ``K``, so a ``K`` run may draw other paths for the same queries. The
training split (whole paths, :func:`ntq_jax.training.batches.split_by_path`)
is drawn from the size's own paths, as in a ``K`` run, so the training rows
after the split are not a prefix of the larger size's.

Folder (``--out``)::

    curve_run.json                the base config's hash and the map (a rerun must match)
    config.yaml                   the resolved base config
    data/<slug>/D0..D3            the datasets at K_max (ntq_jax.data)
    eval/<slug>/                  the test queries and references, shared by every size
    sizes/<K>/models/             training output of size K (checkpoints, ensemble/)
    sizes/<K>/paths/<slug>/       every planned test path of size K
    sizes/<K>/result.json         size K's rows (written last, atomically, fingerprinted)
    curve.json, curve.md, curve.png

Every size is a resumable unit: a size whose ``result.json`` matches its
fingerprint (the size's config and the digest of its prefix data) is reused
without training or planning; an interrupted size resumes training from its
last checkpoint and reuses its saved evaluation files.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import yaml

from ntq_jax import artifacts, training
from ntq_jax import data as data_mod
from ntq_jax.envs import env_slug, resolve_envs
from ntq_jax.errors import UsageError
from ntq_jax.experiment import config as C
from ntq_jax.experiment.evaluate import evaluate_env
from ntq_jax.experiment.formatting import fixed
from ntq_jax.progress import open_bar

__all__ = ["parse_sizes", "size_config", "prefix_dataset", "curve_rows", "run_curve", "write_table"]

CURVE_VERSION = 1


def parse_sizes(text: str, k_train: int) -> list[int]:
    """The sorted distinct sizes of ``--sizes`` (``"250,500"``); each in ``1..k_train``."""
    out = []
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        try:
            k = int(part)
        except ValueError:
            raise UsageError(
                f"--sizes {text}: {part!r} is not an integer; give a comma-separated "
                "list such as 250,500,1000"
            ) from None
        if k < 1:
            raise UsageError(f"--sizes {text}: {k} is not positive; every size must be >= 1")
        if k > k_train:
            raise UsageError(
                f"--sizes {text}: {k} is larger than the config's k_train "
                f"({k_train}) for this map; raise it with --set data.k_train={k} "
                "or drop the size"
            )
        out.append(k)
    if not out:
        raise UsageError(f"--sizes {text!r}: no size given; e.g. --sizes 250,500,1000")
    return sorted(set(out))


def size_config(cfg: C.Config, env_name: str, k: int) -> C.Config:
    """``cfg`` for one map at ``K_train = k``: member rows only, the first steerTo variant."""
    per_env = tuple(o for o in cfg.data.per_env if o.env != env_name)
    return dataclasses.replace(
        cfg,
        envs=(env_name,),
        data=dataclasses.replace(cfg.data, k_train=int(k), per_env=per_env),
        eval=dataclasses.replace(cfg.eval, steer=(cfg.eval.steer[0],), ensemble=()),
    )


def prefix_dataset(ds, k: int) -> dict[str, np.ndarray]:
    """The arrays of dataset ``ds`` restricted to its first ``k`` queries (see the module docstring).

    ``ds`` is a :class:`ntq_jax.data.Dataset` (or anything with its arrays).
    Returns ``inputs``, ``targets``, ``path_index`` (the samples of the first
    ``P = solved[:k].sum()`` paths, a prefix), ``paths``, ``path_lengths``,
    ``queries``, ``query_kind``, ``solved``.
    """
    solved = np.asarray(ds.solved[:k], bool)
    p = int(solved.sum())
    pidx = np.asarray(ds.path_index)
    n = int(np.searchsorted(pidx, p, side="left"))  # path_index is sorted (path order)
    if n and not np.all(np.diff(pidx[:n]) >= 0):
        raise ValueError("path_index is not in path order; the dataset is not includeData's")
    lens = np.asarray(ds.path_lengths[:p])
    lmax = int(lens.max()) if p else 0
    return {
        "inputs": np.asarray(ds.inputs[:n]),
        "targets": np.asarray(ds.targets[:n]),
        "path_index": pidx[:n],
        "paths": np.asarray(ds.paths[:p, :lmax]),
        "path_lengths": lens,
        "queries": np.asarray(ds.queries[:k]),
        "query_kind": np.asarray(ds.query_kind[:k]),
        "solved": solved,
    }


def curve_rows(
    size: int, names: Sequence[str], prefixes: Sequence[dict], eval_rows: Sequence[dict]
) -> list[dict]:
    """One curve row per (dataset, query kind) of one size from its evaluation rows."""
    out = []
    for r in eval_rows:
        m = r.get("member")
        if m is None:
            continue
        pre = prefixes[m]
        out.append(
            {
                "size": int(size),
                "dataset": names[m],
                "model": r["model"],
                "rows": int(len(pre["inputs"])),
                "paths": int(pre["solved"].sum()),
                "queries": int(len(pre["queries"])),
                "kind": r["query_kind"],
                "steer": r["steer"],
                "k_test": r["k_test"],
                "successes": r["successes"],
                "success": r["success_ratio"],
                "ci95": list(r["success_ci95"]),
                "cost_ratio": r["cost_ratio"],
                "cost_ratio_n": r["cost_ratio_n"],
                "cost_ratio_opt": r.get("cost_ratio_opt"),
            }
        )
    return out


def write_table(rows: Sequence[dict], path: Path, title: str) -> Path:
    """``curve.md``: per size and dataset, the rows and both kinds' success and cost ratio."""
    lines = [
        f"# {title}",
        "",
        "Success ratio with its 95 % Wilson interval; cost ratio = neural / reference "
        "cost over the queries both solved.",
        "",
        "| K_train | dataset | rows | non-trivial success [95 % CI] | non-trivial cost ratio "
        "| uniform success [95 % CI] | uniform cost ratio |",
        "|---:|---|---:|---|---:|---|---:|",
    ]
    cells = {(r["size"], r["dataset"], r["kind"]): r for r in rows}
    keys = sorted({(r["size"], r["dataset"]) for r in rows}, key=lambda t: (t[0], int(t[1][1:])))
    for size, ds in keys:
        parts = [str(size), ds]
        rr = [cells.get((size, ds, kind)) for kind in ("nontrivial", "uniform")]
        parts.append(str(next(r["rows"] for r in rr if r)))
        for r in rr:
            if r is None:
                parts += ["-", "-"]
            else:
                parts += [
                    f"{fixed(r['success'])} [{fixed(r['ci95'][0])}, {fixed(r['ci95'][1])}]",
                    fixed(r["cost_ratio"]),
                ]
        lines.append("| " + " | ".join(parts) + " |")
    return artifacts.write_text(path, "\n".join(lines) + "\n")


def _open_folder(cfg: C.Config, env_name: str, out: Path) -> None:
    """Creates ``out`` or checks it holds a curve of this config and map."""
    rec = {"config_hash": cfg.hash(), "env": env_name, "version": CURVE_VERSION}
    f = out / "curve_run.json"
    if f.is_file():
        try:
            got = json.loads(f.read_text())
        except (OSError, ValueError):
            got = None
        if got != rec:
            raise UsageError(
                f"--out {out} holds a learning curve of another config or map "
                f"({f}); pass a new --out, or delete the folder to start over"
            )
    elif out.is_dir() and any(p for p in out.iterdir() if not p.name.startswith(".")):
        raise UsageError(
            f"--out {out} is not empty and holds no learning curve (no {f.name}); pass a new --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    artifacts.write_text(out / "config.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    artifacts.write_json(f, rec)


def _size_unit(
    cfg_k: C.Config,
    env,
    env_name: str,
    k: int,
    names: list[str],
    prefixes: list[dict],
    out: Path,
    data_dir: Path,
    eval_dir: Path,
    progress,
    log: Callable[[str], None],
    executor=None,
) -> list[dict]:
    """Trains and evaluates one size, or reuses its finished ``result.json``."""
    size_dir = out / "sizes" / str(k)
    result = size_dir / "result.json"
    fp = artifacts.fingerprint(
        {
            "version": CURVE_VERSION,
            "config": cfg_k.hash(),
            "env": env_name,
            "size": k,
            "data": [
                artifacts.array_digest(p["inputs"], p["targets"], p["path_index"]) for p in prefixes
            ],
        }
    )
    if result.is_file():
        try:
            got = json.loads(result.read_text())
            if got.get("fingerprint") == fp:
                log(f"[size {k}] done, reusing {result}")
                return got["rows"]
        except (OSError, ValueError, AttributeError):
            pass
    for nm, p in zip(names, prefixes):
        if len(p["inputs"]) == 0:
            raise UsageError(
                f"size {k}: dataset {nm} has no samples in its first {k} queries; "
                "drop the size or use larger sizes"
            )
    t0 = time.perf_counter()
    model_dir = size_dir / "models"
    if (model_dir / "ensemble" / "ensemble.json").is_file():
        log(f"[size {k}] train: complete, loading {model_dir / 'ensemble'}")
    else:
        log(
            f"[size {k}] train: {len(names)} PNets on "
            + ", ".join(f"{nm} {len(p['inputs'])} rows" for nm, p in zip(names, prefixes))
        )
        training.train_ensemble(
            [(p["inputs"], p["targets"], p["path_index"]) for p in prefixes],
            env,
            cfg_k.model,
            cfg_k.train,
            seed=cfg_k.train.seed_for(cfg_k.seed),
            ckpt_dir=model_dir,
            progress=progress,
            labels=names,
            resolved_config=cfg_k.to_dict(),
        )
    ens = training.load_ensemble(model_dir)
    t1 = time.perf_counter()
    log(
        f"[size {k}] evaluate: {cfg_k.eval.k_test} uniform + {cfg_k.eval.k_test} non-trivial "
        "test queries"
    )
    eval_rows = evaluate_env(
        env,
        ens,
        cfg_k,
        size_dir,
        env_name=env_name,
        data_env_dir=data_dir,
        eval_dir=eval_dir,
        log=log,
        executor=executor,
    )
    rows = curve_rows(k, names, prefixes, eval_rows)
    artifacts.write_json(
        result,
        {
            "fingerprint": fp,
            "size": k,
            "rows": rows,
            "seconds": {"train": round(t1 - t0, 1), "eval": round(time.perf_counter() - t1, 1)},
        },
        default=artifacts.json_default,
    )
    return rows


def run_curve(
    cfg: C.Config,
    env_name: str,
    sizes: Sequence[int],
    out: str | Path,
    *,
    progress=True,
    figures: bool = True,
    log: Callable[[str], None] = print,
    executor=None,
) -> dict:
    """Generates the data at ``max(sizes)``, then trains and evaluates every size.

    Args:
        cfg: the resolved base config (model, train, eval, seed, planner).
        env_name: the map (a preset name or JSON path).
        sizes: the K_train values (each <= ``cfg.data.k_train_for(env_name)``).
        out: the curve folder (see the module docstring).
        progress: progress bars (:func:`ntq_jax.progress.open_bar`).
        figures: write ``curve.png``.
        log: one-line progress messages.
        executor: where the planning chunks run (data and the reference;
            :mod:`ntq_jax.executors`; None: in this process).

    Returns:
        ``{"json": ..., "md": ..., "png": ... or None}``: the written files.
    """
    sizes = sorted({int(k) for k in sizes})
    if not sizes or sizes[0] < 1:
        raise UsageError(f"sizes {sizes}: every size must be >= 1")
    if sizes[-1] > cfg.data.k_train_for(env_name):
        raise UsageError(
            f"size {sizes[-1]} is larger than the config's k_train "
            f"({cfg.data.k_train_for(env_name)}) for {env_name}"
        )
    env = resolve_envs([env_name])[env_name]
    out = Path(out)
    _open_folder(cfg, env_name, out)
    slug = env_slug(env_name, env)
    t0 = time.perf_counter()
    gen_cfg = size_config(cfg, env_name, sizes[-1])
    log(
        f"[{env_name}] data: {sizes[-1]} queries x {len(cfg.data.datasets)} datasets "
        f"({cfg.planner.name_for(env_name)}), generated once for sizes {sizes}"
    )
    summary = data_mod.generate_datasets(
        env,
        C.data_options(gen_cfg, env_name),
        out / "data",
        env_name=env_name,
        progress=progress,
        figure=False,
        executor=executor,
    )
    data_dir = Path(summary["env_dir"])
    datasets = data_mod.load_datasets(data_dir)
    names = data_mod.dataset_names(len(datasets))
    t_data = time.perf_counter() - t0
    rows = []
    with open_bar(progress, desc=f"{slug}: learning curve", total=len(sizes), unit="size") as bar:
        for k in sizes:
            prefixes = [prefix_dataset(ds, k) for ds in datasets]
            rows += _size_unit(
                size_config(cfg, env_name, k),
                env,
                env_name,
                k,
                names,
                prefixes,
                out,
                data_dir,
                out / "eval" / slug,
                progress,
                log,
                executor,
            )
            bar.update(1)
    doc = {
        "env": env_name,
        "env_slug": slug,
        "config_hash": cfg.hash(),
        "sizes": sizes,
        "datasets": [
            {"name": nm, "p_nt": d.p_nt, "prune": d.prune}
            for nm, d in zip(names, cfg.data.datasets)
        ],
        "k_test": cfg.eval.k_test,
        "steer": cfg.eval.steer[0],
        "data_seconds": round(t_data, 1),
        "total_seconds": round(time.perf_counter() - t0, 1),
        "rows": rows,
    }
    files = {
        "json": artifacts.write_json(out / "curve.json", doc, default=artifacts.json_default),
        "md": write_table(
            rows,
            out / "curve.md",
            f"Learning curve: {env_name} ({cfg.planner.name_for(env_name)} data, "
            f"K_test {cfg.eval.k_test} per kind)",
        ),
        "png": None,
    }
    if figures:
        from ntq_jax.plotting import learning_curve_figure

        files["png"] = learning_curve_figure(rows, out / "curve.png", title=env_name)
    return files
