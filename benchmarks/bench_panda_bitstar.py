#!/usr/bin/env python
"""BIT*'s data paths on the Panda, recorded in chunks: the reference of the Panda's data path density.

The paper's data planner (OMPL's BIT*, default parameters) at its largest arm's
data-generation budget (6 s per query, the 6-link arm) on non-trivial queries of one
Panda scene (``env.sample_queries(key(seed), n, p_nt=1.0)`` at the data padding),
run in this process on the package's JAX checks (the ``"bitstar_jax"`` planner,
:mod:`ntq_jax.planners.ompl_rrtconnect`, one query after another: pin it to one
core). Chunks of ``--chunk`` queries go to ``<out>/N/plan_<a>_<b>.npz`` in the
format of ``scripts/record_paths.py`` (``queries``, ``paths``, ``lengths``,
``costs``, ``status``, ``rejected``) plus BIT*'s callbacks per query (``n_valid``,
``n_motion``: states and motions it checked in its budget) and ``solve_times``;
each is written atomically, and a rerun of the same command resumes from the
finished chunks (a chunk holding other queries is refused). ``<out>/record.json``
names the scene, planner, options, padding, seed and size.
``benchmarks/bench_panda_data_paths.py`` compares the record with the roadmap's.

    taskset -c 0 python benchmarks/bench_panda_bitstar.py --env panda/table_pick/1 \\
        --n 100 --out results/data_paths/panda/bitstar/table_pick_1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

PLANNER = "bitstar_jax"


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", required=True, help="a Panda scene, e.g. panda/table_pick/1")
    ap.add_argument("--n", type=int, default=100, help="non-trivial queries")
    ap.add_argument("--chunk", type=int, default=10, help="queries per chunk file")
    ap.add_argument("--time-budget", type=float, default=6.0, help="seconds of BIT* per query")
    ap.add_argument("--seed", type=int, default=0, help="query sample and OMPL seeds")
    ap.add_argument("--out", required=True, help="the record's folder")
    ap.add_argument(
        "--profile",
        type=int,
        default=0,
        metavar="K",
        help="instead of recording: time BIT*'s callbacks on the first K queries "
        "and write <out>/callback_profile.json",
    )
    return ap.parse_args(argv)


def profile_callbacks(env, queries, budget, seed, out: Path) -> dict:
    """BIT*'s seconds inside the JAX checker's callbacks, per query, on ``queries``.

    Wraps :class:`JaxChecker`'s ``is_valid`` and ``steer_to`` with timers: the share
    of BIT*'s budget they take is what a native checker would give back to the search.
    """
    from ntq_jax import artifacts
    from ntq_jax.planners import plan
    from ntq_jax.planners.ompl_checker_jax import JaxChecker

    spent = {"is_valid": 0.0, "steer_to": 0.0}
    originals = {k: getattr(JaxChecker, k) for k in spent}

    def timed(name):
        def call(self, *args):
            t = time.perf_counter()
            try:
                return originals[name](self, *args)
            finally:
                spent[name] += time.perf_counter() - t

        return call

    for k in spent:
        setattr(JaxChecker, k, timed(k))
    try:
        plan(env, queries[:1], PLANNER, seed=seed, time_budget=0.2)  # compile outside the timing
        spent.update(is_valid=0.0, steer_to=0.0)
        res = plan(env, queries, PLANNER, seed=seed, time_budget=budget)
    finally:
        for k, fn in originals.items():
            setattr(JaxChecker, k, fn)
    info, k = res.info, len(queries)
    solve = float(info["solve_times"].sum())
    prof = {
        "queries": k,
        "time_budget": budget,
        "solve_seconds_per_query": solve / k,
        "states_checked_per_query": float(info["n_valid_per_query"].mean()),
        "motions_checked_per_query": float(info["n_motion_per_query"].mean()),
        "is_valid_seconds_per_query": spent["is_valid"] / k,
        "steer_to_seconds_per_query": spent["steer_to"] / k,
        "us_per_state_call": 1e6 * spent["is_valid"] / max(info["n_valid_calls"], 1),
        "us_per_motion_call": 1e6 * spent["steer_to"] / max(info["n_motion_calls"], 1),
        "callback_share_of_solve": sum(spent.values()) / solve,
    }
    artifacts.write_json(out / "callback_profile.json", prof)
    print(json.dumps(prof, indent=1))
    return prof


def check_meta(out: Path, meta: dict) -> None:
    """Refuses to resume a record made with other arguments (naming the difference)."""
    path = out / "record.json"
    if path.exists():
        old = json.loads(path.read_text())
        diff = [k for k in meta if old.get(k) != meta[k]]
        if diff:
            raise SystemExit(
                f"error: {out} was recorded with other {', '.join(diff)}: "
                f"{ {k: old.get(k) for k in diff} }"
            )


def record_chunk(env, queries, lo, hi, budget, seed, folder: Path) -> None:
    """Plans rows ``lo..hi`` of ``queries`` with BIT* and writes their chunk file."""
    from ntq_jax import artifacts
    from ntq_jax.planners import plan

    res = plan(env, queries[lo:hi], PLANNER, seed=seed + lo, time_budget=budget)
    info = res.info
    rejected = (info["ompl_status"] == 0) & ~res.solved  # BIT*'s path failed our check
    artifacts.save_npz(
        folder / f"plan_{lo:09d}_{hi:09d}.npz",
        queries=queries[lo:hi],
        paths=res.paths,
        lengths=res.lengths,
        costs=res.costs,
        status=res.status,
        rejected=rejected,
        n_valid=info["n_valid_per_query"],
        n_motion=info["n_motion_per_query"],
        solve_times=info["solve_times"],
    )
    print(
        f"rows {lo}-{hi}: solved {int(res.solved.sum())}/{hi - lo}, states/path "
        f"{res.lengths[res.solved].mean():.2f}, motions/query "
        f"{info['n_motion_per_query'].mean():.0f}, states checked/query "
        f"{info['n_valid_per_query'].mean():.0f}",
        flush=True,
    )


def main(argv=None) -> int:
    args = parse_args(argv)
    import jax

    from ntq_jax import artifacts, make_env

    env = make_env(args.env)
    out = Path(args.out)
    if args.profile:
        q, _ = env.sample_queries(jax.random.key(args.seed), args.n, p_nt=1.0)
        out.mkdir(parents=True, exist_ok=True)
        profile_callbacks(
            env, np.asarray(q, np.float32)[: args.profile], args.time_budget, args.seed, out
        )
        return 0
    meta = {
        "env": args.env,
        "planner": PLANNER,
        "options": {"time_budget": args.time_budget},
        "padding": float(env.padding),
        "seed": args.seed,
        "n": args.n,
        "queries": f"env.sample_queries(jax.random.key({args.seed}), {args.n}, p_nt=1.0)",
    }
    check_meta(out, meta)
    folder = out / "N"
    folder.mkdir(parents=True, exist_ok=True)
    artifacts.write_json(out / "record.json", meta)
    q, _ = env.sample_queries(jax.random.key(args.seed), args.n, p_nt=1.0)
    q = np.asarray(q, np.float32)
    t0 = time.perf_counter()
    for lo in range(0, args.n, args.chunk):
        hi = min(args.n, lo + args.chunk)
        path = folder / f"plan_{lo:09d}_{hi:09d}.npz"
        if path.exists():
            if not np.array_equal(np.load(path)["queries"], q[lo:hi]):
                raise SystemExit(f"error: {path} holds other queries; delete it to plan again")
            continue
        record_chunk(env, q, lo, hi, args.time_budget, args.seed, folder)
    print(f"{args.env}: {args.n} queries recorded in {out} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
