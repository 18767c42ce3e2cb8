#!/usr/bin/env python
"""How many successes of a run evaluated with the discretised check the certified check rejects.

Reads a finished run folder (``python scripts/train_all.py ... --set
eval.motion_check=discretized``) and re-checks every saved success
(``paths/<env>/PNet_<m>_<kind>[_nosteer].npz``) and every reference path
(``eval/<env>/reference.npz``) with both motion checks at padding 0
(:func:`ntq_jax.experiment.metrics.recheck_paths`, :func:`ntq_jax.planners.verify.check_paths`),
and counts how many of the rejected ones a dense check (the robot's own
``is_valid`` at ``resolution / 100`` steps along the rejected segments) finds
in collision: the rest pass too close to an obstacle to be proven (within the
certified check's margin) or the sweep gave up on them.
Prints one row per (environment, model, query kind, steerTo) and writes them as
JSON with ``--json``::

    python benchmarks/diagnostics/recheck_motion_checks.py --run runs/rigid_disc --json rigid.json
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import yaml

import ntq_jax as nj
from ntq_jax import artifacts
from ntq_jax.envs import env_slug
from ntq_jax.experiment.metrics import recheck_paths
from ntq_jax.planners.verify import check_paths
from ntq_jax.robots.batch import distances, steer_to_pairs, valid_states
from ntq_jax.types import PlanStatus

DENSE = 100  # the dense check's step: the robot's resolution / DENSE


def dense_collides(env, paths: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``(K,)`` bool: some state of the path, sampled ``resolution / DENSE`` apart along each
    segment the certified check rejects, is invalid at padding 0 (a real collision, not an
    unproven near-touch)."""
    robot = env.robot
    out = np.zeros(len(paths), bool)
    step = robot.resolution / DENSE
    for i, (p, n) in enumerate(zip(paths, lengths)):
        a, b = p[: n - 1], p[1:n]
        bad = ~steer_to_pairs(robot, env.world, a, b, 0.0, check="certified")
        for sa, sb in zip(a[bad], b[bad]):
            m = int(np.ceil(float(distances(robot, sa[None], sb[None])[0]) / step)) + 1
            t = np.linspace(0.0, 1.0, m, dtype=np.float32)[:, None]
            q = sa[None] + t * (sb - sa)[None]
            if robot.kind == "rigid_body":  # shortest arc, as the robot interpolates
                dth = (sb[2] - sa[2] + np.pi) % (2 * np.pi) - np.pi
                q[:, 2] = (sa[2] + t[:, 0] * dth + np.pi) % (2 * np.pi) - np.pi
            if not valid_states(robot, env.world, q, 0.0).all():
                out[i] = True
                break
    return out


def recheck_run(run: Path) -> list[dict]:
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    delta = float(cfg["eval"]["delta"])
    rows = []
    for name in cfg["envs"]:
        env = nj.make_env(name)
        slug = env_slug(name, env)
        ref = artifacts.load_npz(run / "eval" / slug / "reference.npz")
        for kind in ("uniform", "nontrivial"):
            if ref is None:
                break
            solved = ref[f"{kind}_status"] == PlanStatus.SOLVED
            paths, n = ref[f"{kind}_paths"][solved], ref[f"{kind}_lengths"][solved]
            ok_d, _ = check_paths(env, paths, n, 0.0, "discretized")
            ok_c, _ = check_paths(env, paths, n, 0.0, "certified")
            rej = np.flatnonzero(ok_d & ~ok_c)
            rows.append(
                {
                    "env": name,
                    "model": "reference",
                    "query_kind": kind,
                    "steer": True,
                    "k_test": int(len(solved)),
                    "successes_discretized": int(ok_d.sum()),
                    "rejected_by_certified": int(len(rej)),
                    "rejected_colliding": int(dense_collides(env, paths[rej], n[rej]).sum()),
                }
            )
        for f in sorted((run / "paths" / slug).glob("PNet_*.npz")):
            z = artifacts.load_npz(f)
            succ = np.asarray(z["success"], bool)
            t0 = time.perf_counter()
            ok_d = recheck_paths(env, f, delta=delta, check="discretized")
            ok_c = recheck_paths(env, f, delta=delta, check="certified")
            parts = f.stem.split("_")
            rej = np.flatnonzero(succ & ok_d & ~ok_c)
            coll = dense_collides(env, z["paths"][rej], z["lengths"][rej])
            rows.append(
                {
                    "env": name,
                    "model": "_".join(parts[:2]),
                    "query_kind": parts[2],
                    "steer": not f.stem.endswith("_nosteer"),
                    "k_test": int(len(succ)),
                    "successes_discretized": int(np.sum(succ & ok_d)),
                    "rejected_by_certified": int(len(rej)),
                    "rejected_colliding": int(coll.sum()),
                    "recheck_seconds": time.perf_counter() - t0,
                }
            )
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--run",
        type=Path,
        required=True,
        action="append",
        help="a finished run folder evaluated with eval.motion_check=discretized (repeatable)",
    )
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = []
    for run in args.run:
        if not (run / "config.yaml").is_file():
            print(f"error: {run} is not a run folder (no config.yaml)", file=sys.stderr)
            return 2
        rows += recheck_run(run)
    print(
        f"{'env':<9} {'model':<10} {'kind':<11} {'steer':<6} {'K':>5} {'succ (disc)':>12} "
        f"{'rejected (cert)':>16} {'of which collide':>17}"
    )
    for r in rows:
        print(
            f"{r['env']:<9} {r['model']:<10} {r['query_kind']:<11} {str(r['steer']):<6} "
            f"{r['k_test']:>5} {r['successes_discretized']:>12} {r['rejected_by_certified']:>16} "
            f"{r['rejected_colliding']:>17}"
        )
    for who, sel in (
        ("neural planner", lambda r: r["model"] != "reference"),
        ("reference planner", lambda r: r["model"] == "reference"),
    ):
        tot_s = sum(r["successes_discretized"] for r in rows if sel(r))
        tot_r = sum(r["rejected_by_certified"] for r in rows if sel(r))
        tot_c = sum(r["rejected_colliding"] for r in rows if sel(r))
        print(
            f"{who} successes (discretised check): {tot_s}; rejected by the certified check: "
            f"{tot_r} ({tot_r / max(tot_s, 1):.2%}), of which a dense check at resolution/{DENSE} "
            f"finds in collision: {tot_c}"
        )
    if args.json:
        artifacts.write_json(args.json, {"runs": [str(r) for r in args.run], "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
