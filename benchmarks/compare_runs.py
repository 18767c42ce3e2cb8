#!/usr/bin/env python
"""Two runs of one map on the same test queries, compared model by model.

Each model of run B against the same model of run A (e.g. two data settings),
query by query: both runs must have planned the same saved test queries (same
seed, map and evaluation settings; checked). Prints a Markdown table with the
success ratios, the paired difference B - A with its 95 % interval, the
discordant pairs and McNemar's exact p (``ntq_jax.stats``).

    python benchmarks/compare_runs.py --a runs/paper/rigid/rigid_0 \\
        --b runs/diag_rigid0_raw --env rigid/0 --label-a shortcut --label-b raw
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def compare(a: Path, b: Path, env_name: str, steer: bool = True) -> list[dict]:
    import numpy as np

    from ntq_jax import make_env, stats
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment.evaluate import paths_file

    slug = env_slug(env_name, make_env(env_name))
    qa, qb = (np.load(r / "eval" / slug / "queries.npz") for r in (a, b))
    for kind in ("uniform", "nontrivial"):
        if not np.array_equal(qa[kind], qb[kind]):
            raise SystemExit(
                f"error: the runs' {kind} test queries differ; compare runs made "
                "with the same seed, map and eval settings"
            )
    rows = []
    for m in range(4):
        for kind in ("uniform", "nontrivial"):
            fa, fb = (paths_file(r, slug, m, kind, steer) for r in (a, b))
            if not (fa.is_file() and fb.is_file()):
                continue
            sa, sb = (np.load(f)["success"].astype(bool) for f in (fa, fb))
            d = stats.paired_success_difference(sb, sa)
            rows.append(
                {
                    "model": f"PNet_{m}",
                    "kind": kind,
                    "a": float(sa.mean()),
                    "b": float(sb.mean()),
                    "diff": d,
                    "b_only": int((sb & ~sa).sum()),
                    "a_only": int((sa & ~sb).sum()),
                    "p": stats.mcnemar_exact(int((sb & ~sa).sum()), int((sa & ~sb).sum())),
                }
            )
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", type=Path, required=True, help="run folder A (the baseline)")
    ap.add_argument("--b", type=Path, required=True, help="run folder B")
    ap.add_argument("--env", required=True, help="the map, e.g. rigid/0")
    ap.add_argument("--label-a", default="A")
    ap.add_argument("--label-b", default="B")
    ap.add_argument("--no-steer", action="store_true", help="the runs' rows without steerTo")
    args = ap.parse_args(argv)
    rows = compare(args.a, args.b, args.env, not args.no_steer)
    if not rows:
        raise SystemExit("error: no model was evaluated in both runs (paths/<env>/PNet_*.npz)")
    a, b = args.label_a, args.label_b
    print(f"| model | kind | {a} | {b} | {b} - {a} [95 %] | {b} only / {a} only | McNemar p |")
    print("|---|---|---:|---:|---|---:|---:|")
    for r in rows:
        lo, hi = r["diff"]["ci"]
        print(
            f"| {r['model']} | {r['kind']} | {r['a']:.3f} | {r['b']:.3f} | "
            f"{r['diff']['diff']:+.3f} [{lo:+.3f}, {hi:+.3f}] | {r['b_only']} / {r['a_only']} | "
            f"{r['p']:.2g} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
