#!/usr/bin/env python
"""Obstacle-count scaling (issue 18): compile time, peak memory and throughput on many boxes.

* **First call**: a fresh subprocess per case builds an environment with 2,000
  random boxes (100 x 100 workspace) and times its first ``Env.steer_to`` call
  (1,024 random pairs: tracing, compilation and the run) and a second call;
  ``ru_maxrss`` of the subprocess is its peak memory (the JAX import alone is
  measured too, as the floor). Cases: the point robot and the rigid body (and,
  with ``--with-arm``, the 2-link arm), and the discretised and certified checks.
* **Throughput**, side by side in ONE process with interleaved repeats (medians):
  ``Env.steer_to`` per query on a 256 x 256 MovingAI-style maze (imported with the
  rectangle cover; the point robot at 1 unit per cell, the rigid body at 2) against
  the 9-box preset ``point/3`` and the 11-box ``rigid/3``, on random pairs
  (uniform in the workspace, every pair checked; padding 0 and the map's padding).

    python benchmarks/bench_obstacles.py                  # everything, a few minutes
    python benchmarks/bench_obstacles.py --only compile   # the first-call cases
    python benchmarks/bench_obstacles.py --only throughput --json out.json
    python benchmarks/bench_obstacles.py --src /work/wt/maps-base --only compile  # another checkout

``--src`` imports ``ntq_jax`` from another checkout in the subprocesses (the
previous commit, for the before/after figures; its first calls take minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from common import interleaved

HERE = Path(__file__).resolve().parent
GOALS = {"compile_seconds": 5.0, "peak_rss_mb": 500.0, "maze_vs_preset_slowdown": 10.0}


def random_boxes_map(robot: dict, n: int = 2000, seed: int = 0, padding: float = 0.2) -> dict:
    """A JSON map with ``n`` random boxes (half sizes 0.1..0.6) on 100 x 100."""
    rng = np.random.default_rng(seed)
    boxes = np.c_[rng.uniform(0, 100, (n, 2)), rng.uniform(0.1, 0.6, (n, 2))]
    return {
        "name": f"random{n}",
        "robot": robot,
        "bounds": [[0, 100], [0, 100]],
        "boxes": np.round(boxes, 4).tolist(),
        "discs": [],
        "padding": padding,
    }


# ---------------------------------------------------------------------------
# First call, one subprocess per case
# ---------------------------------------------------------------------------

_CHILD = r"""
import json, resource, sys, time
t0 = time.perf_counter()
import jax, numpy as np
import ntq_jax as nj
spec, check, n = json.loads(sys.argv[1]), sys.argv[2], int(sys.argv[3])
floor = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
t_import = time.perf_counter() - t0
env = nj.Env.from_json(spec)
rng = np.random.default_rng(0)
lo, hi = (np.asarray(v, np.float32) for v in env.robot.config_bounds(env.world))
a = jax.numpy.asarray(rng.uniform(lo, hi, (n, env.dim)).astype(np.float32))
b = jax.numpy.asarray(rng.uniform(lo, hi, (n, env.dim)).astype(np.float32))
t0 = time.perf_counter()
out = np.asarray(env.steer_to(a, b, check=check))
first = time.perf_counter() - t0
t0 = time.perf_counter()
np.asarray(env.steer_to(a, b, check=check))
second = time.perf_counter() - t0
print(json.dumps({"first_call_s": first, "second_call_s": second, "free": float(out.mean()),
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "import_rss_mb": floor, "import_s": t_import,
                  "ntq_jax": nj.__file__,
                  "indexed": getattr(env.world, "index", None) is not None}))
"""


def first_call(spec: dict, check: str, src: str | None, n: int = 1024) -> dict:
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = src
    r = subprocess.run(
        [sys.executable, "-c", _CHILD, json.dumps(spec), check, str(n)],
        capture_output=True,
        text=True,
        env=env,
        cwd=src or None,
    )
    if r.returncode:
        return {"error": r.stderr.strip().splitlines()[-1] if r.stderr.strip() else "failed"}
    return json.loads(r.stdout.strip().splitlines()[-1])


def bench_compile(src: str | None, with_arm: bool, certified: bool = True) -> list[dict]:
    cases = [
        ("point", {"kind": "point"}, "discretized"),
        ("rigid_body", {"kind": "rigid_body", "length": 1.2, "width": 0.4}, "discretized"),
    ]
    if certified:
        cases.append(
            ("rigid_body", {"kind": "rigid_body", "length": 1.2, "width": 0.4}, "certified")
        )
    if with_arm:
        cases.append(
            (
                "nlink",
                {"kind": "nlink", "link_lengths": [8.0, 8.0], "base": [50.0, 50.0]},
                "discretized",
            )
        )
    rows = []
    for name, robot, check in cases:
        res = first_call(random_boxes_map(robot), check, src)
        res.update(
            name=f"first steer_to call, 2000 boxes, {name}, {check}",
            goal_first_call_s=GOALS["compile_seconds"],
            goal_peak_rss_mb=GOALS["peak_rss_mb"],
        )
        print(json.dumps(res), flush=True)
        rows.append(res)
    return rows


# ---------------------------------------------------------------------------
# Throughput, one process
# ---------------------------------------------------------------------------


def bench_throughput(n_point: int, n_rigid: int, reps: int) -> list[dict]:
    import jax

    import ntq_jax as nj
    from ntq_jax.grid_maps import maze_grid, write_movingai

    tmp = Path(tempfile.mkdtemp())
    maze = write_movingai(tmp / "maze256.map", maze_grid(256))
    envs = {
        "point maze256": nj.make_env(maze, padding=0.2),
        "point/3": nj.make_env("point/3"),
        "rigid maze256 (scale 2)": nj.make_env(
            maze, scale=2.0, padding=0.2, robot={"kind": "rigid_body", "length": 1.2, "width": 0.4}
        ),
        "rigid/3": nj.make_env("rigid/3"),
    }
    rows = []
    for e in envs.values():
        print(
            f"{e.name}: {e.world.num_boxes} boxes"
            + (
                f", index {e.world.index.nx}x{e.world.index.ny} cells of {e.world.index.cell:.3g}, "
                f"K={e.world.index.capacity}, reach {e.world.index.reach:.3g}"
                if e.world.index
                else ""
            ),
            flush=True,
        )
    rng = np.random.default_rng(0)
    data = {}
    for name, e in envs.items():
        n = n_point if e.robot.kind == "point" else n_rigid
        lo, hi = (np.asarray(v, np.float32) for v in e.robot.config_bounds(e.world))
        data[name] = [
            jax.numpy.asarray(rng.uniform(lo, hi, (n, e.dim)).astype(np.float32)) for _ in range(2)
        ]
    for pad_name in ("0", "map"):
        cases = {}
        for name, e in envs.items():
            p = 0.0 if pad_name == "0" else e.padding
            a, b = data[name]
            cases[name] = lambda e=e, a=a, b=b, p=p: e.steer_to(a, b, padding=p)
        t = interleaved(cases, reps)
        per_q = {k: t[k] / data[k][0].shape[0] for k in t}
        for k in t:
            free = float(np.asarray(cases[k]()).mean())
            rows.append(
                {
                    "name": f"steer_to {k}, pad {pad_name}",
                    "n": data[k][0].shape[0],
                    "per_second": 1.0 / per_q[k],
                    "free_fraction": free,
                }
            )
        for maze_k, preset_k in (
            ("point maze256", "point/3"),
            ("rigid maze256 (scale 2)", "rigid/3"),
        ):
            rows.append(
                {
                    "name": f"slowdown per query, {maze_k} / {preset_k}, pad {pad_name}",
                    "ratio": per_q[maze_k] / per_q[preset_k],
                    "goal": GOALS["maze_vs_preset_slowdown"],
                }
            )
        for r in rows[-6:]:
            print(json.dumps(r), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--only", choices=("compile", "throughput"))
    ap.add_argument(
        "--src", help="import ntq_jax from this checkout in the first-call subprocesses"
    )
    ap.add_argument("--with-arm", action="store_true", help="also the 2-link arm's first call")
    ap.add_argument("--no-certified", action="store_true", help="skip the certified first call")
    ap.add_argument("--n-point", type=int, default=1 << 18)
    ap.add_argument("--n-rigid", type=int, default=1 << 14)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args(argv)
    rows = [{"name": "load average", "value": os.getloadavg()}]
    print(json.dumps(rows[0]), flush=True)
    if args.only in (None, "compile"):
        rows += bench_compile(args.src, args.with_arm, not args.no_certified)
    if args.only in (None, "throughput"):
        rows += bench_throughput(args.n_point, args.n_rigid, args.reps)
    rows.append({"name": "load average (end)", "value": os.getloadavg()})
    print(json.dumps(rows[-1]), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
