#!/usr/bin/env python
"""The whole pipeline: generate D0..D3 -> train the PNet ensemble -> evaluate -> report.

Examples::

    python scripts/train_all.py                                 # embedded default (point/0-3, rigid/0)
    python scripts/train_all.py --config configs/rigid_small.yaml
    python scripts/train_all.py --config configs/point.yaml --out runs/point_paper
    python scripts/train_all.py --set eval.k_test=100 --set envs=[point/0]

Without ``--config`` the embedded default runs: the four point-robot maps and
the rigid-body map rigid/0 at reduced sizes (K_train 600, a 256-256-128-64 PNet,
40 epochs, K_test 200; grid A* data for the point robot, the roadmap planner's
for the rigid body; about 3-4 minutes on an idle 2-core CPU). ``--set KEY=VALUE`` overrides any config
key (YAML values).

``--executor ray`` runs the planning chunks (data generation, the evaluation's
reference) as Ray tasks and overlaps the environments' data generation with the
training of the ones whose data is ready; ``--ray-address auto`` joins a running
cluster (README, "Running on a Ray cluster"). The outputs do not depend on the
executor.

The run folder (``--out``, default ``<out_dir>/<task>-<config hash>``) is
described in :mod:`ntq_jax.experiment.pipeline`. Rerunning the same command after an
interruption resumes it (datasets are verified against their checksums first;
a damaged one is regenerated). A non-empty folder that is not a run of this
config (another config, or no valid run.json) is refused: pass another
``--out``, or ``--overwrite`` to delete it and start over. Expected errors
(a bad config, environment, run folder, dataset or checkpoint) are one
``error:`` line with the fix, exit code 2.

The run ends with a headline per map (each PNet's success ratio on uniform and
non-trivial test queries, PNet_3 - PNet_0 with its interval) and the paths of
``tables.md`` and the figures; ``--full-tables`` prints every table as well.
"""

from __future__ import annotations

import argparse
import sys
import time

from ntq_jax.experiment.cli import add_run_options, executor_of, run_cli, start_run
from ntq_jax.experiment.headline import headline
from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--out",
        default=None,
        help="run folder (default: <out_dir>/<task>-<config hash>; rerun to resume)",
    )
    ap.add_argument(
        "--overwrite",
        action="store_true",
        help="delete --out first when it is not a run of this config (another "
        "config, or run.json missing or corrupt) and start over; only a folder "
        "holding nothing but a run's files is deleted",
    )
    ap.add_argument(
        "--full-tables",
        action="store_true",
        help="also print every table of tables.md (the end of a run prints a "
        "headline per map and where the tables and figures are)",
    )
    add_run_options(
        ap,
        set_example="eval.k_test=100",
        figures_help="skip the PNG figures",
        cpu_devices_help="JAX CPU devices to create (one per core): the four PNets "
        "train on separate cores (speed: BENCHMARKS.md); results then differ from a "
        "one-device run at float level. Default 1",
        executor=True,
    )
    args = ap.parse_args(argv)
    start_run(args)  # before any JAX operation
    cfg = load_config(args.config, args.set)
    executor = executor_of(args, cfg)
    run = prepare_run(cfg, args.out, overwrite=args.overwrite)  # validates before writing
    print(f"run folder: {run}", flush=True)
    t0 = time.perf_counter()
    out = run_pipeline(
        cfg, run, progress=not args.no_progress, figures=not args.no_figures, executor=executor
    )
    print()
    if args.full_tables:
        print((run / "tables.md").read_text())
    print("\n".join(headline(run)))
    print(f"done in {time.perf_counter() - t0:.0f} s; run folder: {run}")
    for k, v in out.items():
        print(f"  {k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
