#!/usr/bin/env python
"""Benchmark the OMPL BIT* bridge: batch throughput and the cost of BIT*'s Python callbacks.

    python benchmarks/bench_bitstar.py                       # rigid/0, 8 queries, 1 s budget
    python benchmarks/bench_bitstar.py --env nlink/4 --queries 8 --budget 2

1. Throughput: ``plan_bitstar`` on the same non-trivial queries (no straight
   connection, so BIT* uses its whole budget) with 1 and 2 worker processes.
   Queries/s is reported on wall time including the workers' start (spawn,
   importing JAX and OMPL) and without it.
2. Callbacks, in this process, the same queries and budget: BIT* with the
   bridge's Python ``MotionValidator`` (the package's discretised steer_to,
   one NumPy/Python call per edge) vs OMPL's default discrete motion
   validator calling the Python state-validity callback for every
   intermediate state (at the same resolution). Per second of planning:
   Python callbacks, edges checked, and BIT*'s final cost.
3. Per-call costs: the NumPy checker vs calling the jitted JAX kernel for
   one state / one edge from Python.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time


def _nontrivial_queries(env, n, seed):
    import jax
    import numpy as np

    q, _ = env.sample_queries(jax.random.key(seed), n, p_nt=1.0)
    q = np.asarray(q)
    if len(q) < n:
        raise SystemExit(f"{env.name}: only {len(q)} non-trivial queries found")
    return q


def _per_call_us(fn, args, repeat=3):
    best = float("inf")
    for _ in range(repeat):
        n = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 0.3:
            for a in args:
                fn(*a)
            n += len(args)
        best = min(best, (time.perf_counter() - t0) / n * 1e6)
    return best


def parse_args(argv):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--env", default="rigid/0", help="preset or JSON map (default rigid/0)")
    ap.add_argument("--queries", type=int, default=8, help="number of queries (default 8)")
    ap.add_argument("--budget", type=float, default=1.0, help="seconds per query (default 1)")
    ap.add_argument(
        "--workers",
        type=int,
        nargs="+",
        default=[1, 2],
        help="worker counts to compare (default 1 2)",
    )
    ap.add_argument(
        "--callback-queries",
        type=int,
        default=3,
        help="queries for the in-process callback comparison (default 3)",
    )
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args(argv)


def throughput(env, q, args) -> None:
    """Table 1: ``plan_bitstar`` on the queries with each worker count of ``--workers``."""
    from ntq_jax.planners.ompl_bridge import plan_bitstar
    from ntq_jax.types import PlanStatus

    print("\n## Throughput (plan_bitstar, spawn workers)\n")
    print(
        "| workers | solved | wall s | worker start s | mean solve s | queries/s |"
        " queries/s w/o start | mean cost |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for w in args.workers:
        res = plan_bitstar(env, q, time_budget=args.budget, workers=w, seed=args.seed)
        wall, start = res.info["wall_time"], res.info["startup_time"]
        ok = res.status == PlanStatus.SOLVED
        print(
            f"| {w} | {ok.sum()}/{len(q)} | {wall:.2f} | {start:.2f} | "
            f"{res.info['solve_times'].mean():.3f} | {len(q) / wall:.2f} | "
            f"{len(q) / max(wall - start, 1e-9):.2f} | "
            f"{res.costs[ok].mean() if ok.any() else float('nan'):.3f} |",
            flush=True,
        )


def callbacks(env, q, args):
    """Table 2: Python callbacks per second of BIT* with either motion validator; the checker."""
    from ntq_jax.planners.ompl_bridge import query_seeds
    from ntq_jax.planners.ompl_checker import NumpyChecker
    from ntq_jax.planners.ompl_worker import OmplProblem

    print("\n## Python callbacks during BIT* (in process, same queries and budget)\n")
    checker = NumpyChecker.from_env(env)
    seeds = query_seeds(args.seed, len(q))
    k = min(args.callback_queries, len(q))
    print(
        "| motion validator | validity calls/s | motion calls/s | Python callbacks/s |"
        " edges checked/s | callbacks per edge | mean cost |"
    )
    print("|---|---|---|---|---|---|---|")
    for mv in ("python", "ompl"):
        prob = OmplProblem(checker, args.budget, motion_validator=mv)
        tot = {"n_valid": 0, "n_motion": 0, "n_edges": 0, "solve_time": 0.0}
        costs = []
        for i in range(k):
            r = prob.solve(q[i, 0], q[i, 1], seed=int(seeds[i]))
            for key in tot:
                tot[key] += r[key]
            costs.append(r["planner_cost"])
        t = tot["solve_time"]
        calls = tot["n_valid"] + tot["n_motion"]
        name = (
            "Python steer_to MotionValidator"
            if mv == "python"
            else "OMPL DiscreteMotionValidator + Python isValid"
        )
        print(
            f"| {name} | {tot['n_valid'] / t:,.0f} | {tot['n_motion'] / t:,.0f} | "
            f"{calls / t:,.0f} | {tot['n_edges'] / t:,.0f} | "
            f"{calls / max(tot['n_edges'], 1):.1f} | {statistics.mean(costs):.3f} |",
            flush=True,
        )
    return checker


def per_call(env, checker) -> None:
    """Table 3: microseconds per state / per edge, the NumPy checker vs the jitted JAX kernels."""
    import numpy as np

    print("\n## Per call (microseconds)\n")
    states = np.asarray(env.sample_states(__import__("jax").random.key(7), 64), np.float64)
    pairs = list(zip(states[:32], states[32:]))
    one = [(s,) for s in states]
    env.is_valid(states[:1])
    env.steer_to(states[:1], states[1:2])
    jax_valid = _per_call_us(lambda s: bool(env.is_valid(s[None])[0]), one[:16], 1)
    np_valid = _per_call_us(checker.is_valid, one)
    jax_steer = _per_call_us(lambda a, b: bool(env.steer_to(a[None], b[None])[0]), pairs[:8], 1)
    np_steer = _per_call_us(checker.steer_to, pairs)
    print("| check | NumPy checker | jitted JAX, one call per item | ratio |")
    print("|---|---|---|---|")
    print(
        f"| one state (is_valid) | {np_valid:.1f} | {jax_valid:.1f} | {jax_valid / np_valid:.0f}x |"
    )
    print(
        f"| one edge (steer_to, random valid pairs) | {np_steer:.1f} | {jax_steer:.1f} | "
        f"{jax_steer / np_steer:.0f}x |"
    )


def main(argv=None) -> int:
    args = parse_args(argv)

    import ntq_jax
    from ntq_jax.planners.ompl_bridge import plan_bitstar

    env = ntq_jax.make_env(args.env)
    q = _nontrivial_queries(env, args.queries, args.seed)
    print(
        f"# BIT* bridge on {env.name}: {len(q)} non-trivial queries, {args.budget:g} s budget "
        f"per query (full budget, best solution kept)"
    )

    # warm-up: compiles the parent's jitted checks (start/goal validity, path check) once
    plan_bitstar(env, q[:1], time_budget=0.05, workers=1, stop_on_first=True)
    throughput(env, q, args)
    checker = callbacks(env, q, args)
    per_call(env, checker)
    return 0


if __name__ == "__main__":
    sys.exit(main())
