#!/usr/bin/env python
"""Benchmark of steer_to and the fused gamma_nt estimator against baselines (issue 2).

Everything runs side by side in ONE process, repeats are interleaved and medians
are quoted, so the ratios stay meaningful on a busy machine:

* exact point-robot ``Env.steer_to`` on 10^7 random ``(N, 2)`` float32 device arrays
  (padding 0 and the map's padding 0.8) on a fixed 7-box 20x20 map, against an
  MPNet-style per-point Python loop (step 0.01), an exact vectorised NumPy
  segment-vs-boxes test and the coordinate-major JAX kernel;
* the fused ``Env.gamma_nt`` estimator (counter-hash PRNG, ``ntq_jax.prng``) in raw
  candidate queries per second, against the same fused pipeline fed by
  ``jax.random`` threefry uniforms;
* rigid-body and 6-link-arm motion checks per second (``Env.steer_to`` on random
  valid pairs of a preset, at the preset's padding), against ``jax.vmap`` of the
  one-query kernel;
* point-robot ``Env.steer_to`` on ``make_env("point/3")`` (padding 0, 10^7 queries)
  with NumPy input (float32 as NumPy allocates it, and float64) side by side with
  the same queries as device arrays, and with the copy-then-call path
  (``jnp.asarray`` first, what NumPy input cost before it was read in place);
* memory flatness: peak RSS (VmHWM) of a fresh process running ``gamma_nt`` over
  10^7 and over 10^9 queries.

    python benchmarks/bench_steer.py                 # full run, a few minutes
    python benchmarks/bench_steer.py --quick         # < 1 minute, smaller sizes, no 10^9 run
    python benchmarks/bench_steer.py --skip-1e9 --json bench.json
    python benchmarks/bench_steer.py --only numpy    # just the NumPy-input comparison
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from common import interleaved
from numpy_steer import numpy_steer

import ntq_jax as nj
from ntq_jax import artifacts
from ntq_jax import gamma as G
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.robots.batch import steer_to_cm

# The fixed benchmark map: 7 boxes (walls with doors and a block) on 20 x 20.
MAP = {
    "name": "bench7",
    "robot": {"kind": "point"},
    "bounds": [[0, 20], [0, 20]],
    "boxes": [
        [6.5, 4, 0.5, 4],
        [6.5, 15, 0.5, 5],
        [13.5, 5, 0.5, 5],
        [13.5, 16, 0.5, 4],
        [3, 10, 3, 0.5],
        [17, 10.5, 3, 0.5],
        [10, 8, 1.5, 1.5],
    ],
    "discs": [],
    "padding": 0.8,
}

GOALS = {
    "steer_qps": 3e8,
    "steer_vs_loop": 1e5,
    "steer_vs_numpy": 100.0,
    "gamma_cps": 1.5e8,
    "gamma_1e9_seconds": 10.0,
    "rigid_cps": 1e5,
    "arm_cps": 2.5e5,
    "rigid_cert_cps": 7e5,
    "arm_cert_cps": 2.5e5,
    "rss_ratio": 1.10,
    "steer_numpy_qps": 5e8,
}


# ---------------------------------------------------------------------------
# Timing
# ---------------------------------------------------------------------------


# ---------------------------------------------------------------------------
# Point-robot baselines
# ---------------------------------------------------------------------------


def mpnet_loop_steer(a, b, boxes, bounds, padding, step=0.01) -> bool:
    """MPNet-style steerTo: walk the segment in steps of ``step``, test each point in Python."""
    (ax, ay), (bx, by) = a, b
    length = math.hypot(bx - ax, by - ay)
    n = max(1, math.ceil(length / step))
    p2 = padding * padding
    for i in range(n + 1):
        t = i / n
        x, y = ax + t * (bx - ax), ay + t * (by - ay)
        if not (bounds[0][0] <= x <= bounds[0][1] and bounds[1][0] <= y <= bounds[1][1]):
            return False
        for cx, cy, hw, hh in boxes:
            dx = max(abs(x - cx) - hw, 0.0)
            dy = max(abs(y - cy) - hh, 0.0)
            if dx * dx + dy * dy <= p2:
                return False
    return True


def bench_point_steer(env, n: int, n_numpy: int, n_loop: int, reps: int) -> list[dict]:
    rows = []
    ka, kb = jax.random.split(jax.random.key(0))
    lo, hi = env.world.bounds[:, 0], env.world.bounds[:, 1]
    a = jax.block_until_ready(lo + jax.random.uniform(ka, (n, 2)) * (hi - lo))
    b = jax.block_until_ready(lo + jax.random.uniform(kb, (n, 2)) * (hi - lo))
    a_cm, b_cm = jax.block_until_ready((a.T.copy(), b.T.copy()))
    a_np, b_np = np.asarray(a[:n_numpy]), np.asarray(b[:n_numpy])
    a_rows, b_rows = a[:n_numpy], b[:n_numpy]
    boxes = np.asarray(env.world.boxes).tolist()
    bounds = np.asarray(env.world.bounds).tolist()
    for padding in (0.0, env.padding):
        cm = jax.jit(
            functools.partial(steer_to_cm, env.robot, padding=padding),
            compiler_options=KERNEL_COMPILER_OPTIONS,
        )
        rowwise = jax.jit(
            lambda w, a, b, p=padding: jax.vmap(env.robot.steer_to, in_axes=(0, 0, None, None))(
                a, b, w, p
            )
        )  # the naive layout: vmap over (N, 2) rows
        t = interleaved(
            {
                "api": lambda p=padding: env.steer_to(a, b, padding=p),
                "cm": lambda: cm(env.world, a_cm, b_cm),
                "rows": lambda: rowwise(env.world, a_rows, b_rows),
                "numpy": lambda p=padding: numpy_steer(a_np, b_np, boxes, bounds, p),
            },
            reps,
        )
        api_out = np.asarray(env.steer_to(a[:n_numpy], b[:n_numpy], padding=padding))
        agree = int(np.sum(api_out == numpy_steer(a_np, b_np, boxes, bounds, padding)))
        a_py, b_py = a_np[:n_loop].tolist(), b_np[:n_loop].tolist()
        t0 = time.perf_counter()
        loop_out = [
            mpnet_loop_steer(a_py[i], b_py[i], boxes, bounds, padding) for i in range(n_loop)
        ]
        t_loop = (time.perf_counter() - t0) / n_loop
        loop_agree = int(np.sum(np.array(loop_out) == api_out[:n_loop]))
        cores = interleaved.cores
        api_qps = n / t["api"]
        rows += [
            {
                "name": f"steer point exact, public API (N,2), pad {padding:g}",
                "n": n,
                "per_second": api_qps,
                "goal": GOALS["steer_qps"],
                "cores": cores["api"],
            },
            {
                "name": f"steer point exact, coordinate-major JAX, pad {padding:g}",
                "n": n,
                "per_second": n / t["cm"],
                "cores": cores["cm"],
            },
            {
                "name": f"steer point exact, JAX vmap over (N,2) rows, pad {padding:g}",
                "n": n_numpy,
                "per_second": n_numpy / t["rows"],
                "cores": cores["rows"],
            },
            {
                "name": f"steer point exact, vectorised NumPy, pad {padding:g}",
                "n": n_numpy,
                "per_second": n_numpy / t["numpy"],
                "agree_with_api": f"{agree}/{n_numpy}",
                "cores": cores["numpy"],
            },
            {
                "name": f"steer point MPNet-style Python loop (step 0.01), pad {padding:g}",
                "n": n_loop,
                "per_second": 1.0 / t_loop,
                "agree_with_api": f"{loop_agree}/{n_loop} (the loop is discretised, not exact)",
            },
            {
                "name": f"ratio API / Python loop, pad {padding:g}",
                "ratio": api_qps * t_loop,
                "goal": GOALS["steer_vs_loop"],
            },
            {
                "name": f"ratio API / NumPy, pad {padding:g}",
                "ratio": api_qps * t["numpy"] / n_numpy,
                "goal": GOALS["steer_vs_numpy"],
            },
            {"name": f"ratio API / coordinate-major, pad {padding:g}", "ratio": t["cm"] / t["api"]},
        ]
    return rows


def bench_numpy_steer(name: str, n: int, reps: int) -> list[dict]:
    """``Env.steer_to`` with NumPy input against the same queries as device arrays."""
    env = nj.make_env(name)
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(env.world.bounds[:, 0]), np.asarray(env.world.bounds[:, 1])
    a64 = lo + rng.random((n, 2)) * (hi - lo)
    b64 = lo + rng.random((n, 2)) * (hi - lo)
    a_np, b_np = a64.astype(np.float32), b64.astype(np.float32)  # NumPy's own allocations
    a_dev, b_dev = jax.block_until_ready((jax.device_put(a_np), jax.device_put(b_np)))
    tiny, z = jax.jit(lambda x: x + 1), jnp.zeros(4)

    def own_cleanup(call):
        """``call`` waited for, then one tiny dispatch: XLA frees the buffers a call
        allocated (the float64 input's float32 copy, the copied device arrays: ~10 ms for
        10^7 rows) when the next program is dispatched, which would charge that cost to
        whichever case runs next (measured: the device-array call after the copy case ran
        at 0.4x its rate after itself). Each case that allocates pays its own."""

        def run():
            out = jax.block_until_ready(call())
            jax.block_until_ready(tiny(z))
            return out

        return run

    t = interleaved(
        {
            "device": lambda: env.steer_to(a_dev, b_dev, padding=0),
            "numpy": lambda: env.steer_to(a_np, b_np, padding=0),
            "numpy64": own_cleanup(lambda: env.steer_to(a64, b64, padding=0)),
            "copy": own_cleanup(
                lambda: env.steer_to(jnp.asarray(a_np), jnp.asarray(b_np), padding=0)
            ),
        },
        reps,
    )
    cores = interleaved.cores
    want = np.asarray(env.steer_to(a_dev, b_dev, padding=0))
    same = {
        k: f"{int(np.sum(np.asarray(env.steer_to(x, y, padding=0)) == want))}/{n}"
        for k, (x, y) in {"numpy": (a_np, b_np), "numpy64": (a64, b64)}.items()
    }
    phase = f"data at 64-byte phase {a_np.ctypes.data % 64}/{b_np.ctypes.data % 64}"
    return [
        {
            "name": f"steer {name} pad 0, device arrays (N,2) float32",
            "n": n,
            "per_second": n / t["device"],
            "cores": cores["device"],
        },
        {
            "name": f"steer {name} pad 0, NumPy float32 (N,2), {phase}",
            "n": n,
            "per_second": n / t["numpy"],
            "goal": GOALS["steer_numpy_qps"],
            "cores": cores["numpy"],
            "same_as_device": same["numpy"],
        },
        {
            "name": f"steer {name} pad 0, NumPy float64 (N,2)",
            "n": n,
            "per_second": n / t["numpy64"],
            "cores": cores["numpy64"],
            "same_as_device": same["numpy64"],
        },
        {
            "name": f"steer {name} pad 0, jnp.asarray copy then call (float32)",
            "n": n,
            "per_second": n / t["copy"],
            "cores": cores["copy"],
        },
        {"name": f"ratio NumPy float32 / device, {name}", "ratio": t["device"] / t["numpy"]},
    ]


# ---------------------------------------------------------------------------
# gamma_nt
# ---------------------------------------------------------------------------


@functools.partial(
    jax.jit, static_argnames=("robot", "padding", "size"), compiler_options=KERNEL_COMPILER_OPTIONS
)
def _threefry_chunk(robot, world, key, padding: float, size: int):
    """The package's fused gamma chunk, fed by ``jax.random`` (threefry) uniforms instead."""
    u = jax.random.uniform(key, (2 * robot.dim, size), jnp.float32)
    return G.count_outcomes(*G._outcomes_from_uniforms(robot, world, u, padding))


def threefry_gamma(env, key, candidates: int, chunk: int):
    """Streams ``candidates`` (a multiple of ``chunk``) through the threefry pipeline."""
    chunks = max(1, candidates // chunk)
    t0 = time.perf_counter()
    valid = blocked = 0
    pending = _threefry_chunk(env.robot, env.world, jax.random.fold_in(key, 0), 0.0, chunk)
    for i in range(1, chunks + 1):
        nxt = (
            _threefry_chunk(env.robot, env.world, jax.random.fold_in(key, i), 0.0, chunk)
            if i < chunks
            else None
        )
        v, b = (int(x) for x in pending)
        valid, blocked = valid + v, blocked + b
        pending = nxt
    secs = time.perf_counter() - t0
    return {
        "gamma": blocked / valid,
        "candidates": chunks * chunk,
        "seconds": secs,
        "candidates_per_second": chunks * chunk / secs,
    }


def bench_gamma(env, n: int, reps: int) -> list[dict]:
    chunk = G.default_chunk(env.robot)
    env.gamma_nt(jax.random.key(99), 10_000, padding=0.0)  # compile both chunk kernels
    threefry_gamma(env, jax.random.key(99), chunk, chunk)
    ours, base, cpu = [], [], [0.0, 0.0]
    for r in range(reps):
        c0 = time.process_time()
        ours.append(env.gamma_nt(jax.random.key(r), n, padding=0.0))
        c1 = time.process_time()
        base.append(threefry_gamma(env, jax.random.key(r), ours[-1].candidates, chunk))
        cpu[0] += c1 - c0
        cpu[1] += time.process_time() - c1
    cps = float(np.median([e.candidates_per_second for e in ours]))
    base_cps = float(np.median([e["candidates_per_second"] for e in base]))
    e = ours[-1]
    return [
        {
            "name": "gamma_nt fused, counter-hash PRNG (raw candidates/s)",
            "n": e.candidates,
            "per_second": cps,
            "goal": GOALS["gamma_cps"],
            "valid_queries_per_second": float(np.median([x.queries_per_second for x in ours])),
            "gamma": e.gamma,
            "ci95": list(e.ci95),
            "cores": cpu[0] / sum(x.seconds for x in ours),
        },
        {
            "name": "gamma_nt fused, jax.random threefry uniforms (baseline)",
            "n": base[-1]["candidates"],
            "per_second": base_cps,
            "gamma": base[-1]["gamma"],
            "cores": cpu[1] / sum(x["seconds"] for x in base),
        },
        {"name": "ratio counter-hash / threefry", "ratio": cps / base_cps},
    ]


def bench_gamma_1e9(env) -> list[dict]:
    env.gamma_nt(jax.random.key(99), 10_000, padding=0.0)
    c0 = time.process_time()
    e = env.gamma_nt(jax.random.key(1), 10**9, padding=0.0)
    return [
        {
            "name": "gamma_nt over 1e9 valid queries (seconds, in-process)",
            "n": e.candidates,
            "seconds": e.seconds,
            "goal": GOALS["gamma_1e9_seconds"],
            "per_second": e.candidates_per_second,
            "gamma": e.gamma,
            "ci95": list(e.ci95),
            "cores": (time.process_time() - c0) / e.seconds,
        }
    ]


_CHILD = """
import json, jax
import ntq_jax as nj
env = nj.Env.from_json({spec!r})
est = env.gamma_nt(jax.random.key(0), {n}, padding=0.0)
status = dict(l.split(":", 1) for l in open("/proc/self/status") if ":" in l)
print(json.dumps({{"vmhwm_kb": int(status["VmHWM"].split()[0]), "seconds": est.seconds,
                  "gamma": est.gamma, "queries": est.queries}}))
"""


def bench_memory(sizes: tuple[int, int]) -> list[dict]:
    """Peak RSS of a fresh process running gamma_nt over each size (VmHWM at its end)."""
    out = {}
    for n in sizes:
        res = subprocess.run(
            [sys.executable, "-c", _CHILD.format(spec=MAP, n=n)],
            capture_output=True,
            text=True,
            check=True,
        )
        out[n] = json.loads(res.stdout.strip().splitlines()[-1])
    lo, hi = sizes
    ratio = out[hi]["vmhwm_kb"] / out[lo]["vmhwm_kb"]
    return [
        {
            "name": f"peak RSS gamma_nt {n:.0e} queries (MiB)",
            "value": out[n]["vmhwm_kb"] / 1024,
            "seconds": out[n]["seconds"],
        }
        for n in sizes
    ] + [
        {
            "name": f"peak RSS ratio {hi:.0e} / {lo:.0e}",
            "ratio": ratio,
            "goal": GOALS["rss_ratio"],
            "goal_is_max": True,
        }
    ]


# ---------------------------------------------------------------------------
# Rigid body and arm motion checks
# ---------------------------------------------------------------------------


def bench_motions(name: str, n: int, reps: int, goal: float) -> list[dict]:
    env = nj.make_env(name)
    s = env.sample_states(jax.random.key(0), 2 * n)
    a, b = jnp.asarray(s[:n]), jnp.asarray(s[n:])
    robot, pad = env.robot, env.padding
    vmapped = jax.jit(
        lambda w, a, b: jax.vmap(robot.steer_to, in_axes=(1, 1, None, None))(a.T, b.T, w, pad),
        compiler_options=KERNEL_COMPILER_OPTIONS,
    )  # the scheduling before issue 2
    t = interleaved(
        {"api": lambda: env.steer_to(a, b), "vmap": lambda: vmapped(env.world, a, b)}, reps
    )
    cores = interleaved.cores
    free = np.asarray(env.steer_to(a, b))
    same = bool(np.array_equal(free, np.asarray(vmapped(env.world, a, b))))
    kind = "rigid body" if robot.kind == "rigid_body" else f"{robot.dim}-link arm"
    return [
        {
            "name": f"{kind} motion checks, Env.steer_to ({name}, pad {pad:g})",
            "n": n,
            "per_second": n / t["api"],
            "goal": goal,
            "free_fraction": float(free.mean()),
            "resolution": robot.resolution,
            "cores": cores["api"],
        },
        {
            "name": f"{kind} motion checks, jax.vmap(one-query kernel) baseline",
            "n": n,
            "per_second": n / t["vmap"],
            "same_answers": same,
            "cores": cores["vmap"],
        },
        {"name": f"ratio {kind} Env.steer_to / vmap", "ratio": t["vmap"] / t["api"]},
    ]


def _short_motions(env, key, n: int, pad: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """``n`` valid pairs whose second state is the first plus a random step of metric length
    up to about ``length`` (steps of the size a PNet predicts), kept where both are valid."""
    robot = env.robot
    out_a, out_b = [], []
    rng = np.random.default_rng(int(jax.random.randint(key, (), 0, 2**31 - 1)))
    while sum(len(x) for x in out_a) < n:
        a = np.asarray(env.sample_states(jax.random.fold_in(key, len(out_a)), n, padding=pad))
        step = rng.normal(size=a.shape) / np.asarray(robot.metric_weights)
        step *= (length * rng.uniform(size=(n, 1))) / np.linalg.norm(
            step * np.asarray(robot.metric_weights), axis=1, keepdims=True
        )
        b = (a + step).astype(np.float32)
        if robot.kind == "rigid_body":
            b[:, 2] = (b[:, 2] + np.pi) % (2 * np.pi) - np.pi
        ok = np.asarray(env.is_valid(b, padding=pad))
        out_a.append(a[ok])
        out_b.append(b[ok])
    return np.concatenate(out_a)[:n], np.concatenate(out_b)[:n]


def bench_certified(
    name: str,
    n: int,
    reps: int,
    goal: float | None,
    pad: float | None = None,
    short: float | None = None,
) -> list[dict]:
    """The certified motion check against the discretised one, side by side, same motions.

    Motions: uniform random valid pairs (``short`` None), or PNet-step-like pairs
    (a valid state and a random step of metric length up to ``short``).
    """
    env = nj.make_env(name)
    pad = env.padding if pad is None else pad
    key = jax.random.key(1)
    if short is None:
        s = np.asarray(env.sample_states(key, 2 * n, padding=pad))
        a, b = jnp.asarray(s[:n]), jnp.asarray(s[n:])
        what = "uniform valid pairs"
    else:
        a, b = (jnp.asarray(x) for x in _short_motions(env, key, n, pad, short))
        what = f"steps <= {short:g}"
    t = interleaved(
        {
            "certified": lambda: env.steer_to(a, b, padding=pad, check="certified"),
            "discretized": lambda: env.steer_to(a, b, padding=pad),
        },
        reps,
    )
    cores = interleaved.cores
    cert = np.asarray(env.steer_to(a, b, padding=pad, check="certified"))
    disc = np.asarray(env.steer_to(a, b, padding=pad))
    kind = "rigid body" if env.robot.kind == "rigid_body" else f"{env.robot.dim}-link arm"
    row = {
        "name": f"{kind} certified motion checks ({name}, pad {pad:g}, {what})",
        "n": n,
        "per_second": n / t["certified"],
        "free_fraction": float(cert.mean()),
        "cores": cores["certified"],
        "certified_free_discretized_blocked": int(np.sum(cert & ~disc)),
        "discretized_free_certified_blocked": int(np.sum(disc & ~cert)),
    }
    if goal is not None:
        row["goal"] = goal
    return [
        row,
        {
            "name": f"{kind} discretised motion checks, same motions",
            "n": n,
            "per_second": n / t["discretized"],
            "free_fraction": float(disc.mean()),
            "cores": cores["discretized"],
        },
        {
            "name": f"ratio {kind} certified / discretised throughput",
            "ratio": t["discretized"] / t["certified"],
        },
        {
            "name": f"{kind}: free by discretised, blocked by certified",
            "n": n,
            "value": float(np.sum(disc & ~cert)),
        },
    ]


def bench_all_certified(quick: bool, reps: int) -> list[dict]:
    n_r, n_a = (2 * 10**4, 10**4) if quick else (10**5, 10**5)
    rows = []
    rows += bench_certified("rigid/3", n_r, reps, GOALS["rigid_cert_cps"])
    rows += bench_certified("nlink/6", n_a, reps, GOALS["arm_cert_cps"])
    rows += bench_certified("rigid/3", n_r, reps, None, pad=0.0)
    rows += bench_certified("nlink/6", n_a, reps, None, pad=0.0)
    rows += bench_certified("rigid/3", n_r, reps, None, pad=0.0, short=2.0)
    rows += bench_certified("nlink/6", n_a, reps, None, pad=0.0, short=1.0)
    return rows


# ---------------------------------------------------------------------------


def _fmt(v: float) -> str:
    return f"{v:,.0f}" if v >= 100 else f"{v:.3g}"


def print_table(rows: list[dict]) -> None:
    print(f"{'measurement':<66} {'n':>13} {'value':>16} {'cores':>5} {'goal':>8}  ok")
    for r in rows:
        if "per_second" in r and "seconds" not in r:
            val = _fmt(r["per_second"]) + "/s"
        elif "seconds" in r and "value" not in r:
            val = f"{r['seconds']:.2f} s"
        elif "ratio" in r:
            val = f"{r['ratio']:,.3g}x" if r["ratio"] < 1000 else f"{r['ratio']:,.0f}x"
        else:
            val = _fmt(r["value"])
        goal, ok = "", ""
        if "goal" in r:
            key = "ratio" if "ratio" in r else ("seconds" if "seconds" in r else "per_second")
            got = r[key]
            met = (
                got <= r["goal"] if (key == "seconds" or r.get("goal_is_max")) else got >= r["goal"]
            )
            r["goal_met"] = bool(met)
            goal = f"{r['goal']:.3g}"
            ok = "yes" if met else "NO"
        n = f"{r['n']:,}" if "n" in r else ""
        cores = f"{r['cores']:.2f}" if "cores" in r else ""
        print(f"{r['name']:<66} {n:>13} {val:>16} {cores:>5} {goal:>8}  {ok}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="smaller sizes, no 1e9 runs (< 1 minute)")
    ap.add_argument(
        "--skip-1e9",
        action="store_true",
        help="skip the 1e9-query gamma_nt runs (memory check uses 1e7 vs 1e8)",
    )
    ap.add_argument(
        "--reps", type=int, default=None, help="interleaved repeats (default 7, quick 3)"
    )
    ap.add_argument("--json", type=Path, default=None, help="also write all rows as JSON")
    ap.add_argument(
        "--only",
        choices=("numpy", "certified"),
        default=None,
        help="run only one part: numpy = the NumPy-input steer_to comparison, "
        "certified = certified vs discretised motion checks",
    )
    args = ap.parse_args(argv)
    quick = args.quick
    skip_1e9 = args.skip_1e9 or quick
    reps = args.reps or (3 if quick else 7)

    t_start = time.time()
    load0 = os.getloadavg()
    env = nj.Env.from_json(MAP)
    print(
        f"jax {jax.__version__}, {os.cpu_count()} CPUs, devices {jax.devices()}; "
        f"load average {load0[0]:.2f} at start; map {env.name}: {env.world.num_boxes} boxes, "
        f"padding {env.padding}"
    )
    rows = []
    if args.only == "certified":
        return _report(args, argv, bench_all_certified(quick, reps), t_start, load0)
    rows += bench_numpy_steer("point/3", n=10**7, reps=reps if not quick else 5)
    if args.only == "numpy":
        return _report(args, argv, rows, t_start, load0)
    rows += bench_point_steer(
        env,
        n=10**7,
        n_numpy=10**6 if not quick else 3 * 10**5,
        n_loop=2000 if not quick else 300,
        reps=reps,
    )
    rows += bench_gamma(env, n=10**8 if not quick else 2 * 10**7, reps=3 if not quick else 2)
    if not skip_1e9:
        rows += bench_gamma_1e9(env)
    rows += bench_motions(
        "rigid/3",
        n=10**5 if not quick else 2 * 10**4,
        reps=reps if not quick else 2,
        goal=GOALS["rigid_cps"],
    )
    rows += bench_motions(
        "nlink/6",
        n=10**5 if not quick else 10**4,
        reps=reps if not quick else 2,
        goal=GOALS["arm_cps"],
    )
    rows += bench_all_certified(quick, reps)
    rows += bench_memory((10**7, 10**9) if not skip_1e9 else (10**7, 10**8))
    return _report(args, argv, rows, t_start, load0)


def _report(args, argv, rows, t_start, load0) -> int:
    load1 = os.getloadavg()
    print()
    print_table(rows)
    for r in rows:
        if "same_as_device" in r:
            print(
                f"answers equal to the device-array answers: {r['same_as_device']}  ({r['name']})"
            )
    print(
        f"\nload average {load0[0]:.2f} -> {load1[0]:.2f}; total {time.time() - t_start:.0f} s. "
        "cores = process CPU time / wall time during the measurement (2 = both cores of this "
        "machine); the machine is shared, so compare the side-by-side ratios."
    )
    if args.json:
        out = {
            "command": " ".join(
                [Path(sys.argv[0]).name] + (argv if argv is not None else sys.argv[1:])
            ),
            "jax": jax.__version__,
            "cpus": os.cpu_count(),
            "load_average": [load0[0], load1[0]],
            "map": MAP,
            "rows": rows,
        }
        artifacts.write_json(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
