#!/usr/bin/env python
"""XLA compiler options for the motion-check kernels: compile cost, speed and answers, side by side.

For each map and kernel (the discretised ``steer_to`` of an 8,192-motion chunk, the
certified one of a 1,024-motion chunk, ``is_valid`` of 8,192 states; the map's data
padding, uniform states) it compiles the kernel twice in this process: with
:data:`ntq_jax.geometry.KERNEL_COMPILER_OPTIONS` (the baseline) and with those plus
the ``--option`` overrides. It prints the CPU seconds of each XLA compilation, the
median wall time of a call (calls interleaved round-robin), the ratios candidate /
baseline, and whether the answers are identical.

    python benchmarks/bench_compiler_options.py --env rigid/0 --env nlink/6 \
        --option xla_cpu_use_fusion_emitters=false

An option this jaxlib does not know fails at its first compilation with XLA's
own message.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
from common import interleaved

from ntq_jax.envs import make_env
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.queries import _uniform_block
from ntq_jax.robots.batch import is_valid_cm, steer_to_cm

KERNELS = {"discretized": 8192, "certified": 1024, "valid": 8192}  # kernel -> rows per call


def parse_option(text: str) -> tuple[str, object]:
    name, _, value = text.partition("=")
    low = value.lower()
    if low in ("true", "false"):
        return name, low == "true"
    try:
        return name, int(value)
    except ValueError:
        return name, value


def kernel(env, check: str):
    pad = env.padding
    if check == "valid":
        return lambda w, a, b: is_valid_cm(env.robot, w, a.T, pad)
    return lambda w, a, b: steer_to_cm(env.robot, w, a.T, b.T, pad, check=check)


def compare(env, check: str, options: dict, reps: int) -> dict:
    n = KERNELS[check]
    a = _uniform_block(env.robot, env.world, jax.random.key(1), n)
    b = _uniform_block(env.robot, env.world, jax.random.key(2), n)
    calls, compile_s, answers = {}, {}, {}
    for label, opts in (
        ("base", KERNEL_COMPILER_OPTIONS),
        ("cand", {**KERNEL_COMPILER_OPTIONS, **options}),
    ):
        lowered = jax.jit(kernel(env, check), compiler_options=opts).lower(env.world, a, b)
        t = time.process_time()
        compiled = lowered.compile()
        compile_s[label] = time.process_time() - t
        calls[label] = lambda c=compiled: c(env.world, a, b)
        answers[label] = np.asarray(calls[label]())
    run = interleaved(calls, reps)
    return {
        "compile": compile_s,
        "run": run,
        "equal": bool(np.array_equal(answers["base"], answers["cand"])),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--env", action="append", help="preset maps (default: point/3, rigid/0, nlink/6)"
    )
    ap.add_argument(
        "--option",
        action="append",
        required=True,
        type=parse_option,
        help="name=value, an XLA compile option of the candidate (repeatable)",
    )
    ap.add_argument("--kernel", action="append", choices=sorted(KERNELS))
    ap.add_argument("--reps", type=int, default=15)
    args = ap.parse_args()
    options = dict(args.option)
    print(f"candidate: {KERNEL_COMPILER_OPTIONS} + {options}")
    print("| map | kernel | XLA compile, CPU s | ratio | call, ms | ratio | answers |")
    print("|---|---|---|---|---|---|---|")
    for name in args.env or ["point/3", "rigid/0", "nlink/6"]:
        env = make_env(name)
        for check in args.kernel or list(KERNELS):
            r = compare(env, check, options, args.reps)
            c, t = r["compile"], r["run"]
            print(
                f"| {name} | {check} | {c['base']:.2f} -> {c['cand']:.2f} | {c['cand'] / c['base']:.2f}x "
                f"| {t['base'] * 1e3:.2f} -> {t['cand'] * 1e3:.2f} | {t['cand'] / t['base']:.2f}x "
                f"| {'identical' if r['equal'] else 'DIFFER'} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
