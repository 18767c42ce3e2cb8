#!/usr/bin/env python
"""Benchmark: the batched neural planner vs a per-query loop of the same planner.

Examples::

    python benchmarks/bench_plan.py                         # point/0, 500 queries
    python benchmarks/bench_plan.py --env rigid/0 --env nlink/4 --loop-queries 100
    python benchmarks/bench_plan.py --run runs/point-xxxx --env point/3   # a trained PNet_3

The same compiled planner (:func:`ntq_jax.neural.plan_batch`, the
evaluation options of the config) plans the same test queries (half uniform,
half non-trivial, padding 0) once as one batch and once one query at a time
(batch size 1). Compilation is excluded from both (each shape is warmed up
first, and any compilation inside a timed call is subtracted). Without
``--run`` the PNet is an untrained ensemble member (random weights, widths
from ``--hidden``); its paths differ from a trained one's, so use ``--run``
for the timing of a real evaluation. With ``--loop-queries`` smaller than
``--queries`` the loop's time
is measured on that many queries and scaled (reported as such).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _git_show(rev: str, path: str) -> str | None:
    r = subprocess.run(
        ["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True, text=True
    )
    return r.stdout if r.returncode == 0 else None


def _load_source(name: str, src: str):
    path = Path(tempfile.mkdtemp()) / f"{name}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


#: The neural planner's modules in import order, the one with ``plan_batch`` last: the
#: ``ntq_jax.neural`` package (issue 51), else the flat modules before it.
PLANNER_LAYOUTS = (
    tuple(
        f"ntq_jax.neural.{m}"
        for m in ("options", "motions", "proposals", "steps", "repair", "driver")
    ),
    (
        "ntq_jax.neural_options",
        "ntq_jax.neural_motions",
        "ntq_jax.neural_steps",
        "ntq_jax.neural_planner",
    ),
)


def planner_at(rev: str):
    """The neural planner module (the one with ``plan_batch``) of git revision ``rev``, as a
    separate module, bound to that revision's other modules of the planner (those it has)."""
    for names in PLANNER_LAYOUTS:
        srcs = {n: _git_show(rev, n.replace(".", "/") + ".py") for n in names}
        if srcs[names[-1]] is not None:
            break
    else:
        raise SystemExit(f"git revision {rev!r} has no neural planner ({PLANNER_LAYOUTS[0][-1]})")
    import ntq_jax.neural  # noqa: F401  (this tree's package first: the swaps below stay put)

    saved = {n: sys.modules.get(n) for n in names}
    try:  # each of the revision's modules binds the revision's modules before it at import
        for n in names:
            if srcs[n] is not None:
                sys.modules[n] = _load_source(f"{n.rsplit('.', 1)[-1]}_{rev}", srcs[n])
        return sys.modules[names[-1]]
    finally:
        for n, mod in saved.items():
            if mod is None:
                sys.modules.pop(n, None)
            else:
                sys.modules[n] = mod


def _options(mod, cfg):
    """The evaluation's planner options for ``mod`` (a tree before issue 51 maps them itself)."""
    if hasattr(mod.PlannerOptions, "from_config"):
        return mod.PlannerOptions.from_config(cfg.eval, steer=True)
    from ntq_jax.experiment import config as C

    return C.neural_options(cfg.eval, steer=True)


def against(env, pnet, q, key, cfg, other, repeats: int) -> dict:
    """Median batched seconds (compile excluded) of this planner and ``other``, interleaved."""
    import jax
    import numpy as np

    from ntq_jax.neural import driver as current

    times = {"current": [], "other": []}
    for mod in (current, other):  # compile both first
        mod.plan_batch(env, pnet, q, key, _options(mod, cfg))
    for r in range(repeats):
        for name, mod in (("current", current), ("other", other)):
            opts = _options(mod, cfg)
            t0 = time.perf_counter()
            res = mod.plan_batch(env, pnet, q, jax.random.fold_in(key, r), opts)
            times[name].append(time.perf_counter() - t0 - res.compile_seconds)
    return {k: float(np.median(v)) for k, v in times.items()}


def bench(
    env_name: str,
    *,
    queries: int,
    loop_queries: int,
    run=None,
    model: int = 3,
    hidden=(256, 256, 128, 64),
    seed: int = 0,
    eval_overrides=(),
    other=None,
    repeats: int = 5,
) -> dict:
    import jax
    import numpy as np

    from ntq_jax import make_env, models
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment import config as C
    from ntq_jax.models import member_pnets
    from ntq_jax.neural import plan_batch

    env = make_env(env_name)
    if run is not None:
        from ntq_jax.training import load_ensemble

        cfg = C.load(Path(run) / "config.yaml", list(eval_overrides))
        ens = load_ensemble(Path(run) / "models" / env_slug(env_name, env))
        source = f"trained PNet_{model} of {run}"
    else:
        cfg = C.load(None, [f"model.hidden={list(hidden)}", *eval_overrides])
        spec = models.ModelSpec.from_env(env, cfg.model)
        ens = models.init_ensemble(spec, seed, num_members=model + 1)
        source = f"untrained PNet (hidden {list(hidden)})"
    pnet = member_pnets(ens)[model]
    opts = C.neural_options(cfg.eval, steer=True)
    key = jax.random.key(seed)
    qu, _ = env.sample_queries(jax.random.fold_in(key, 1), queries // 2, 0.0, padding=0.0)
    qn, _ = env.sample_queries(jax.random.fold_in(key, 2), queries - queries // 2, 1.0, padding=0.0)
    q = np.concatenate([qu, qn]).astype(np.float32)

    # Compilation is excluded from both timings: each call's compile time (reported by
    # plan_batch; a stage compiles on its first use) is subtracted from its wall time.
    warm = plan_batch(env, pnet, q, key, opts)  # compiles the batch shapes
    t0 = time.perf_counter()
    res = plan_batch(env, pnet, q, key, opts)
    batched = time.perf_counter() - t0 - res.compile_seconds

    vs = against(env, pnet, q, key, cfg, other, repeats) if other is not None else None
    n_loop = min(loop_queries, len(q))
    if n_loop:
        plan_batch(env, pnet, q[:1], key, opts)  # compiles the single-query shapes
    loop, succ, loop_compile = 0.0, 0, 0.0
    for i in range(n_loop):
        t0 = time.perf_counter()
        r = plan_batch(env, pnet, q[i : i + 1], jax.random.fold_in(key, i), opts)
        loop += time.perf_counter() - t0 - r.compile_seconds
        loop_compile += r.compile_seconds
        succ += int(r.success[0])
    loop *= len(q) / max(n_loop, 1)
    return {
        "env": env_name,
        "robot": env.robot.kind,
        "queries": len(q),
        "loop_queries": n_loop,
        "pnet": source,
        "n_plan": opts.n_plan,
        "replan_rounds": opts.replan_rounds,
        "batched_seconds": batched,
        "batched_seconds_per_query": batched / len(q),
        "loop_seconds": loop,
        "loop_seconds_per_query": loop / len(q),
        "speedup": loop / batched,
        "compile_seconds": warm.compile_seconds,
        "loop_compile_seconds_excluded": loop_compile,
        "batched_success": float(res.success.mean()),
        "loop_success": succ / max(n_loop, 1),
        "mean_pnet_calls": float(res.pnet_calls.mean()),
        "against": vs,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--env", action="append", default=None, help="environment(s) (default point/0)")
    ap.add_argument("--queries", type=int, default=500)
    ap.add_argument(
        "--loop-queries",
        type=int,
        default=500,
        help="queries timed in the per-query loop (scaled to --queries)",
    )
    ap.add_argument("--run", default=None, help="use a trained ensemble of this run folder")
    ap.add_argument("--model", type=int, default=3)
    ap.add_argument("--hidden", type=int, nargs="+", default=[256, 256, 128, 64])
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="eval config override, e.g. --set eval.n_plan=50",
    )
    ap.add_argument(
        "--against",
        default=None,
        metavar="REV",
        help="also time the batched planner of this git revision, side by side",
    )
    ap.add_argument("--repeats", type=int, default=5, help="interleaved repeats for --against")
    ap.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = ap.parse_args(argv)
    other = planner_at(args.against) if args.against else None
    out = []
    for name in args.env or ["point/0"]:
        r = bench(
            name,
            queries=args.queries,
            loop_queries=args.loop_queries,
            run=args.run,
            model=args.model,
            hidden=tuple(args.hidden),
            eval_overrides=args.set,
            other=other,
            repeats=args.repeats,
        )
        out.append(r)
        if r["against"] is not None:
            a = r["against"]
            print(
                f"{r['env']:8s} batched, median of {args.repeats}: this tree {a['current']:.3f} s, "
                f"{args.against} {a['other']:.3f} s: {a['other'] / a['current']:.2f}x faster",
                flush=True,
            )
        if not r["loop_queries"]:
            continue
        print(
            f"{r['env']:8s} {r['queries']} queries ({r['pnet']}, n_plan {r['n_plan']}, "
            f"replan {r['replan_rounds']}): batched {r['batched_seconds']:.2f} s "
            f"({r['batched_seconds_per_query'] * 1e3:.2f} ms/query), per-query loop "
            f"{r['loop_seconds']:.2f} s ({r['loop_seconds_per_query'] * 1e3:.2f} ms/query"
            f"{', measured on %d' % r['loop_queries'] if r['loop_queries'] < r['queries'] else ''}"
            f"), speedup {r['speedup']:.1f}x; success {r['batched_success']:.3f} / "
            f"{r['loop_success']:.3f}; compile {r['compile_seconds']:.1f} s",
            flush=True,
        )
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
