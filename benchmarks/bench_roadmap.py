#!/usr/bin/env python
"""Benchmark the multi-query roadmap planner against BIT* at the paper's data budget.

    python benchmarks/bench_roadmap.py --stage bitstar          # BIT* references (~27 min, resumable)
    python benchmarks/bench_roadmap.py --stage roadmap --milestones 20000
    python benchmarks/bench_roadmap.py --stage report           # summary.md from the saved files
    python benchmarks/bench_roadmap.py --stage pool --milestones 20000    # 10,000-query pools
    python benchmarks/bench_roadmap.py --stage memory           # peak RSS, 50,000 milestones
    python benchmarks/bench_roadmap.py --stage all --env rigid/0
    python benchmarks/bench_roadmap.py --stage bitstar --budget-scale 0.05 --queries 4 --out /tmp/br

Per map (default rigid/0, rigid/3, nlink/4, nlink/6; ``--env`` repeatable), the
same ``--queries`` (200) non-trivial queries at the environment's own (data)
padding, ``env.sample_queries(jax.random.key(SEED), n, p_nt=1.0)``; their
sha256 is stored with every result, so results of different queries are never
compared (and the count of the sampler's trivial fallback, kind 2, is reported).

Stages (each writes to ``--out``, default ``results/bench_roadmap/`` of the repository):

``bitstar``
    ``ntq_jax.plan(env, q, "bitstar", time_budget=B, workers=2, seed=0)``, B the
    paper's data budget (3 s rigid body, 4 s nlink/4, 6 s nlink/6; times
    ``--budget-scale``) -> ``<map>_bitstar.json``: per-query status and cost,
    wall time, load average before/after, cpu count, git revision, date. A map
    whose file holds the same queries (hash), budget, workers and seed is skipped,
    so an interrupted run resumes at the next map (``--force`` redoes it).
``roadmap``
    ``ntq_jax.plan(env, q, "roadmap", seed=0, **options)`` with the options given
    here (``--milestones``, ``--k``, ``--cache-dir``, any ``--opt KEY=VALUE``),
    timed in this process (compilation included; the build/query split of
    ``res.info`` when present) -> ``<map>_roadmap.json``. ``--roadmap-repeats N``
    plans the same queries N times and records each wall time (the first is cold).
``report``
    Reads both files of every map; prints and writes ``summary.md``: success ratio
    of each, per-query cost ratio roadmap/BIT* on the queries both solved (median,
    p90, count), wall time per query of each, and the goals (success >= BIT*'s,
    median <= 1.0, p90 <= 1.05; pool time; roadmap memory).
``pool``
    Throughput: a paper-size pool (``--pool-size`` 10,000 = half uniform, half
    non-trivial, sampled as data generation samples its pools:
    ``data.pools.sample_pools`` with ``run_keys(0, slug)``) planned with the
    roadmap in a child process (its peak RSS measured) for rigid/0 and nlink/6
    (``--pool-env``) -> ``<map>_pool.json``. Goals: <= 5 min rigid/0, <= 10 min nlink/6.
``memory``
    Peak RSS of a child process that plans ``--queries`` queries with a
    ``--memory-milestones`` (50,000) roadmap, on the pool stage's maps
    -> ``<map>_memory.json``. Goal < 2 GB.

Until ``"roadmap"`` is registered, its stages stop with one line naming the
missing planner (``report`` still runs and shows the roadmap as missing).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

from bench_roadmap_report import MEMORY_GOAL_BYTES, WORKERS, slug, stage_report
from common import LoadSampler, children_cpu, finite_or_none, load_json, loadavg, machine

ROOT = Path(__file__).resolve().parents[1]
SEED = 0  # the query key: jax.random.key(SEED)
DEFAULT_ENVS = ("rigid/0", "rigid/3", "nlink/4", "nlink/6")
POOL_ENVS = ("rigid/0", "nlink/6")
# the paper's BIT* budget for data generation (seconds per query)
DATA_BUDGET = {"rigid_body": 3.0, ("nlink", 2): 2.0, ("nlink", 4): 4.0, ("nlink", 6): 6.0}
POOL_GOAL_S = {"rigid/0": 300.0, "nlink/6": 600.0}


class StageError(Exception):
    """A stage cannot run (one line for the user, no traceback)."""


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def data_budget(env) -> float:
    kind = env.robot.kind if hasattr(env.robot, "kind") else type(env.robot).__name__
    if kind == "rigid_body":
        return DATA_BUDGET["rigid_body"]
    if kind == "nlink":
        key = ("nlink", env.dim)
        if key in DATA_BUDGET:
            return DATA_BUDGET[key]
    raise StageError(f"{env.name}: no paper data budget for robot {kind!r} (dim {env.dim})")


def query_hash(q) -> str:
    import numpy as np

    a = np.ascontiguousarray(q, np.float32)
    h = hashlib.sha256(f"{a.shape}|float32|".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def bench_queries(env, n: int):
    """The benchmark's queries: ``(q (n, 2, d) float32, kind (n,) int8, sha256)``."""
    import jax
    import numpy as np

    q, kind = env.sample_queries(jax.random.key(SEED), n, p_nt=1.0)
    q, kind = np.asarray(q, np.float32), np.asarray(kind)
    return q, kind, query_hash(q)


def info_scalars(info: dict) -> dict:
    """The JSON-able scalar entries of a PlanResult's info (times, counts)."""
    import numpy as np

    out = {}
    for k, v in (info or {}).items():
        if isinstance(v, (bool, np.bool_)):
            out[k] = bool(v)
        elif isinstance(v, (int, np.integer)):
            out[k] = int(v)
        elif isinstance(v, (float, np.floating)):
            out[k] = finite_or_none(v)
        elif isinstance(v, str) and len(v) < 200:
            out[k] = v
    return out


def result_lists(res) -> dict:
    import numpy as np

    from ntq_jax.types import STATUS_NAMES

    st = np.asarray(res.status).astype(int)
    return {
        "status": st.tolist(),
        "cost": [finite_or_none(c) for c in np.asarray(res.costs, np.float64)],
        "waypoints": np.asarray(res.lengths).astype(int).tolist(),
        "status_counts": {
            STATUS_NAMES.get(int(s), str(s)): int(c)
            for s, c in zip(*np.unique(st, return_counts=True))
        },
    }


def require_roadmap() -> None:
    from ntq_jax.planners import available_planners

    if "roadmap" not in available_planners():
        raise StageError(
            "planner 'roadmap' is not registered in this ntq_jax "
            f"(available: {', '.join(available_planners())}); "
            "its stages run once it lands"
        )


def roadmap_options(args) -> dict:
    opts = {}
    if args.milestones is not None:
        opts["milestones"] = args.milestones
    if args.k is not None:
        opts["k"] = args.k
    if args.cache_dir is not None:
        opts["cache_dir"] = args.cache_dir
    for kv in args.opt:
        if "=" not in kv:
            raise StageError(f"--opt {kv!r}: expected KEY=VALUE")
        k, v = kv.split("=", 1)
        try:
            opts[k] = json.loads(v)
        except ValueError:
            opts[k] = v
    return opts


# ---------------------------------------------------------------------------
# stages
# ---------------------------------------------------------------------------


def stage_bitstar(env, args, out: Path) -> None:
    import numpy as np

    import ntq_jax
    from ntq_jax import artifacts

    budget = round(data_budget(env) * args.budget_scale, 6)
    q, kind, qhash = bench_queries(env, args.queries)
    path = out / f"{slug(env.name)}_bitstar.json"
    old = load_json(path)
    key = {"query_sha256": qhash, "time_budget": budget, "workers": WORKERS, "seed": 0}
    if old is not None and not args.force and all(old.get(k) == v for k, v in key.items()):
        print(f"  {env.name}: {path.name} exists for these queries and budget; skipped", flush=True)
        return
    n_fb = int((kind != ntq_jax.NON_TRIVIAL).sum())
    eta = len(q) * budget / WORKERS
    print(
        f"  {env.name}: BIT* {budget:g} s x {len(q)} queries / {WORKERS} workers "
        f"(~{eta / 60:.1f} min), load {loadavg()}",
        flush=True,
    )
    if n_fb:
        print(
            f"  {env.name}: {n_fb} of {len(q)} queries are the sampler's trivial fallback (kind 2)",
            flush=True,
        )
    load0 = loadavg()
    cpu0 = children_cpu()
    t0 = time.perf_counter()
    with LoadSampler() as sampler:
        res = ntq_jax.plan(env, q, "bitstar", time_budget=budget, workers=WORKERS, seed=0)
    wall = time.perf_counter() - t0
    cpu = children_cpu() - cpu0
    load1 = loadavg()
    info = res.info
    rec = {
        "env": env.name,
        "stage": "bitstar",
        "planner": "bitstar",
        "n_queries": len(q),
        "query_seed": SEED,
        "padding": float(env.padding),
        "n_nontrivial": int((kind == ntq_jax.NON_TRIVIAL).sum()),
        "n_fallback": n_fb,
        **key,
        "budget_scale": args.budget_scale,
        "wall_time": round(wall, 3),
        "wall_per_query": round(wall / len(q), 4),
        "startup_time": finite_or_none(info.get("startup_time", float("nan"))),
        "mean_solve_time": finite_or_none(np.mean(info["solve_times"]))
        if "solve_times" in info
        else None,
        # CPU seconds of the (exited) worker processes: vs len(q) x budget, the share of
        # the cores BIT* actually got (it runs on wall-clock time, so load costs it samples);
        # includes each worker's start-up (importing JAX and OMPL, a few CPU seconds)
        "workers_cpu_time": round(cpu, 2),
        "workers_cpu_per_budget": round(cpu / (len(q) * budget), 3),
        "worker_deaths": int(info.get("worker_deaths", 0)),
        "n_errors": len(info.get("errors", {}) or {}),
        "n_rejected": int(info.get("rejected", 0)),
        "loadavg_before": load0,
        "loadavg_after": load1,
        "loadavg_during": sampler.summary(),  # 1-minute figure, sampled every 15 s
        **machine(),
        **result_lists(res),
    }
    artifacts.write_json(path, rec)
    ok = res.status == ntq_jax.PlanStatus.SOLVED
    print(
        f"  {env.name}: BIT* solved {ok.sum()}/{len(q)}, median cost "
        f"{np.median(res.costs[ok]) if ok.any() else float('nan'):.4f}, wall {wall:.1f} s, "
        f"workers' CPU {cpu:.0f} s = {cpu / (len(q) * budget):.2f} x queries x budget, "
        f"load {load0} -> {load1} -> {path}",
        flush=True,
    )


def stage_roadmap(env, args, out: Path) -> None:
    import ntq_jax
    from ntq_jax import artifacts

    require_roadmap()
    opts = roadmap_options(args)
    q, kind, qhash = bench_queries(env, args.queries)
    path = out / f"{slug(env.name)}_roadmap.json"
    print(f"  {env.name}: roadmap {opts} on {len(q)} queries, load {loadavg()}", flush=True)
    walls, infos, res = [], [], None
    load0 = loadavg()
    for _ in range(max(1, args.roadmap_repeats)):
        t0 = time.perf_counter()
        res = ntq_jax.plan(env, q, "roadmap", seed=0, **opts)
        walls.append(time.perf_counter() - t0)
        infos.append(info_scalars(res.info))
    load1 = loadavg()
    rec = {
        "env": env.name,
        "stage": "roadmap",
        "planner": "roadmap",
        "options": opts,
        "n_queries": len(q),
        "query_seed": SEED,
        "padding": float(env.padding),
        "n_nontrivial": int((kind == ntq_jax.NON_TRIVIAL).sum()),
        "n_fallback": int((kind != ntq_jax.NON_TRIVIAL).sum()),
        "query_sha256": qhash,
        "seed": 0,
        "wall_time": round(walls[0], 3),
        "wall_per_query": round(walls[0] / len(q), 5),
        "wall_times": [round(w, 3) for w in walls],
        # build vs query: the planner's own split when its info has one, else wall - build
        "build_time": infos[0].get("build_time"),
        "query_time": infos[0].get(
            "query_time",
            round(walls[0] - infos[0]["build_time"], 3)
            if infos[0].get("build_time") is not None
            else None,
        ),
        "info": infos[0],
        "info_repeats": infos[1:],
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "loadavg_before": load0,
        "loadavg_after": load1,
        **machine(),
        **result_lists(res),
    }
    artifacts.write_json(path, rec)
    ok = res.status == ntq_jax.PlanStatus.SOLVED
    print(
        f"  {env.name}: roadmap solved {ok.sum()}/{len(q)}, wall {walls[0]:.2f} s "
        f"({', '.join(f'{w:.2f}' for w in walls)}) -> {path}",
        flush=True,
    )


def _child(args) -> int:
    """``--child pool|memory``: plans in this (fresh) process and reports its peak RSS."""
    import numpy as np

    import ntq_jax
    from ntq_jax import artifacts
    from ntq_jax.data.pools import run_keys, sample_pools

    env = ntq_jax.make_env(args.env[0])
    require_roadmap()
    opts = roadmap_options(args)
    rss_start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t0 = time.perf_counter()
    if args.child == "pool":
        half = args.pool_size // 2
        pools = sample_pools(
            env,
            run_keys(0, slug(env.name)),
            args.pool_size - half,
            half,
            float(env.padding),
            10_000,
        )
        q, kind = pools.queries, pools.kind
    else:
        q, kind, _ = bench_queries(env, args.queries)
        opts["milestones"] = args.memory_milestones
    t_sample = time.perf_counter() - t0
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    load0 = loadavg()
    t0 = time.perf_counter()
    res = ntq_jax.plan(env, q, "roadmap", seed=0, **opts)
    wall = time.perf_counter() - t0
    ok = res.status == ntq_jax.PlanStatus.SOLVED
    rec = {
        "env": env.name,
        "stage": args.child,
        "planner": "roadmap",
        "options": opts,
        "n_queries": len(q),
        "n_uniform": int((kind == ntq_jax.UNIFORM).sum()),
        "n_nontrivial": int((kind == ntq_jax.NON_TRIVIAL).sum()),
        "n_fallback": int((kind == ntq_jax.NT_EXHAUSTED).sum()),
        "query_sha256": query_hash(q),
        "padding": float(env.padding),
        "sample_time": round(t_sample, 3),
        "wall_time": round(wall, 3),
        "wall_per_query": round(wall / len(q), 6),
        "solved": int(ok.sum()),
        "success": float(ok.mean()),
        "mean_cost_solved": finite_or_none(np.mean(res.costs[ok])) if ok.any() else None,
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "rss_peak_before_plan_bytes": rss_before,
        "rss_peak_after_imports_bytes": rss_start,
        "info": info_scalars(res.info),
        "loadavg_before": load0,
        "loadavg_after": loadavg(),
        **machine(),
    }
    if args.child == "pool":
        rec["goal_seconds"] = POOL_GOAL_S.get(env.name)
    else:
        rec["goal_peak_rss_bytes"] = MEMORY_GOAL_BYTES
    artifacts.write_json(args.child_out, rec)
    return 0


def stage_child(env, args, out: Path, which: str) -> None:
    require_roadmap()
    path = out / f"{slug(env.name)}_{which}.json"
    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--child",
        which,
        "--child-out",
        str(path),
        "--env",
        env.name,
        "--queries",
        str(args.queries),
        "--pool-size",
        str(args.pool_size),
        "--memory-milestones",
        str(args.memory_milestones),
    ]
    for name in ("milestones", "k", "cache_dir"):
        v = getattr(args, name)
        if v is not None:
            cmd += [f"--{name.replace('_', '-')}", str(v)]
    for kv in args.opt:
        cmd += ["--opt", kv]
    print(f"  {env.name}: {which} in a child process, load {loadavg()}", flush=True)
    t0 = time.perf_counter()
    r = subprocess.run(cmd)
    if r.returncode:
        raise StageError(f"{env.name}: {which} child failed (exit {r.returncode})")
    rec = load_json(path)
    print(
        f"  {env.name}: {which}: {rec['n_queries']} queries, solved {rec['solved']}, "
        f"plan {rec['wall_time']:.1f} s, peak RSS {rec['peak_rss_bytes'] / 2**30:.2f} GiB "
        f"(child {time.perf_counter() - t0:.1f} s) -> {path}",
        flush=True,
    )


# ---------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------


# ---------------------------------------------------------------------------


def parse_args(argv):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--stage", default="all", choices=("bitstar", "roadmap", "report", "pool", "memory", "all")
    )
    ap.add_argument(
        "--env",
        action="append",
        default=None,
        help=f"preset or JSON map, repeatable (default {' '.join(DEFAULT_ENVS)})",
    )
    ap.add_argument("--queries", type=int, default=200, help="queries per map (default 200)")
    ap.add_argument("--out", default=None, help="results folder (default results/bench_roadmap)")
    ap.add_argument(
        "--budget-scale",
        type=float,
        default=1.0,
        help="BIT* budget = the paper's data budget x this (default 1)",
    )
    ap.add_argument("--force", action="store_true", help="rerun BIT* maps whose file matches")
    ap.add_argument("--milestones", type=int, default=None, help="roadmap option")
    ap.add_argument("--k", type=int, default=None, help="roadmap option (default: PRM* rule)")
    ap.add_argument("--cache-dir", default=None, help="roadmap option")
    ap.add_argument(
        "--opt",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="any other roadmap option (VALUE parsed as JSON, else a string)",
    )
    ap.add_argument(
        "--roadmap-repeats",
        type=int,
        default=1,
        help="plan the roadmap queries this many times (default 1; first is cold)",
    )
    ap.add_argument(
        "--pool-env",
        action="append",
        default=None,
        help=f"maps of the pool and memory stages (default those of --env among "
        f"{' '.join(POOL_ENVS)}, else both)",
    )
    ap.add_argument("--pool-size", type=int, default=10_000, help="pool queries (default 10000)")
    ap.add_argument(
        "--memory-milestones",
        type=int,
        default=50_000,
        help="milestones of the memory stage (default 50000)",
    )
    ap.add_argument("--child", choices=("pool", "memory"), help=argparse.SUPPRESS)
    ap.add_argument("--child-out", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.queries < 1:
        ap.error("--queries must be >= 1")
    return args


def stage_maps(stage: str, envs: list[str], args) -> list[str]:
    """The maps ``stage`` runs on (the pool and memory stages: ``--pool-env`` or a default)."""
    names = envs
    if stage in ("pool", "memory"):
        names = args.pool_env or (
            [e for e in envs if e in POOL_ENVS] if args.env else list(POOL_ENVS)
        )
        if not names:
            print(f"  no map for {stage} (--pool-env)", flush=True)
    return names


def run_stage(stage: str, names: list[str], args, out: Path) -> bool:
    """Runs ``stage`` on each map of ``names``; whether it failed (StageError) on any."""
    import ntq_jax

    failed = False
    for name in names:
        try:
            env = ntq_jax.make_env(name)
            if stage == "bitstar":
                stage_bitstar(env, args, out)
            elif stage == "roadmap":
                stage_roadmap(env, args, out)
            else:
                stage_child(env, args, out, stage)
        except StageError as e:
            print(f"bench_roadmap: {stage}: {e}", file=sys.stderr, flush=True)
            failed = True
            if "not registered" in str(e):
                break  # the same for every map
    return failed


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.child:
        try:
            return _child(args)
        except StageError as e:
            print(f"bench_roadmap: {e}", file=sys.stderr)
            return 2

    import ntq_jax  # noqa: F401  (loaded once, before the first stage heading)

    out = Path(args.out) if args.out else ROOT / "results" / "bench_roadmap"
    envs = args.env or list(DEFAULT_ENVS)
    stages = (
        ["bitstar", "roadmap", "pool", "memory", "report"] if args.stage == "all" else [args.stage]
    )
    failed = []
    for stage in stages:
        print(f"# stage {stage}", flush=True)
        if stage == "report":
            stage_report(envs, args, out)
            continue
        if run_stage(stage, stage_maps(stage, envs, args), args, out):
            failed.append(stage)
    return 2 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
