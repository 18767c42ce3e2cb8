#!/usr/bin/env python
"""Benchmark the executors (issue 15): the same BIT* planning chunks, local vs Ray, on one machine.

    python benchmarks/bench_executor.py                     # rigid/0, 40 queries, 0.5 s, chunk 10
    python benchmarks/bench_executor.py --repeats 5 --json results/bench_executor.json

What is timed: :func:`ntq_jax.planners.jobs.plan_pool` over the same pool of
non-trivial queries (BIT* uses its whole budget on each: the work is fixed),
chunk files written by the driver exactly as in ``generate_data.py``.

* ``local``: ``LocalExecutor``, the chunks one after the other in this process,
  each a ``plan_bitstar`` call with ``--workers`` (2) BIT* processes.
* ``local_1call``: the strongest local baseline, the whole pool in ONE
  ``plan_bitstar`` call (its BIT* processes started once; not resumable
  chunk by chunk).
* ``ray``: ``RayExecutor`` on a local Ray instance with ``--cpus`` (2) CPUs, a
  task per chunk (1 CPU, so one BIT* process per task; 2 tasks at a time).

Runs alternate (local, ray, local_1call, local, ray, ...) so that both see the same load
on a shared machine; the medians are reported with the 1-minute load average
before each run. Ray is started once before the first run (``ray.init``, timed
separately) and its workers are warmed by one no-op task per CPU: on a cluster
both are paid once per job, not per chunk. The first ray run (workers importing
the package) is reported apart as ``ray_cold``.

Ray's overhead is measured two ways: head to head (``ray`` wall vs ``local``
wall; the local executor also restarts its BIT* processes for every chunk,
so this favours Ray) and, within each ray run, the share of the CPU slots'
time spent outside the chunks' own computation
(``1 - sum(chunk seconds) / (cpus * wall)``: scheduling, transfers, the
driver's writes and idle slots).

Also measured: Ray's task scheduling latency (a no-op task's submit -> start
and round trip, one at a time, warm workers) and each chunk's compute time
(in the task), the inputs of BENCHMARKS.md's projection to more nodes.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path


def _noop(x):
    return x


def _queries(env, n, seed):
    import jax
    import numpy as np

    q, _ = env.sample_queries(jax.random.key(seed), n, p_nt=1.0)
    return np.asarray(q, np.float32)[:n]


def _run(env, pool, executor, planner, chunk: int, seed: int) -> tuple[float, list[float]]:
    from ntq_jax.planners.jobs import plan_pool

    work = Path(tempfile.mkdtemp(prefix="bench_executor-"))
    try:
        t0 = time.perf_counter()
        out = plan_pool(
            env,
            pool,
            planner,
            verify=False,
            padding=env.padding,
            seed=seed,
            chunk=chunk,
            work=work,
            progress=False,
            executor=executor,
        )
        wall = time.perf_counter() - t0
        assert len(list(work.glob("plan_*.npz"))) == -(-len(pool) // chunk)
        return wall, out
    finally:
        shutil.rmtree(work, ignore_errors=True)


def parse_args(argv):
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--env", default="rigid/0")
    ap.add_argument("--queries", type=int, default=40)
    ap.add_argument("--budget", type=float, default=0.5, help="BIT* seconds per query")
    ap.add_argument("--chunk", type=int, default=10, help="queries per chunk (task)")
    ap.add_argument("--workers", type=int, default=2, help="BIT* processes of the local run")
    ap.add_argument("--cpus", type=int, default=2, help="CPUs of the local Ray instance")
    ap.add_argument("--repeats", type=int, default=3, help="warm runs per executor")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="write the figures to this file")
    return ap.parse_args(argv)


def start_ray(args):
    """Starts the local Ray instance and warms its workers: the executor and both timings."""
    import ray

    from ntq_jax.executors import RayExecutor

    t0 = time.perf_counter()
    ray.init(
        num_cpus=args.cpus,
        include_dashboard=False,
        configure_logging=False,
        runtime_env={"env_vars": {"JAX_PLATFORMS": "cpu"}},
    )
    ray_init = time.perf_counter() - t0
    rex = RayExecutor()
    t0 = time.perf_counter()
    list(rex.imap_unordered(_noop, [(i,) for i in range(args.cpus)]))  # start the workers
    warm_workers = time.perf_counter() - t0
    return rex, ray_init, warm_workers


def alternating_runs(args, env, pool, planner, local, rex) -> dict:
    """The runs, alternating local, ray, local_1call: walls, loads and the ray runs' details."""
    rows: dict[str, list] = {"local": [], "local_1call": [], "ray": [], "ray_cold": []}
    loads: dict[str, list] = {k: [] for k in rows}
    chunk_seconds: list[float] = []
    latencies: list[float] = []
    busy: list[float] = []  # per warm ray run: sum of chunk seconds / (cpus * wall)
    order = ["ray_cold"] + ["local", "ray", "local_1call"] * args.repeats
    for kind in order:
        loads[kind].append(os.getloadavg()[0])
        if kind.startswith("local"):
            chunk = args.queries if kind == "local_1call" else args.chunk
            wall, _ = _run(env, pool, local, planner, chunk, args.seed)
        else:
            rex.latencies.clear()
            rex.task_seconds.clear()
            wall, _ = _run(env, pool, rex, planner, args.chunk, args.seed)
            if kind == "ray":
                chunk_seconds += rex.task_seconds
                latencies += rex.latencies
                busy.append(sum(rex.task_seconds) / (args.cpus * wall))
        rows[kind].append(wall)
        print(f"{kind:9s} {wall:7.2f} s   load {loads[kind][-1]:.2f}", flush=True)
    return {
        "rows": rows,
        "loads": loads,
        "chunk_seconds": chunk_seconds,
        "latencies": latencies,
        "busy": busy,
    }


def noop_latency(rex) -> tuple[list[float], list[float]]:
    """Round trip and submit -> start seconds of 100 no-op tasks, one at a time, warm workers."""
    rt, start = [], []
    for i in range(100):
        rex.latencies.clear()
        t0 = time.perf_counter()
        list(rex.imap_unordered(_noop, [(i,)]))
        rt.append(time.perf_counter() - t0)
        start.append(rex.latencies[0])
    return rt, start


def figures(args, argv, runs: dict, rt, start, ray_init, warm_workers) -> dict:
    """The JSON record of the benchmark."""
    rows, busy, chunk_seconds = runs["rows"], runs["busy"], runs["chunk_seconds"]
    med = {k: statistics.median(v) for k, v in rows.items() if v}
    ideal = args.queries * args.budget / args.cpus
    return {
        "command": "python benchmarks/bench_executor.py " + " ".join(argv or sys.argv[1:]),
        "env": args.env,
        "queries": args.queries,
        "budget": args.budget,
        "chunk": args.chunk,
        "workers_local": args.workers,
        "ray_cpus": args.cpus,
        "repeats": args.repeats,
        "walls": rows,
        "load_1min": runs["loads"],
        "median_wall": med,
        "ray_minus_local_fraction": (med["ray"] - med["local"]) / med["ray"],
        "ray_minus_local_1call_fraction": (med["ray"] - med["local_1call"]) / med["ray"],
        # the share of the ray run's CPU-slots time not spent inside a chunk (scheduling,
        # argument and result transfer, the driver's writes, idle slots at the end)
        "ray_overhead_fraction_median": 1.0 - statistics.median(busy),
        "ray_overhead_fractions": [1.0 - b for b in busy],
        "chunk_submit_to_start_s": runs["latencies"],
        "ideal_wall": ideal,
        "ray_init_seconds": ray_init,
        "ray_warm_workers_seconds": warm_workers,
        "chunk_seconds_median": statistics.median(chunk_seconds),
        "chunk_seconds": chunk_seconds,
        "noop_submit_to_start_ms_median": 1e3 * statistics.median(start),
        "noop_round_trip_ms_median": 1e3 * statistics.median(rt),
        "noop_round_trip_ms_p90": 1e3 * sorted(rt)[int(0.9 * len(rt))],
        "cpu_count": os.cpu_count(),
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("JAX_PLATFORMS", "cpu")

    import ray

    from ntq_jax import make_env
    from ntq_jax.executors import LocalExecutor
    from ntq_jax.planners.jobs import resolve_planner

    env = make_env(args.env)
    pool = _queries(env, args.queries, args.seed)
    planner, _ = resolve_planner("bitstar", {"time_budget": args.budget, "workers": args.workers})
    local = LocalExecutor()
    rex, ray_init, warm_workers = start_ray(args)
    runs = alternating_runs(args, env, pool, planner, local, rex)
    rt, start = noop_latency(rex)
    ray.shutdown()

    res = figures(args, argv, runs, rt, start, ray_init, warm_workers)
    print(json.dumps({k: v for k, v in res.items() if k not in ("chunk_seconds",)}, indent=1))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
