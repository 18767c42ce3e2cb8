#!/usr/bin/env python
"""Benchmark: the ensemble planners' time against one member's, on a run's test queries.

Example::

    python scripts/train_all.py --out runs/default500 --set eval.k_test=500
    python benchmarks/bench_ensemble.py --run runs/default500 --repeats 5

For every environment of the run (or ``--env``) and both test-query kinds, the
trained members and the ensemble planners plan the run's saved test queries
with the run's evaluation options, interleaved, ``--repeats`` times (the
median is reported; compilation is excluded: every planner is warmed up first
and any compile time inside a timed call is subtracted):

* ``member m``: :func:`ntq_jax.neural.plan_batch` with member ``m``;
* ``ens``: the per-step ensemble rule (``plan_batch`` with the members' list);
* ``members``: every member on every query in one batch
  (:func:`ntq_jax.neural.plan_members`, what best-of-N plans);
* ``cascade``: :func:`ntq_jax.neural.plan_cascade` in the run's
  validation order (``paths/<env>/validation.npz``; ``0..M-1`` if absent).

Ratios are against the mean member time. Successes are printed for orientation
only: the evaluation's keys differ, so use the run's tables for success.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path


def bench_env(run: Path, env_name: str, repeats: int) -> list[dict]:
    import jax
    import numpy as np

    from ntq_jax import make_env
    from ntq_jax import neural as NP
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment import config as C
    from ntq_jax.models import member_pnets
    from ntq_jax.training import load_ensemble

    env = make_env(env_name)
    slug = env_slug(env_name, env)
    cfg = C.load(run / "config.yaml", [])
    pnets = member_pnets(load_ensemble(run / "models" / slug))
    opts = C.neural_options(cfg.eval, steer=True)
    val = run / "paths" / slug / "validation.npz"
    order = [int(m) for m in np.load(val)["order"]] if val.is_file() else list(range(len(pnets)))
    queries = np.load(run / "eval" / slug / "queries.npz")
    key = jax.random.key(0)
    planners = {
        f"member {m}": (lambda q, p=p: NP.plan_batch(env, p, q, key, opts))
        for m, p in enumerate(pnets)
    }
    planners["ens"] = lambda q: NP.plan_batch(env, pnets, q, key, opts)
    planners["members"] = lambda q: NP.plan_members(env, pnets, q, key, opts)[0]
    planners["cascade"] = lambda q: NP.plan_cascade(env, pnets, q, key, opts, order=order)
    out = []
    for kind in ("uniform", "nontrivial"):
        q = np.asarray(queries[kind], np.float32)
        times = {name: [] for name in planners}
        success = {}
        for name, fn in planners.items():  # warm up: compile every shape
            fn(q)
        for _ in range(repeats):
            for name, fn in planners.items():
                r = fn(q)
                times[name].append(r.seconds)
                success[name] = float(r.success.mean())
        med = {name: statistics.median(t) for name, t in times.items()}
        one = statistics.mean(med[f"member {m}"] for m in range(len(pnets)))
        row = {
            "env": env_name,
            "kind": kind,
            "queries": len(q),
            "order": order,
            "seconds": med,
            "ratio_to_one_member": {n: t / one for n, t in med.items()},
            "success": success,
        }
        out.append(row)
        print(
            f"{env_name} {kind:10s} K={len(q)}: one member {one:.3f} s; "
            + ", ".join(
                f"{n} {med[n]:.3f} s ({med[n] / one:.2f}x)" for n in ("ens", "members", "cascade")
            )
            + f"; cascade order {order}",
            flush=True,
        )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--run", required=True, help="a run folder of scripts/train_all.py")
    ap.add_argument(
        "--env",
        action="append",
        default=None,
        help="environment(s) (default: every environment of the run)",
    )
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = ap.parse_args(argv)
    run = Path(args.run)
    from ntq_jax.experiment import config as C

    envs = args.env or list(C.load(run / "config.yaml", []).envs)
    out = [r for name in envs for r in bench_env(run, name, args.repeats)]
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
