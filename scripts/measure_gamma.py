#!/usr/bin/env python
"""Measure gamma_nt (the non-trivial fraction of uniform queries) of an environment.

Streams N uniform queries in fixed-size chunks (memory stays flat for 1e9 and
beyond), shows progress, and prints the estimate, its 95% Wilson interval,
elapsed seconds and throughput.

    python scripts/measure_gamma.py --env point/3 --queries 100000000
    python scripts/measure_gamma.py --env my_map.json --queries 1e6 --padding 0.8 --json out.json

The default padding is 0, the evaluation geometry on which the paper reports
gamma_nt; ``--padding`` measures another geometry (e.g. the data-generation one).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


from ntq_jax import artifacts


def _count(text: str) -> int:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v >= 1 and v == int(v)):
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return int(v)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--env", default="point/0", help="preset name (point/0..3, rigid/0..3, "
                    "nlink/2|4|6) or a JSON map file (default: point/0)")
    ap.add_argument("--queries", type=_count, default=10**7,
                    help="uniform valid queries to examine; accepts 1e9 (default: 1e7)")
    ap.add_argument("--padding", type=float, default=0.0,
                    help="clearance of the geometry (default 0: the evaluation geometry)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunk", type=_count, default=None,
                    help="candidate queries per compiled chunk (default: 4M point, 32k others)")
    ap.add_argument("--json", type=Path, default=None, help="also write the result as JSON")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = ap.parse_args(argv)

    import jax
    from tqdm import tqdm

    import ntq_jax as nj

    try:
        env = nj.make_env(args.env)
    except nj.EnvError as e:
        ap.error(str(e))
    if args.padding < 0:
        ap.error(f"--padding must be >= 0, got {args.padding}")

    bar = tqdm(total=args.queries, unit="q", unit_scale=True, disable=args.no_progress,
               desc=f"gamma_nt {env.name}", file=sys.stderr)

    def progress(done):
        bar.update(done - bar.n)

    try:
        est = env.gamma_nt(jax.random.key(args.seed), args.queries, padding=args.padding,
                           chunk=args.chunk, progress=progress)
    except nj.FreeSpaceTooSmall as e:
        bar.close()
        print(f"error: {e}", file=sys.stderr)
        return 2
    bar.close()
    lo, hi = est.ci95
    print(f"env {env.name}  padding {args.padding:g}  queries {est.queries:,}  "
          f"non-trivial {est.non_trivial:,}")
    print(f"gamma_nt = {est.gamma:.6f}  95% CI [{lo:.6f}, {hi:.6f}]")
    print(f"{est.seconds:.2f} s  {est.queries_per_second:,.0f} queries/s  "
          f"({est.candidates_per_second:,.0f} raw candidates/s)")
    if args.json:
        out = {"env": env.name, "padding": args.padding, "seed": args.seed,
               "queries": est.queries, "non_trivial": est.non_trivial, "gamma": est.gamma,
               "ci95": [lo, hi], "seconds": est.seconds,
               "queries_per_second": est.queries_per_second,
               "candidates": est.candidates,
               "candidates_per_second": est.candidates_per_second}
        artifacts.write_json(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
