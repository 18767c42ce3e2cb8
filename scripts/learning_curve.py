#!/usr/bin/env python
"""Data-efficiency curve: every dataset trained at several K_train on one map, then evaluated.

Examples::

    python scripts/learning_curve.py --config configs/point.yaml --sizes 250,500,1000,2000,3000
    python scripts/learning_curve.py --env point/2 --sizes 100,300,600 --out runs/curve_p2

The datasets D0..D3 are generated once, at the largest size; a smaller size
uses the first K queries of each (a prefix: :mod:`ntq_jax.experiment.curve`), so only
training and evaluation repeat. Every size is evaluated on the same test
queries (from the run seed and the map). Writes ``<out>/curve.json`` (one row
per size, dataset and test-query kind: training rows, success with its 95 %
Wilson interval, cost ratio), ``curve.md`` and ``curve.png``. Rerunning the
same command resumes: finished sizes are reused, an interrupted one resumes
training from its last checkpoint. ``--env`` defaults to the config's first
map; every size must be in 1..the config's k_train for that map. Expected
errors are one ``error:`` line, exit code 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ntq_jax.experiment.cli import (
    add_run_options,
    check_writable_folder,
    executor_of,
    run_cli,
    start_run,
)


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--env", default=None, help="the map (default: the config's first)")
    ap.add_argument(
        "--sizes",
        default="250,500,1000,2000,3000",
        help="comma-separated K_train values (default 250,500,1000,2000,3000)",
    )
    ap.add_argument(
        "--out",
        default=None,
        help="curve folder (default: <out_dir>/curve-<map>-<config hash>; rerun to resume)",
    )
    add_run_options(
        ap,
        set_example="train.epochs=20",
        figures_help="skip curve.png",
        cpu_devices_help="JAX CPU devices to create (the PNets train on separate cores); default 1",
        executor=True,
    )
    args = ap.parse_args(argv)
    start_run(args)  # before any JAX operation
    from ntq_jax.envs import env_slug, resolve_envs
    from ntq_jax.experiment.curve import parse_sizes, run_curve
    from ntq_jax.experiment.pipeline import load_config

    cfg = load_config(args.config, args.set)
    env_name = args.env or cfg.envs[0]
    env = resolve_envs([env_name])[env_name]  # a bad map is an error before anything is written
    sizes = parse_sizes(args.sizes, cfg.data.k_train_for(env_name))
    out = (
        Path(args.out)
        if args.out
        else (Path(cfg.out_dir) / f"curve-{env_slug(env_name, env)}-{cfg.hash()[:8]}")
    )
    check_writable_folder(out, "--out")  # before any work
    print(f"curve folder: {out}", flush=True)
    t0 = time.perf_counter()
    files = run_curve(
        cfg,
        env_name,
        sizes,
        out,
        progress=not args.no_progress,
        figures=not args.no_figures,
        executor=executor_of(args, cfg),
    )
    print()
    print(Path(files["md"]).read_text())
    print(f"done in {time.perf_counter() - t0:.0f} s; curve folder: {out}")
    for k, v in files.items():
        if v is not None:
            print(f"  {k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
