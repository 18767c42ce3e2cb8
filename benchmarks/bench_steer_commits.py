#!/usr/bin/env python
"""The public point ``Env.steer_to`` of this checkout against another commit's, alternately.

Two versions of the package cannot share one process, so each round runs one child
process per version (a ``git worktree`` of the other commit under /tmp), one after the
other, and each child times ``Env.steer_to`` on the same 10^7 uniform device-array pairs
of point/3 (padding 0; median of 5 after a warm-up) beside the vectorised NumPy slab
test of bench_steer.py on 10^6 of them. Rounds alternate the order, so a drift of the
machine's load hits both; the medians over rounds are compared.

    python benchmarks/bench_steer_commits.py --against 3db75c4 --rounds 3
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

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, time
import numpy as np, jax, jax.numpy as jnp
import ntq_jax as nj
from numpy_steer import numpy_steer
env = nj.make_env("point/3")
n, n_np = {n}, {n_np}
rng = np.random.default_rng(0)
lo, hi = np.asarray(env.world.bounds)[:, 0], np.asarray(env.world.bounds)[:, 1]
a = (lo + rng.random((n, 2)) * (hi - lo)).astype(np.float32)
b = (lo + rng.random((n, 2)) * (hi - lo)).astype(np.float32)
da, db = jax.block_until_ready((jnp.asarray(a), jnp.asarray(b)))
boxes, bounds = np.asarray(env.world.boxes).tolist(), np.asarray(env.world.bounds).tolist()
def med(f, reps=5):
    jax.block_until_ready(f()); ts = []
    for _ in range(reps):
        t0 = time.perf_counter(); jax.block_until_ready(f()); ts.append(time.perf_counter() - t0)
    return float(np.median(ts))
t_api = med(lambda: env.steer_to(da, db, padding=0))
t_np = med(lambda: numpy_steer(a[:n_np], b[:n_np], boxes, bounds, 0.0), reps=3)
ok = bool((np.asarray(env.steer_to(da[:n_np], db[:n_np], padding=0))
           == numpy_steer(a[:n_np], b[:n_np], boxes, bounds, 0.0)).all())
print(json.dumps({{"api_qps": n / t_api, "numpy_qps": n_np / t_np, "agree": ok}}))
"""


def run_child(src: Path, n: int, n_np: int) -> dict:
    # the version's package first, then this folder (for bench_steer's NumPy baseline)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(src), str(HERE)]))
    code = CHILD.format(n=n, n_np=n_np)
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        cwd=str(src),
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", default="3db75c4")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--n", type=int, default=10_000_000)
    ap.add_argument("--n-numpy", type=int, default=1_000_000)
    args = ap.parse_args(argv)
    here = HERE.parent
    tmp = Path(tempfile.mkdtemp(prefix="ntq_old_"))
    subprocess.run(
        ["git", "-C", str(here), "worktree", "add", "--detach", str(tmp / "src"), args.against],
        check=True,
        capture_output=True,
    )
    try:
        runs = {"this": [], args.against: []}
        for r in range(args.rounds):
            order = [("this", here), (args.against, tmp / "src")]
            for name, src in order if r % 2 == 0 else order[::-1]:
                res = run_child(src, args.n, args.n_numpy)
                runs[name].append(res)
                print(
                    f"round {r}: {name:8s} public steer_to {res['api_qps'] / 1e6:8.1f} M/s, "
                    f"NumPy {res['numpy_qps'] / 1e6:6.1f} M/s, "
                    f"{res['api_qps'] / res['numpy_qps']:5.1f}x, agree {res['agree']}",
                    flush=True,
                )
    finally:
        subprocess.run(
            ["git", "-C", str(here), "worktree", "remove", "--force", str(tmp / "src")],
            capture_output=True,
        )
    summary = {}
    for name, rs in runs.items():
        api = float(np.median([x["api_qps"] for x in rs]))
        ratio = float(np.median([x["api_qps"] / x["numpy_qps"] for x in rs]))
        summary[name] = {"api_qps": api, "vs_numpy": ratio}
        print(f"{name:8s} median {api / 1e6:8.1f} M/s, {ratio:5.1f}x NumPy")
    rel = summary["this"]["api_qps"] / summary[args.against]["api_qps"]
    print(
        f"this / {args.against}: {rel:.3f} (goal >= 0.9); this / NumPy "
        f"{summary['this']['vs_numpy']:.1f}x (goal >= 30)"
    )
    return summary


if __name__ == "__main__":
    main()
