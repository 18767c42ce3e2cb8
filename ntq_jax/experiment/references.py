"""Test queries and reference plans of an environment (:mod:`ntq_jax.experiment.evaluate`).

:func:`test_queries`: ``K_test`` fresh uniform and ``K_test`` fresh non-trivial test
queries, sampled at ``eval.query_padding`` with keys derived from the run seed with
:data:`EVAL_TAG` (a tag no other stage uses, so they are disjoint from the training
queries). :func:`reference_plans`: their classical reference plans (the map's planner
on the evaluation geometry, padding 0, at the evaluation budget) and, for point
robots, the exact visibility graph's optimum; :func:`reuse_roadmaps` lets the
reference planner reuse the roadmaps the data planner built. Both are cached in the
environment's evaluation folder (``queries.npz``, ``reference.npz``), which several
runs can share.
"""

from __future__ import annotations

import shutil
import time
import zlib
from pathlib import Path
from typing import Callable

import jax
import numpy as np

from ntq_jax import artifacts
from ntq_jax.experiment import config as C
from ntq_jax.planners import plan, visgraph
from ntq_jax.planners.jobs import plan_pool, planner_options, resolve_planner
from ntq_jax.types import QUERY_KINDS

EVAL_TAG = 0x7E57  # key tag of the test queries (training uses other streams)


def _tag(slug: str) -> int:
    return zlib.crc32(slug.encode()) & 0x7FFFFFFF


def test_queries(env, cfg, slug: str, out_dir: Path) -> dict[str, np.ndarray]:
    """``{"uniform": (K, 2, d), "nontrivial": (K, 2, d)}``, cached in ``queries.npz``."""
    ev = cfg.eval
    qpad = env.resolve_padding(ev.query_padding)
    fp = artifacts.fingerprint(slug, ev.k_test, qpad, cfg.seed, cfg.sampling.n_max, env.to_json())

    def compute():
        key = jax.random.fold_in(jax.random.fold_in(jax.random.key(cfg.seed), EVAL_TAG), _tag(slug))
        out = {"query_padding": qpad}
        for i, kind in enumerate(QUERY_KINDS):
            q, _ = env.sample_queries(
                jax.random.fold_in(key, i),
                ev.k_test,
                float(i),
                padding=qpad,
                n_max=cfg.sampling.n_max,
            )
            out[kind] = np.asarray(q, np.float32)
        return out

    got = artifacts.compute_or_load(Path(out_dir) / "queries.npz", fp, compute)
    return {k: got[k] for k in QUERY_KINDS}


def reuse_roadmaps(source, out_dir: Path) -> int:
    """Copies the roadmaps the data planner built (``<source>/roadmap_*.npz``, e.g. a
    dataset folder's ``roadmap/``) into the reference's roadmap folder
    ``<out_dir>/roadmap``; returns how many were copied.

    A roadmap file is named and checked by the fingerprint of its map, robot, padding
    and settings (:func:`ntq_jax.planners.roadmap.roadmap_for`), so the reference
    planner uses a copied one only where it would build the same roadmap (the data
    and evaluation paddings equal, as on the Panda's scenes, padding 0) and builds
    its own otherwise. Files already there are kept."""
    if source is None or not Path(source).is_dir():
        return 0
    dest = Path(out_dir) / "roadmap"
    copied = 0
    for f in sorted(Path(source).glob("roadmap_*.npz")):
        if not (dest / f.name).exists():
            artifacts.write_bytes(dest / f.name, f.read_bytes())
            copied += 1
    return copied


def reference_plans(
    env,
    cfg,
    env_name: str,
    slug: str,
    queries: dict,
    out_dir: Path,
    planner: Callable | None = None,
    executor=None,
) -> dict:
    """Reference (and, for point robots, optimum) costs and paths on padding 0, cached.

    ``planner`` (optional) replaces ``cfg.planner``: a callable ``(env, q, *,
    padding, seed)`` returning a :class:`ntq_jax.types.PlanResult`. The optimum is
    the visibility graph's (``ntq_jax.plan(env, q, "visgraph", padding=0.0)``), omitted for
    maps with more than :data:`ntq_jax.planners.visgraph.MAX_OBSTACLES` obstacles (users'
    grid maps: the all-pairs graph would not fit; the cost ratios to the optimum are then
    absent from the metrics).

    ``executor`` (:mod:`ntq_jax.executors`; None or local: one call in this
    process, as always): with Ray the config's planner runs in chunks of
    ``data.chunk`` queries as tasks, resumable in ``<out_dir>/.work/`` (the
    chunks written by the driver, :func:`ntq_jax.planners.jobs.plan_pool`).
    A* (grid, visgraph, roadmap) give the same references either way; BIT*'s
    queries then get their chunks' seeds (it is not reproducible anyway).
    """
    name = (
        cfg.planner.name_for(env_name)
        if planner is None
        else getattr(planner, "__name__", "custom")
    )
    fp = artifacts.fingerprint(
        slug,
        name,
        cfg.planner,
        cfg.eval.motion_check,
        {k: artifacts.array_digest(v) for k, v in queries.items()},
        {k: len(v) for k, v in queries.items()},
    )

    def compute():
        out: dict = {"planner": name}
        for kind in QUERY_KINDS:
            q = queries[kind]
            t0 = time.perf_counter()
            res = _run_reference(
                env,
                q,
                cfg,
                env_name,
                planner,
                out_dir,
                executor,
                Path(out_dir) / ".work" / f"reference_{fp[:16]}_{kind}",
            )
            out[f"{kind}_seconds"] = time.perf_counter() - t0
            out[f"{kind}_costs"] = np.asarray(res.costs, np.float64)
            out[f"{kind}_status"] = np.asarray(res.status, np.int8)
            out[f"{kind}_paths"] = np.asarray(res.paths, np.float32)
            out[f"{kind}_lengths"] = np.asarray(res.lengths, np.int32)
            if env.robot.kind == "point" and (
                env.world.num_boxes + env.world.num_discs <= visgraph.MAX_OBSTACLES
            ):
                opt = plan(env, q, "visgraph", padding=0.0)
                out[f"{kind}_opt_costs"] = np.asarray(opt.costs, np.float64)
        return out

    got = artifacts.compute_or_load(Path(out_dir) / "reference.npz", fp, compute)
    shutil.rmtree(Path(out_dir) / ".work", ignore_errors=True)
    return got


def _run_reference(
    env, q, cfg, env_name, planner, out_dir: Path, executor=None, work: Path | None = None
):
    if planner is not None:
        return planner(env, q, padding=0.0, seed=cfg.seed)
    name = cfg.planner.name_for(env_name)
    settings = C.planner_settings(cfg, env_name)
    run, _ = resolve_planner(
        name, planner_options(settings, name, evaluation=True), cache_dir=Path(out_dir) / "roadmap"
    )
    if executor is None or executor.name == "local":
        return run(env, q, padding=0.0, seed=cfg.seed)
    work.mkdir(parents=True, exist_ok=True)
    return plan_pool(
        env,
        q,
        run,
        verify=False,
        padding=0.0,
        seed=cfg.seed,
        chunk=cfg.data.chunk,
        work=work,
        progress=False,
        executor=executor,
    ).result
