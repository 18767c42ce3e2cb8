"""Dataset generation (Alg. 2 of the paper, samples by includeData, Alg. 4): :func:`generate_datasets`.

Usage::

    from ntq_jax import data, make_env
    opts = data.DataOptions(k_train=400, chunk=200, gamma_queries=200_000)
    summary = data.generate_datasets(make_env("point/0"), opts, "runs/data")
    d0, d1, d2, d3 = data.load_datasets("runs/data/point_0")

Shared planning: the datasets draw their queries from two pools, each planned
once, ``U`` (i.i.d. uniform queries) and ``N`` (i.i.d. non-trivial queries).
Dataset ``j`` uses the prefixes ``U[:K - sum(b_j)]`` and ``N[:sum(b_j)]``,
interleaved by its mixing bits ``b_j`` (:mod:`ntq_jax.data.pools`). The bits are
independent of the pools, so every dataset's queries have exactly Alg. 2's
distribution; only the datasets' joint distribution changes (they share
queries). For the paper's D0..D3: D0 = ``U[:K]``, D2 = ``N[:K]``, D3 = D2 pruned,
D1 about half of each, so ``2K`` queries are planned instead of ``4K``.
A dataset with probabilistic pruning (``prune`` a probability or ``gamma``, e.g.
a ``D4`` with ``p_nt = 1``) shares D2's queries and keeps each of D2's free
("trivial-remainder") samples with probability ``1 - p_prune``
(:mod:`ntq_jax.data.include`); ``gamma`` is this run's gamma_nt estimate at the
data-generation padding (``meta.json``'s ``gamma_nt``), and ``p_prune`` is
recorded in ``meta.json``.
``meta.json`` records each dataset's pool ranges (``sharing``).

Resumable: the planning chunks stay in ``<env_dir>/.work/<fingerprint>/``
(:mod:`ntq_jax.planners.jobs`) until the datasets are written (``meta.json``
last, :mod:`ntq_jax.data.format`); a rerun reuses them. Complete means verified:
a rerun checks every array against the checksums in its ``meta.json``
(:func:`ntq_jax.data.format.damaged_datasets`); when all match the output is
left untouched, otherwise the pools are planned again and only the damaged
datasets are rewritten (an intact dataset is rewritten too if the planner does
not reproduce it bit for bit, so the set stays consistent). ``<env_dir>/config.yaml``
records the resolved config (``DataOptions.record``), so the advice of every dataset
error is an exact command. Stage timings: BENCHMARKS.md (``benchmarks/bench_data.py``).
"""

from __future__ import annotations

import contextlib
import json
import shutil
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, NamedTuple

import jax
import numpy as np
import yaml

from ntq_jax import artifacts
from ntq_jax import queries as Q
from ntq_jax.data import records
from ntq_jax.data.datasets import (
    common_meta,
    dataset_arrays,
    dataset_stats,
    dataset_warnings,
    resolve_prune,
    sharing,
)
from ntq_jax.data.format import (
    CONFIG_FILE,
    FORMAT_VERSION,
    damaged_datasets,
    dataset_names,
    plot_environment,
    write_dataset,
)
from ntq_jax.data.include import prune_rng
from ntq_jax.data.limits import check_roadmap, check_spacing
from ntq_jax.data.options import DataOptions
from ntq_jax.data.pools import (
    Keys,
    mixing_bits,
    pool_index,
    pool_sizes,
    run_keys,
    sample_pools,
)
from ntq_jax.envs import env_slug
from ntq_jax.planners.jobs import PoolPlan, plan_pool, planner_options, resolve_planner
from ntq_jax.planners.path_modes import shape_paths
from ntq_jax.progress import open_bar
from ntq_jax.robots.batch import steer_to_pairs

__all__ = [
    "RunSpec",
    "resolve_run",
    "estimate_gammas",
    "dataset_arrays",
    "dataset_stats",
    "generate_datasets",
]

_NO_GAMMA = {"padding": 0.0, "gamma": None, "ci95": None, "queries": 0}


# ---------------------------------------------------------------------------
# The run's settings
# ---------------------------------------------------------------------------


class RunSpec(NamedTuple):
    """Everything one environment's generation follows from, resolved once."""

    env_name: str
    slug: str
    env_dir: Path
    names: list[str]  # D0, D1, ...
    specs: list  # options.datasets
    k: int  # queries per dataset
    padding: float  # the data-generation geometry
    prune_padding: float
    plan_fn: Callable
    planner_name: str
    options: dict
    verify: bool  # plan_fn is a user's callable: verify its results here
    keys: Keys
    bits: list[np.ndarray]
    fingerprint: str
    data_paths: float | str | None = None  # planner.data_paths (ntq_jax.planners.path_modes)
    record: dict | None = None  # data.per_env's paths_from: records.provenance of the record
    data_check: str = "discretized"  # the motion check of the data paths (planner.data_check)

    @property
    def n_u(self) -> int:
        return pool_sizes(self.bits)[0]

    @property
    def n_nt(self) -> int:
        return pool_sizes(self.bits)[1]


def resolve_run(env, opts: DataOptions, out_dir, env_name: str | None, planner) -> RunSpec:
    """The :class:`RunSpec` of ``generate_datasets``' arguments (paddings resolved here)."""
    env_name = env_name or env.name
    slug = env_slug(env_name, env)
    dc = opts
    specs = list(dc.datasets)
    k = dc.k_train
    pad, prune_pad = env.resolve_padding(None), env.resolve_padding(dc.prune_padding)
    planner = opts.planner.name if planner is None else planner
    custom = callable(planner)
    options = (
        dict(getattr(planner, "options", {}) or {})
        if custom
        else planner_options(opts.planner, str(planner))
    )
    plan_fn, planner_name = resolve_planner(
        planner, options, cache_dir=Path(out_dir) / slug / "roadmap"
    )
    keys = run_keys(opts.seed, slug)
    bits = [mixing_bits(keys.mix, k, s.p_nt) for s in specs]
    n_u, n_nt = pool_sizes(bits)
    mode = opts.planner.data_paths
    check_spacing(env, mode, env_name)  # before any work
    if planner_name == "roadmap":
        check_roadmap(env, options, env_name)
    source = dc.paths_from
    record = None if source is None else records.provenance(source, {"U": n_u, "N": n_nt})
    fp = artifacts.fingerprint(
        {
            "format": FORMAT_VERSION,
            "env": env.to_json(),
            "env_name": env_name,
            "seed": opts.seed,
            "pad": pad,
            "prune_pad": prune_pad,
            "planner": planner_name,
            "options": options,
            "n_max": opts.n_max,
            "n_u": n_u,
            "n_nt": n_nt,
            "k": k,
            "datasets": [[s.p_nt, s.prune] for s in specs],
            "gamma_queries": dc.gamma_queries,
            "gamma_eval": dc.gamma_eval,
            # only when set: the fingerprints of runs with the planners' default paths stay
            **({} if mode is None else {"data_paths": mode}),
            # a spacing's paths keep a direct connection as its two ends (path_modes)
            **(
                {"direct": "ends"}
                if isinstance(mode, (int, float)) and not isinstance(mode, bool)
                else {}
            ),
            # only when set: every data path passes this check (a user's planner's too)
            **(
                {}
                if opts.planner.data_check == "discretized"
                else {"data_check": opts.planner.data_check}
            ),
            # the record's chunks, by content: a changed record makes the datasets again
            **({} if record is None else {"paths_from": str(source), "record": record["digest"]}),
        },
        default=artifacts.json_default,
    )
    return RunSpec(
        env_name,
        slug,
        Path(out_dir) / slug,
        dataset_names(len(specs)),
        specs,
        k,
        pad,
        prune_pad,
        plan_fn,
        planner_name,
        options,
        custom,
        keys,
        bits,
        fp,
        mode,
        record,
        opts.planner.data_check,
    )


# ---------------------------------------------------------------------------
# Steps
# ---------------------------------------------------------------------------


def estimate_gamma(env, key: jax.Array, n: int, padding: float, cache: Path) -> dict:
    """gamma_nt at ``padding`` as a JSON-ready dict, cached in ``cache`` (a resumed run reads it)."""
    if cache.is_file():
        try:
            return json.loads(cache.read_text())
        except (OSError, json.JSONDecodeError):
            pass
    try:
        e = env.gamma_nt(key, n, padding=padding)
        out = {"padding": padding, "gamma": e.gamma, "ci95": list(e.ci95), "queries": e.queries}
    except Q.FreeSpaceTooSmall as err:
        out = {"padding": padding, "gamma": None, "ci95": None, "queries": 0, "error": str(err)}
    artifacts.write_json(cache, out, default=artifacts.json_default)
    return out


def estimate_gammas(
    env, key: jax.Array, opts: DataOptions, padding: float, work: Path
) -> tuple[dict, dict, float]:
    """``(gamma_nt at padding, gamma_nt at 0 or none, seconds)`` (``data.gamma_eval``).

    At ``padding`` 0 (e.g. the Panda's scenes) the data geometry is the evaluation
    geometry, and the one estimate serves as both."""
    t0 = time.perf_counter()
    n = opts.gamma_queries
    g_data = estimate_gamma(env, jax.random.fold_in(key, 0), n, padding, work / "gamma_data.json")
    if not opts.gamma_eval:
        g_eval = dict(_NO_GAMMA)
    elif float(padding) == 0.0:
        g_eval = dict(g_data)
    else:
        g_eval = estimate_gamma(env, jax.random.fold_in(key, 1), n, 0.0, work / "gamma_eval.json")
    return g_data, g_eval, time.perf_counter() - t0


def write_figure(run: RunSpec) -> None:
    """``<env_dir>/figure.png``; a failure is a warning (a figure must never cost the data)."""
    try:
        plot_environment(run.env_dir, out=run.env_dir / "figure.png")
    except Exception as e:  # noqa: BLE001
        warnings.warn(f"{run.env_name}: figure not written: {e}", RuntimeWarning, stacklevel=3)


def _warn_rejected(run: RunSpec, planned: PoolPlan, recorded: int = 0) -> None:
    n = int(planned.rejected.sum())
    if n:
        where = f" ({recorded} of them from {run.record['record']})" if recorded else ""
        warnings.warn(
            f"{run.env_name}: {n} planner path(s){where} failed the independent "
            f"check (a segment in collision at padding {run.padding}, or not finite); "
            "they are recorded as unsolved",
            RuntimeWarning,
            stacklevel=3,
        )


def _open_work(env, opts: DataOptions, run: RunSpec) -> Path:
    """Creates ``<env_dir>/.work/<fingerprint>/``; writes ``env.json`` and ``config.yaml``."""
    work = run.env_dir / ".work" / run.fingerprint
    work.mkdir(parents=True, exist_ok=True)
    artifacts.clean_tmp(work)
    env.save_json(run.env_dir / "env.json")
    text = yaml.safe_dump(opts.recorded(), sort_keys=False)
    cfg_file = run.env_dir / CONFIG_FILE
    if not cfg_file.is_file() or cfg_file.read_text() != text:
        artifacts.write_text(cfg_file, text)
    return work


def _unchanged(folder: Path, arrays: dict[str, np.ndarray]) -> bool:
    """``folder``'s ``meta.json`` records exactly these arrays (sha256 of their ``.npy`` bytes)."""
    try:
        recorded = json.loads((folder / "meta.json").read_text())["arrays"]
        return all(
            recorded[name]["sha256"] == artifacts.npy_sha256(a) for name, a in arrays.items()
        )
    except (OSError, ValueError, KeyError, TypeError):
        return False


def _already_complete(run: RunSpec, figure: bool) -> dict:
    """The summary of a complete output; finishes an interrupted figure and clean-up."""
    metas = {nm: json.loads((run.env_dir / nm / "meta.json").read_text()) for nm in run.names}
    if figure and not (run.env_dir / "figure.png").is_file():
        write_figure(run)
    shutil.rmtree(run.env_dir / ".work", ignore_errors=True)
    return {
        "env_dir": str(run.env_dir),
        "skipped": True,
        "fingerprint": run.fingerprint,
        "timings": {},
        "reused_queries": 0,
        "damaged": {},
        "rewritten": [],
        "datasets": {nm: m["stats"] for nm, m in metas.items()},
    }


@contextlib.contextmanager
def _timed(timings: dict, stage: str):
    t0 = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - t0


# ---------------------------------------------------------------------------
# The orchestrator
# ---------------------------------------------------------------------------


def _write_datasets(
    env, opts, run, pools, planned, blocked, gammas, bad: dict, timings: dict, progress
) -> tuple[dict[str, dict], list[str]]:
    """includeData (Alg. 4) for every dataset of ``run``, each written with its metadata.

    A dataset is rewritten only when it is damaged (``bad``) or its arrays changed.
    Returns ``(statistics per dataset, names of the datasets written now)``.
    """
    g_data, g_eval = gammas
    common = common_meta(env, opts, run, g_data, g_eval)
    summary: dict[str, dict] = {}
    rewritten: list[str] = []
    with open_bar(
        progress, desc=f"{run.slug}: includeData + write", total=len(run.specs), unit="dataset"
    ) as bar:
        for j, (name, spec) in enumerate(zip(run.names, run.specs)):
            with _timed(timings, "include"):
                idx = pool_index(run.bits[j], pools.n_u)
                p_prune = resolve_prune(spec, g_data, run.env_name, name)
                # bool prune: exactly Alg. 4's flag (the paper's datasets, as before)
                prune = spec.prune if isinstance(spec.prune, bool) else p_prune
                arrays = dataset_arrays(
                    env,
                    pools,
                    planned.result,
                    idx,
                    prune,
                    run.prune_padding,
                    rng=prune_rng(opts.seed, run.slug, name),
                    keep_last=spec.prune == "keep_last",
                )
            with _timed(timings, "write"):
                stats = dataset_stats(arrays, idx, planned, blocked, p_prune > 0, g_data, g_eval)
                warns = dataset_warnings(run.env_name, name, stats, p_prune > 0, opts.n_max)
                if name in bad or not _unchanged(run.env_dir / name, arrays):
                    write_dataset(
                        run.env_dir / name,
                        arrays,
                        dict(
                            common,
                            name=name,
                            p_nt=spec.p_nt,
                            prune=spec.prune,
                            p_prune=p_prune,
                            stats=stats,
                            sharing=sharing(run, j),
                            warnings=warns,
                        ),
                    )
                    rewritten.append(name)
            summary[name] = stats
            bar.update(1)
    return summary, rewritten


def generate_datasets(
    env,
    options: DataOptions | None,
    out_dir,
    *,
    env_name: str | None = None,
    planner=None,
    progress=True,
    figure: bool = True,
    executor=None,
) -> dict:
    """Generates D0..D3 (``options.datasets``) for one environment (Alg. 2 + 4).

    Writes ``<out_dir>/<env_slug>/env.json``, ``D<i>/`` (:mod:`ntq_jax.data.format`)
    and ``figure.png``. Resumable: a rerun after an interruption reuses the
    completed planning chunks; a complete, matching output is left untouched.

    Args:
        env: the :class:`ntq_jax.Env` (its padding is the data-generation geometry).
        options: the :class:`~ntq_jax.data.options.DataOptions` of this environment
            (None: the defaults, the paper's).
        out_dir: the output root.
        env_name: the environment's name in messages and the folder name; default ``env.name``.
        planner: ``None`` (``options.planner.name``), a planner name, or a callable
            ``(env, queries (K, 2, d), *, padding, seed) -> PlanResult`` (its
            results are verified with :func:`ntq_jax.planners.verify.finalize`).
        progress: progress bars per stage (:func:`ntq_jax.progress.open_bar`; True = tqdm).
        figure: write the PNG figure.
        executor: where the planning chunks run (:mod:`ntq_jax.executors`; None:
            in this process). The outputs do not depend on it (for the
            deterministic planners, byte for byte), and a run interrupted under
            one executor resumes under the other.

    Returns:
        A summary dict: ``env_dir``, ``datasets`` (name -> statistics), ``timings``
        (seconds per stage), ``reused_queries``, ``skipped`` (already complete and
        verified), ``damaged`` (name -> problem, for datasets that had been
        written before but failed verification), ``rewritten`` (the datasets
        written now), ``fingerprint`` and (unless skipped) ``planned_queries``.
    """
    t_all = time.perf_counter()
    opts = DataOptions() if options is None else options
    run = resolve_run(env, opts, out_dir, env_name, planner)
    bad = damaged_datasets(run.env_dir, run.names, run.fingerprint)
    if not bad:
        return _already_complete(run, figure)
    damaged = {nm: why for nm, why in bad.items() if (run.env_dir / nm / "meta.json").exists()}
    work = _open_work(env, opts, run)
    timings: dict[str, float] = {}

    # 1. the query pools U and N
    with _timed(timings, "sample"):
        pools = sample_pools(
            env,
            run.keys,
            run.n_u,
            run.n_nt,
            run.padding,
            opts.n_max,
            progress,
            f"{run.slug}: sample queries",
        )

    recorded = 0  # recorded paths the verification rejected
    if run.record is not None:  # checked and verified before plan_pool reuses them
        recorded = records.seed_work(
            work,
            run.record["record"],
            pools.queries,
            pools.n_u,
            env,
            env_name=run.env_name,
            seed=opts.seed,
            padding=run.padding,
        )[1]

    with ThreadPoolExecutor(1, thread_name_prefix="ntq_jax-gamma") as gamma_thread:
        # 2. gamma_nt of the map, in the background while the planner runs
        gammas = gamma_thread.submit(estimate_gammas, env, run.keys.gamma, opts, run.padding, work)
        # 3. planning (chunked, resumable, verified) and the blocked-ness of every query
        with _timed(timings, "plan"):
            planned = plan_pool(
                env,
                pools.queries,
                run.plan_fn,
                verify=run.verify and run.data_check,
                padding=run.padding,
                seed=opts.seed,
                chunk=opts.chunk,
                work=work,
                progress=progress,
                desc=f"{run.slug}: plan ({run.planner_name})",
                executor=executor,
            )
        _warn_rejected(run, planned, recorded)
        with _timed(timings, "shape"):
            shaped, shaping = shape_paths(
                env,
                planned.result,
                run.data_paths,
                "custom" if run.verify else run.planner_name,
                run.padding,
                run.data_check,
            )
            planned = planned._replace(result=shaped)
        with _timed(timings, "check"):
            blocked = ~steer_to_pairs(
                env.robot, env.world, pools.queries[:, 0], pools.queries[:, 1], run.padding
            )
        with _timed(timings, "gamma_wait"):
            g_data, g_eval, timings["gamma"] = gammas.result()
        with open_bar(progress, desc=f"{run.slug}: gamma_nt", total=1, unit="estimate") as bar:
            bar.update(1)

    # 4. includeData per dataset, written with its metadata (meta.json last)
    summary, rewritten = _write_datasets(
        env, opts, run, pools, planned, blocked, (g_data, g_eval), bad, timings, progress
    )

    # 5. the figure; the datasets are complete: drop every work folder
    if figure:
        with _timed(timings, "figure"):
            write_figure(run)
    shutil.rmtree(run.env_dir / ".work", ignore_errors=True)
    timings["total"] = time.perf_counter() - t_all
    return {
        "env_dir": str(run.env_dir),
        "skipped": False,
        "fingerprint": run.fingerprint,
        "timings": timings,
        "reused_queries": planned.reused,
        "datasets": summary,
        "damaged": damaged,
        "rewritten": rewritten,
        "planned_queries": len(pools.queries),
        "data_paths": shaping,
    }
