#!/usr/bin/env python
"""Benchmark of dataset generation: D0..D3 for one map, end to end, time split by stage.

Examples::

    python benchmarks/bench_data.py                       # point/0, K = 3000, grid A*
    python benchmarks/bench_data.py --planner visgraph
    python benchmarks/bench_data.py --rigid               # + projected BIT* wall time, rigid/0

Each run starts from an empty output folder in a fresh process, so the wall
time includes JAX compilation, query sampling, planning, the path checks,
gamma_nt, includeData, writing and the figure. ``--rigid`` samples the rigid
body's query pools at the paper's size (K = 5000) and projects BIT*'s wall time
(every pooled query runs for the full time budget, ``workers`` in parallel).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default="point/0")
    ap.add_argument("--config", default="configs/point.yaml")
    ap.add_argument("--planner", default=None, help="override planner.name (astar, visgraph)")
    ap.add_argument("--k", type=int, default=3000, help="queries per dataset (paper: 3000)")
    ap.add_argument("--chunk", type=int, default=None, help="planning chunk (default: config)")
    ap.add_argument("--gamma-queries", type=int, default=None)
    ap.add_argument("--out", default=None, help="output root (default: a temporary folder)")
    ap.add_argument("--rigid", action="store_true", help="also project rigid-body BIT* time")
    ap.add_argument("--progress", action="store_true")
    return ap.parse_args(argv)


def load_config(args):
    """The experiment configuration with the command line's overrides."""
    from ntq_jax.experiment import config as C

    sets = [f"data.k_train={args.k}", f"envs=[{args.env}]"]
    if args.planner:
        sets.append(f"planner.name={args.planner}")
    if args.chunk:
        sets.append(f"data.chunk={args.chunk}")
    if args.gamma_queries:
        sets.append(f"data.gamma_queries={args.gamma_queries}")
    return C.load(args.config, sets)


def generate(args, cfg, out: Path, t_import: float) -> dict:
    """Generates D0..D3 into ``out`` (timed), prints the stages; returns the report."""
    import jax

    from ntq_jax import data, make_env
    from ntq_jax.envs import env_slug

    env = make_env(args.env)
    shutil.rmtree(out / env_slug(args.env, env), ignore_errors=True)
    t0 = time.perf_counter()
    from ntq_jax.experiment import config as C

    s = data.generate_datasets(
        env, C.data_options(cfg, args.env), out, env_name=args.env, progress=args.progress
    )
    wall = time.perf_counter() - t0
    report = {
        "env": args.env,
        "planner": cfg.planner.name,
        "k_train": args.k,
        "chunk": cfg.data.chunk,
        "gamma_queries": cfg.data.gamma_queries,
        "planned_queries": s["planned_queries"],
        "import_s": round(t_import, 2),
        "generate_s": round(wall, 2),
        "wall_incl_import_s": round(wall + t_import, 2),
        "stages_s": {k: round(v, 2) for k, v in s["timings"].items()},
        "datasets": {
            k: {
                f: v[f]
                for f in (
                    "queries",
                    "solved",
                    "samples",
                    "fraction_pruned",
                    "mean_waypoints",
                    "blocked_fraction",
                )
            }
            for k, v in s["datasets"].items()
        },
        "gamma_nt": s["datasets"]["D0"]["gamma_nt"],
        "cpus": os.cpu_count(),
        "jax_devices": jax.device_count(),
        "out": str(out),
    }
    print(
        f"{args.env}: D0..D3 with K = {args.k} ({s['planned_queries']} planned queries, "
        f"planner {cfg.planner.name}) in {wall:.1f} s (+ {t_import:.1f} s imports)"
    )
    for k, v in s["timings"].items():
        print(f"  {k:8s} {v:7.2f} s")
    for k, v in report["datasets"].items():
        print(f"  {k}: {v}")
    return report


def rigid_projection() -> dict:
    """Samples rigid/0's query pools at the paper's size and projects BIT*'s wall time."""
    import jax

    from ntq_jax import data, make_env
    from ntq_jax import queries as Q
    from ntq_jax.data.pools import pool_sizes
    from ntq_jax.experiment import config as C

    rcfg = C.load("configs/rigid.yaml")
    renv = make_env("rigid/0")
    kr = rcfg.data.k_train_for("rigid/0")
    k_mix = data.run_keys(rcfg.seed, "rigid_0").mix
    bits = [data.mixing_bits(k_mix, kr, sp.p_nt) for sp in rcfg.data.datasets]
    n_pool = sum(pool_sizes(bits))
    t0 = time.perf_counter()
    Q.sample_nontrivial_queries(
        renv.robot, renv.world, jax.random.PRNGKey(0), kr, renv.padding, rcfg.sampling.n_max
    )
    t_nt = time.perf_counter() - t0
    budget = rcfg.planner.time_budget_for("rigid/0")
    workers = rcfg.planner.workers or os.cpu_count()
    proj = n_pool * budget / workers
    print(
        f"rigid/0 at paper size: {n_pool} pooled queries (instead of {kr * len(bits)}) x "
        f"{budget} s BIT* / {workers} workers = {proj / 3600:.2f} h projected "
        f"(non-trivial sampling of {kr} queries: {t_nt:.1f} s)"
    )
    return {
        "env": "rigid/0",
        "k_train": kr,
        "pooled_queries": n_pool,
        "unshared_queries": kr * len(bits),
        "time_budget_s": budget,
        "workers": workers,
        "projected_bitstar_h": round(proj / 3600, 2),
        "projected_unshared_h": round(kr * len(bits) * budget / workers / 3600, 2),
        "nontrivial_sampling_s": round(t_nt, 2),
    }


def main(argv=None) -> int:
    args = parse_args(argv)

    t_start = time.perf_counter()
    import jax  # noqa: F401  (the imports are timed here; the stages reuse them)

    from ntq_jax import data, make_env  # noqa: F401
    from ntq_jax.envs import env_slug  # noqa: F401
    from ntq_jax.experiment import config as C  # noqa: F401

    t_import = time.perf_counter() - t_start

    cfg = load_config(args)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_data_"))
    report = generate(args, cfg, out, t_import)
    if args.rigid:
        report["rigid_projection"] = rigid_projection()
    print(json.dumps(report))
    if not args.out:
        shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
