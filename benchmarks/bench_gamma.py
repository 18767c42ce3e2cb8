#!/usr/bin/env python
"""gamma_nt streaming against the bare motion check it counts, side by side (issue 27).

For each environment, in ONE process with interleaved repeats (medians quoted):

* ``check``: the bare batched motion check (``steer_to_cm``, the kernel gamma_nt
  fuses, compiled with the same options) on pre-sampled uniform valid pairs held
  as coordinate-major device arrays, its blocked lanes counted in the same call;
  rate = pairs / second. ``check_box``: the same on pairs drawn uniformly from the
  configuration box (valid or not; what ``bench_steer.py`` times);
* ``gamma``: ``gamma.gamma_nt`` over ``n`` uniform valid queries at the default
  chunk; rate = valid queries / second (sampling, validity, the check and the
  counting all included);
* ``ratio`` = gamma rate / check rate (the issue's goal: >= 0.5 on point/3).

``--stages`` also times the pieces of one compiled gamma chunk (default chunk
size) side by side: the counter-hash uniforms alone, uniforms + the validity of
both endpoints, the whole chunk, and the bare check on as many valid pairs.

    python benchmarks/bench_gamma.py                          # point/3, rigid/0, nlink/4
    python benchmarks/bench_gamma.py --env point/3 --stages --reps 9 --json out.json
"""

from __future__ import annotations

import argparse
import functools
import json
import os

import jax
import jax.numpy as jnp
import numpy as np
from common import interleaved, loadavg, machine

import ntq_jax as nj
from ntq_jax import gamma as G
from ntq_jax import prng
from ntq_jax import queries as Q
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.robots.batch import is_valid_cm, steer_to_cm

# pairs of the bare check, and gamma_nt queries per repeat (~0.2-1 s each on one core)
SIZES = {"point": (1 << 23, 1 << 25), "rigid_body": (1 << 16, 1 << 17), "nlink": (1 << 16, 1 << 17)}

_jit = functools.partial(jax.jit, compiler_options=KERNEL_COMPILER_OPTIONS)


@functools.partial(_jit, static_argnames=("robot", "padding"))
def _count_blocked(robot, world, a_cm, b_cm, padding: float):
    return jnp.sum(~steer_to_cm(robot, world, a_cm, b_cm, padding))


@functools.partial(_jit, static_argnames=("robot", "padding", "size", "stage"))
def _stage(robot, world, seeds, padding: float, size: int, stage: str):
    """One gamma chunk cut after ``stage``: "uniforms", "valid" or "full" (the package's chunk)."""
    u = G._chunk_uniforms(seeds, jnp.uint32(0), size, 2 * robot.dim)
    if stage == "uniforms":
        s = functools.reduce(jnp.add, u)
        return G.count_outcomes(s > 1.0, s > 2.0)
    if stage == "full":
        return G.count_outcomes(*G._outcomes_from_uniforms(robot, world, u, padding))
    d = robot.dim
    lo, hi = robot.config_bounds(world)
    rows = [lo[j % d] + u[j] * (hi[j % d] - lo[j % d]) for j in range(2 * d)]
    va = is_valid_cm(robot, world, jnp.stack(rows[:d]), padding)
    vb = is_valid_cm(robot, world, jnp.stack(rows[d:]), padding)
    return G.count_outcomes(va & vb, va)


def _pairs_cm(robot, world, key, m: int, padding: float):
    q = Q.sample_uniform_queries(robot, world, key, m, padding)
    return jax.device_put(q[:, 0].T.copy()), jax.device_put(q[:, 1].T.copy())


def bench_env(
    name: str, padding: float, reps: int, pairs: int | None, queries: int | None, seed: int = 0
) -> dict:
    env = nj.make_env(name)
    robot, world = env.robot, env.world
    m, n = SIZES[robot.kind]
    m, n = pairs or m, queries or n
    a_cm, b_cm = _pairs_cm(robot, world, jax.random.key(seed + 1000), m, padding)
    lo, hi = (np.asarray(x) for x in robot.config_bounds(world))
    u = np.random.default_rng(seed).random((2, robot.dim, m), np.float32)
    box = [
        jax.device_put((lo[:, None] + u[i] * (hi - lo)[:, None]).astype(np.float32))
        for i in range(2)
    ]
    keys = iter(range(seed, seed + 10 * reps + 10))
    last = {}

    def gamma():
        last["est"] = G.gamma_nt(robot, world, jax.random.key(next(keys)), n, padding)
        return ()

    med = interleaved(
        {
            "check": lambda: _count_blocked(robot, world, a_cm, b_cm, padding),
            "check_box": lambda: _count_blocked(robot, world, *box, padding),
            "gamma": gamma,
        },
        reps,
    )
    check_rate, gamma_rate, box_rate = m / med["check"], n / med["gamma"], m / med["check_box"]
    est = last["est"]
    return {
        "env": name,
        "padding": padding,
        "pairs": m,
        "queries": n,
        "reps": reps,
        "check_per_second": check_rate,
        "box_check_per_second": box_rate,
        "gamma_queries_per_second": gamma_rate,
        "ratio": gamma_rate / check_rate,
        "ratio_box": gamma_rate / box_rate,
        "cores": dict(interleaved.cores),
        "gamma": est.gamma,
        "valid_pair_fraction": est.queries / est.candidates,
        "check_gamma": float(_count_blocked(robot, world, a_cm, b_cm, padding)) / m,
    }


def bench_stages(name: str, padding: float, reps: int, seed: int = 0) -> dict:
    """Milliseconds of one default-size gamma chunk cut after each stage, and the bare check."""
    env = nj.make_env(name)
    robot, world = env.robot, env.world
    size = G.default_chunk(robot)
    seeds = prng.stream_seeds(jax.random.key(seed), 0)
    valid = int(_stage(robot, world, seeds, padding, size, "full")[0])
    a_cm, b_cm = _pairs_cm(robot, world, jax.random.key(seed + 1000), valid, padding)
    cases = {
        s: functools.partial(_stage, robot, world, seeds, padding, size, s)
        for s in ("uniforms", "valid", "full")
    }
    cases["check"] = lambda: _count_blocked(robot, world, a_cm, b_cm, padding)
    med = interleaved(cases, reps)
    return {
        "env": name,
        "padding": padding,
        "chunk": size,
        "valid_pairs": valid,
        "ms": {k: 1e3 * v for k, v in med.items()},
        "cores": dict(interleaved.cores),
        "ratio": med["check"] / med["full"],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--env", action="append", help="preset (repeatable); default point/3, rigid/0, nlink/4"
    )
    ap.add_argument("--padding", type=float, default=0.0)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--pairs", type=int, default=None, help="pairs of the bare check")
    ap.add_argument("--queries", type=int, default=None, help="gamma_nt queries per repeat")
    ap.add_argument("--stages", action="store_true", help="also time the stages of one chunk")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    rows, stages = [], []
    print(f"load average {loadavg()}, affinity {sorted(os.sched_getaffinity(0))}")
    for name in args.env or ["point/3", "rigid/0", "nlink/4"]:
        r = bench_env(name, args.padding, args.reps, args.pairs, args.queries)
        rows.append(r)
        c = r["cores"]
        print(
            f"{name} padding {args.padding}: check {r['check_per_second']:.3e}/s, gamma_nt "
            f"{r['gamma_queries_per_second']:.3e} valid queries/s, ratio {r['ratio']:.3f} | "
            f"box-pair check {r['box_check_per_second']:.3e}/s, ratio {r['ratio_box']:.3f} | "
            f"gamma {r['gamma']:.4f} (check {r['check_gamma']:.4f}), valid pairs "
            f"{r['valid_pair_fraction']:.3f}, cores {c['check']:.2f}/{c['check_box']:.2f}/"
            f"{c['gamma']:.2f}",
            flush=True,
        )
        if args.stages:
            s = bench_stages(name, args.padding, args.reps)
            stages.append(s)
            print(
                f"  one chunk of {s['chunk']} candidate pairs ({s['valid_pairs']} valid), ms: "
                + ", ".join(f"{k} {v:.1f}" for k, v in s["ms"].items())
                + f"; check / full = {s['ratio']:.3f}",
                flush=True,
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {"machine": machine(), "load_end": loadavg(), "rows": rows, "stages": stages},
                f,
                indent=1,
            )


if __name__ == "__main__":
    main()
