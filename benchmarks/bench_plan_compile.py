#!/usr/bin/env python
"""Neural planner: compile time and planning time of two checkouts, and whether they agree.

For one map of a finished run (its trained PNets and saved test queries), a fresh
subprocess per checkout and repeat, alternating (``base``, ``head``, ``base``,
...), plans both query kinds with the planners the evaluation uses: members 0
and 3 (member 3 on a 37-query slice: another batch size), member 1 with narrow
chunks (``chunk=64``, ``repair_width=16``), the ensemble rule, the members side
by side and the cascade. Each subprocess starts with an empty persistent
compilation cache, as on a fresh machine. It prints per checkout the medians of
the compile seconds and the planning seconds (``NeuralPlanResult.seconds``,
excluding compilation), their ratios head/base, and whether every planner's
outputs (paths, lengths, success, costs, causes, PNet calls, replans, members)
hash the same in both checkouts.

    python scripts/train_all.py --out runs/default            # a run to plan on
    python benchmarks/bench_plan_compile.py --run runs/default --env rigid/0 \\
        --base <checkout of the previous commit> --repeats 3

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
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

_CHILD = r"""
import hashlib, json, sys, time
from pathlib import Path
import jax, numpy as np
from ntq_jax import make_env
try:
    from ntq_jax import neural as NP
except ImportError:  # a checkout from before the ntq_jax.neural package (issue 51)
    from ntq_jax import neural_planner as NP
from ntq_jax.experiment import config as C
from ntq_jax.envs import env_slug
from ntq_jax.models import member_pnets
from ntq_jax.training import load_ensemble
run, env_name = Path(sys.argv[1]), sys.argv[2]
env = make_env(env_name)
slug = env_slug(env_name, env)
cfg = C.load(run / "config.yaml", [])
pnets = member_pnets(load_ensemble(run / "models" / slug))
opts = C.neural_options(cfg.eval, steer=True)
queries = np.load(run / "eval" / slug / "queries.npz")
key = jax.random.key(0)

def digest(r):
    h = hashlib.sha256()
    for f in ("paths", "lengths", "success", "costs", "cause", "pnet_calls", "replans", "member"):
        x = getattr(r, f, None)
        if x is not None:
            h.update(np.ascontiguousarray(np.asarray(x)).tobytes())
    return h.hexdigest()[:16]

out = {"compile": 0.0, "plan": 0.0, "hashes": {}}
for kind in ("uniform", "nontrivial"):
    q = np.asarray(queries[kind], np.float32)
    res = {"member 0": NP.plan_batch(env, pnets[0], q, key, opts),
           "member 3 (37 queries)": NP.plan_batch(env, pnets[3], q[:37], key, opts),
           "member 1 (narrow chunks)": NP.plan_batch(env, pnets[1], q, key, opts,
                                                     repair_width=16, chunk=64),
           "ensemble rule": NP.plan_batch(env, pnets, q, key, opts),
           "members side by side": NP.plan_members(env, pnets, q, key, opts)[0],
           "cascade": NP.plan_cascade(env, pnets, q, key, opts)}
    for name, r in res.items():
        out["compile"] += r.compile_seconds
        out["plan"] += r.seconds
        out["hashes"][f"{kind}: {name}"] = digest(r)
print(json.dumps(out))
"""


def child(src: Path, run: Path, env_name: str) -> dict:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, PYTHONPATH=str(src), JAX_COMPILATION_CACHE_DIR=cache)
        r = subprocess.run(
            [sys.executable, "-c", _CHILD, str(run), env_name],
            capture_output=True,
            text=True,
            env=env,
            cwd=str(src),
        )
    if r.returncode:
        tail = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else "failed"
        raise SystemExit(f"error: the planner run in {src} failed: {tail}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="a finished run folder")
    ap.add_argument("--env", default="rigid/0", help="a map of that run")
    ap.add_argument("--base", type=Path, required=True, help="the baseline checkout")
    ap.add_argument("--head", type=Path, default=HERE.parent, help="the new checkout")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path, help="write the figures here")
    args = ap.parse_args(argv)
    for src in (args.base, args.head):
        if not (src / "ntq_jax").is_dir():
            raise SystemExit(f"error: {src} holds no ntq_jax/ (pass a checkout)")
    if not (args.run / "config.yaml").is_file():
        raise SystemExit(f"error: {args.run} is not a finished run (run scripts/train_all.py)")
    got = {"base": [], "head": []}
    for i in range(args.repeats):
        for side in ("base", "head"):
            r = child(getattr(args, side).resolve(), args.run.resolve(), args.env)
            got[side].append(r)
            print(
                f"repeat {i + 1} {side}: compile {r['compile']:.1f} s, planning {r['plan']:.2f} s",
                flush=True,
            )
    med = {
        side: {k: statistics.median(r[k] for r in rows) for k in ("compile", "plan")}
        for side, rows in got.items()
    }
    same = all(r["hashes"] == got["base"][0]["hashes"] for rows in got.values() for r in rows)
    summary = {
        "env": args.env,
        "repeats": args.repeats,
        "median": med,
        "ratio_head_to_base": {k: med["head"][k] / med["base"][k] for k in med["base"]},
        "outputs_identical": same,
    }
    print(json.dumps(summary, indent=1))
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
