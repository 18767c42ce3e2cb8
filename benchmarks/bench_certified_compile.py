#!/usr/bin/env python
"""Motion checks: compile cost and speed of two checkouts, and whether they agree.

For each map, a fresh subprocess per checkout and repeat, alternating (``base``,
``head``, ``base``, ...), builds the program of one chunk of the motion check
``--check`` (``certified``, the default: :data:`ntq_jax.robots.batch.CERTIFIED_CHUNK`
motions; ``discretized``: :data:`~ntq_jax.robots.batch.STEER_CHUNK`; the shapes
every caller shares) and reports the CPU seconds (``time.process_time``: robust to other jobs
on the machine) of tracing, lowering and XLA compilation, the StableHLO size, the
median wall seconds of checking 20 chunks of motions (short to long, uniform
valid states) and a hash of the answers. It prints per checkout the medians, the
ratios head/base, and whether the answers hash the same.

    git worktree add /tmp/base <previous commit>
    python benchmarks/bench_certified_compile.py --base /tmp/base --env rigid/0 --env nlink/6
    python benchmarks/bench_certified_compile.py --base /tmp/base --check discretized --env point/3

``--base`` and ``--head`` are checkouts (folders holding ``ntq_jax/``); ``--head``
defaults to this one.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import hashlib, json, sys, time
import jax, jax.numpy as jnp, numpy as np
from ntq_jax.envs import make_env
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.robots.batch import CERTIFIED_CHUNK, STEER_CHUNK, steer_to_cm

env = make_env(sys.argv[1])
check = sys.argv[2]
robot, world, pad = env.robot, env.world, env.padding
n = CERTIFIED_CHUNK if check == "certified" else STEER_CHUNK
states = env.sample_states(jax.random.key(1), 40 * n)
rng = np.random.default_rng(0)
a, far = states[: 20 * n], states[20 * n:]
b = (a + rng.choice([0.02, 0.1, 0.3, 1.0], size=(20 * n, 1)) * (far - a)).astype(np.float32)
fn = jax.jit(lambda w, x, y: steer_to_cm(robot, w, x, y, pad, check=check),
             compiler_options=KERNEL_COMPILER_OPTIONS)
xa = [jnp.asarray(a[i * n:(i + 1) * n].T) for i in range(20)]
xb = [jnp.asarray(b[i * n:(i + 1) * n].T) for i in range(20)]
c0 = time.process_time(); traced = fn.trace(world, xa[0], xb[0])
c1 = time.process_time(); lowered = traced.lower()
c2 = time.process_time(); compiled = lowered.compile()
c3 = time.process_time()
out = np.concatenate([np.asarray(compiled(world, x, y)) for x, y in zip(xa, xb)])
runs = []
for _ in range(5):
    t = time.perf_counter()
    jax.block_until_ready([compiled(world, x, y) for x, y in zip(xa, xb)])
    runs.append(time.perf_counter() - t)
print(json.dumps({"trace": c1 - c0, "lower": c2 - c1, "compile": c3 - c2,
                  "hlo_mb": len(lowered.as_text()) / 1e6, "run": float(np.median(runs)),
                  "free": float(out.mean()), "hash": hashlib.sha256(out.tobytes()).hexdigest()[:16]}))
"""


def measure(checkout: Path, env: str, check: str) -> dict:
    """One fresh process in ``checkout`` (its ``ntq_jax`` first on the path)."""
    environ = dict(os.environ, PYTHONPATH=str(checkout), JAX_PLATFORMS="cpu")
    environ.pop("JAX_COMPILATION_CACHE_DIR", None)  # no persistent cache: a cold compile
    out = subprocess.run(
        [sys.executable, "-c", CHILD, env, check],
        env=environ,
        cwd=checkout,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, required=True, help="checkout to compare against")
    ap.add_argument("--head", type=Path, default=ROOT, help="checkout measured (default: this)")
    ap.add_argument(
        "--env", action="append", default=None, help="map (repeatable; default rigid/0)"
    )
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument(
        "--check",
        choices=("certified", "discretized"),
        default="certified",
        help="the motion check measured",
    )
    args = ap.parse_args()
    keys = ("trace", "lower", "compile", "hlo_mb", "run")
    for env in args.env or ["rigid/0"]:
        got = {"base": [], "head": []}
        for _ in range(args.repeats):
            for side in ("base", "head"):
                got[side].append(measure(getattr(args, side), env, args.check))
        med = {
            s: {k: statistics.median(r[k] for r in rows) for k in keys} for s, rows in got.items()
        }
        same = {r["hash"] for r in got["base"] + got["head"]}
        print(
            f"{env}: "
            + ", ".join(
                f"{k} {med['base'][k]:.2f} -> {med['head'][k]:.2f} ({med['head'][k] / med['base'][k]:.2f}x)"
                for k in keys
            )
        )
        total = {s: sum(med[s][k] for k in ("trace", "lower", "compile")) for s in med}
        print(
            f"{env}: trace+lower+compile CPU s {total['base']:.1f} -> {total['head']:.1f} "
            f"({total['head'] / total['base']:.2f}x); answers identical: {len(same) == 1} "
            f"(free fraction {got['head'][0]['free']:.4f})",
            flush=True,
        )


if __name__ == "__main__":
    main()
