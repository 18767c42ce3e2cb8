#!/usr/bin/env python
"""The public batched calls against their own compiled kernels, at every kind of batch size.

``Env.steer_to`` / ``is_valid`` / ``distance`` take batches of any size and reach
the compiled kernels in pieces of a few power-of-two sizes, read in place
(``ntq_jax.robots.rows``). This measures what that costs, side by side in one
process (repeats interleaved, medians): the public call against the bare kernel
(``ntq_jax.robots.batch.steer_to_batch``, ...) on the same rows, as one array of
exactly the rows (compiled for that size), or, below ``PIECE_MIN`` rows, already
padded to the public call's bucket size so the bare call does no padding and no
slicing. Printed per robot, input kind (device array, NumPy) and size:
both times and the wrapper's cost ``public / bare``; and the per-query rate of
the public call at ``2^k + 1`` rows against ``2^k`` rows (goal >= 0.7).

Robots: ``point/3`` (exact segment test, the cheapest kernel: the wrapper's cost
shows most), ``rigid/0`` and ``nlink/4`` on short motions (the goal's state
0.01 away in every coordinate: a few checked states each, so the kernel is as
cheap as these robots get).

    python benchmarks/bench_wrapper.py                 # all sizes up to 10^7 (a few minutes)
    python benchmarks/bench_wrapper.py --max-rows 2e6  # quicker
    python benchmarks/bench_wrapper.py --robots point/3 --method steer_to
"""

from __future__ import annotations

import argparse
import json

import jax
import jax.numpy as jnp
import numpy as np
from common import interleaved

import ntq_jax as nj
from ntq_jax.batching import fine_bucket_size
from ntq_jax.robots import batch as B
from ntq_jax.robots.rows import PIECE_MIN

SIZES = (1, 63, 64, 65, 1 << 20, (1 << 20) + 1, 10_000_000)
GOAL_WRAPPER = 1.25  # public / bare kernel, at most
GOAL_NEIGHBOUR = 0.7  # per-query rate at 2^k + 1 rows / at 2^k rows, at least


def pairs(env, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` pairs of the benchmark: uniform point pairs; short motions for the other robots."""
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(v, np.float64) for v in env.robot.config_bounds(env.world))
    a = (lo + rng.random((n, env.dim)) * (hi - lo)).astype(np.float32)
    if env.robot.kind == "point":
        b = (lo + rng.random((n, env.dim)) * (hi - lo)).astype(np.float32)
    else:
        b = np.clip(a + np.float32(0.01), lo, hi).astype(np.float32)
    return a, b


def kernels(env, method: str):
    """``(public(a, b), bare(a_padded, b_padded))`` for ``method``."""
    robot, world = env.robot, env.world
    if method == "steer_to":
        return (
            lambda a, b: env.steer_to(a, b, padding=0),
            lambda a, b: B.steer_to_batch(robot, world, a, b, 0.0),
        )
    if method == "is_valid":
        return (
            lambda a, b: env.is_valid(a, padding=0),
            lambda a, b: B.is_valid_batch(robot, world, a, 0.0),
        )
    return (lambda a, b: env.distance(a, b), lambda a, b: B.distance_batch(robot, a, b))


def measure(env, method: str, n: int, inputs: str, reps: int) -> dict:
    a, b = pairs(env, n)
    m = fine_bucket_size(n, 64) if n < PIECE_MIN else n  # the public call's own edge bucket
    pad = ((0, m - n), (0, 0))
    ap, bp = jax.block_until_ready((jnp.asarray(np.pad(a, pad)), jnp.asarray(np.pad(b, pad))))
    public, bare = kernels(env, method)
    x, y = jax.block_until_ready((jnp.asarray(a), jnp.asarray(b))) if inputs == "device" else (a, b)
    want = np.asarray(bare(ap, bp))[:n]
    got = np.asarray(public(x, y))
    same = bool(np.array_equal(got, want) if got.dtype == bool else np.allclose(got, want))
    t = interleaved({"public": lambda: public(x, y), "bare": lambda: bare(ap, bp)}, reps)
    return {
        "env": env.name,
        "method": method,
        "inputs": inputs,
        "n": n,
        "bucket": m,
        "public_s": t["public"],
        "bare_s": t["bare"],
        "ratio": t["public"] / t["bare"],
        "public_per_s": n / t["public"],
        "same_answers": same,
    }


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["point/3", "rigid/0", "nlink/4"])
    ap.add_argument(
        "--method", nargs="+", default=["steer_to"], choices=["steer_to", "is_valid", "distance"]
    )
    ap.add_argument("--inputs", nargs="+", default=["device", "numpy"])
    ap.add_argument("--max-rows", type=float, default=1e7)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    sizes = [n for n in SIZES if n <= args.max_rows]
    rows = []
    print(
        f"{'env':9s} {'method':9s} {'inputs':6s} {'rows':>10s} {'public':>11s} {'bare':>11s} "
        f"{'public/bare':>11s} {'queries/s':>10s}  same"
    )
    for name in args.robots:
        env = nj.make_env(name)
        for method in args.method:
            for inputs in args.inputs:
                for n in sizes:
                    r = measure(env, method, n, inputs, args.reps)
                    rows.append(r)
                    flag = "" if r["ratio"] <= GOAL_WRAPPER else f"  > {GOAL_WRAPPER}"
                    print(
                        f"{name:9s} {method:9s} {inputs:6s} {n:10d} {r['public_s'] * 1e3:9.3f}ms "
                        f"{r['bare_s'] * 1e3:9.3f}ms {r['ratio']:11.2f} "
                        f"{r['public_per_s']:10.3g}  {r['same_answers']}{flag}",
                        flush=True,
                    )
    by = {(r["env"], r["method"], r["inputs"], r["n"]): r for r in rows}
    print(f"\nper-query rate at 2^k + 1 rows / at 2^k rows (goal >= {GOAL_NEIGHBOUR}):")
    for (env, method, inputs, n), r in by.items():
        low = by.get((env, method, inputs, n - 1))
        if low is not None and (n - 1) & (n - 2) == 0:
            print(
                f"  {env} {method} {inputs} {n - 1}+1: "
                f"{r['public_per_s'] / low['public_per_s']:.2f}"
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return rows


if __name__ == "__main__":
    main()
