#!/usr/bin/env python
"""Generates the datasets D0..D3 (Alg. 2 and 4) for every environment of a config.

Examples::

    python scripts/generate_data.py --config configs/point_small.yaml
    python scripts/generate_data.py --config configs/point.yaml --env point/2 --out runs/data
    python scripts/generate_data.py --config configs/nlink.yaml --set data.chunk=100

Writes ``<out>/<env_slug>/env.json``, ``<out>/<env_slug>/D0..D3/`` (see
:mod:`ntq_jax.data`) and ``<out>/<env_slug>/figure.png``. Rerunning the same
command after an interruption (Ctrl-C, kill -9) resumes from the completed
chunks; a complete output is left as it is.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path



def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=None, help="YAML config (default: built-in defaults)")
    ap.add_argument("--env", action="append", default=None,
                    help="environment(s) to generate (default: every one in the config's envs)")
    ap.add_argument("--out", default=None, help="output root (default: <out_dir>/data)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="config override, e.g. --set data.k_train=100 (repeatable)")
    ap.add_argument("--planner", default=None,
                    help="planner name overriding planner.name (astar, visgraph, bitstar, roadmap)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    ap.add_argument("--no-figure", action="store_true", help="skip the PNG figures")
    args = ap.parse_args(argv)

    from ntq_jax import config as C
    from ntq_jax import artifacts, data, make_env
    from ntq_jax.envs import EnvError

    overrides = list(args.set)
    if args.planner:
        overrides.append(f"planner.name={args.planner}")
    try:
        cfg = C.load(args.config, overrides)
    except C.ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    envs = args.env or list(cfg.envs)
    out = Path(args.out) if args.out else Path(cfg.out_dir) / "data"
    results = {}
    for name in envs:
        try:
            env = make_env(name)
        except EnvError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        s = data.generate_datasets(env, cfg, out, env_name=name, progress=not args.no_progress,
                                   figure=not args.no_figure)
        results[name] = s
        state = "already complete" if s["skipped"] else (
            f"done in {s['timings']['total']:.1f} s"
            + (f" (reused {s['reused_queries']} planned queries)" if s["reused_queries"] else ""))
        print(f"{name}: {s['env_dir']} {state}")
        for ds, st in s["datasets"].items():
            print(f"  {ds}: {st['queries']} queries, {st['solved']} solved, {st['samples']} "
                  f"samples, pruned {st['fraction_pruned']:.1%}, mean waypoints "
                  f"{st['mean_waypoints']:.2f}, blocked {st['blocked_fraction']:.3f} "
                  f"(gamma_nt {st['gamma_nt']})")
    artifacts.write_json(out / "generate_summary.json", results, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
