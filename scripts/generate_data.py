#!/usr/bin/env python
"""Generates the datasets D0..D3 (Alg. 2 and 4) for every environment of a config.

Examples::

    python scripts/generate_data.py --config configs/point_small.yaml
    python scripts/generate_data.py --config configs/point.yaml --env point/2 --out runs/data
    python scripts/generate_data.py --config configs/nlink.yaml --set data.chunk=100
    python scripts/generate_data.py --config configs/rigid.yaml --executor ray --ray-address auto

Writes ``<out>/<env_slug>/env.json``, ``config.yaml`` (the resolved config),
``D0..D3/`` (see :mod:`ntq_jax.data`) and ``figure.png``. Rerunning the same
command after an interruption (Ctrl-C, kill -9) resumes from the completed
chunks. A complete output is verified against the checksums in its meta.json
files and left as it is; a damaged dataset (truncated or corrupt array) is
regenerated, and only the damaged ones are rewritten. Expected errors are one
``error:`` line with the fix, exit code 2.

``--executor ray`` plans every chunk as a Ray task (a local Ray instance, or the
cluster of ``--ray-address auto``) and generates the environments concurrently;
the outputs are those of ``--executor local`` (byte for byte with the
deterministic planners), and either executor resumes the other's run.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ThreadPoolExecutor
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
    add_run_options(
        ap,
        set_example="data.k_train=100",
        figures_help="skip the PNG figures",
        cpu_devices_help="JAX CPU devices to create (default 1)",
        executor=True,
    )
    ap.add_argument(
        "--env",
        action="append",
        default=None,
        help="environment(s) to generate (default: every one in the config's envs)",
    )
    ap.add_argument("--out", default=None, help="output root (default: <out_dir>/data)")
    ap.add_argument(
        "--planner",
        default=None,
        help="planner name overriding planner.name (astar, visgraph, bitstar, roadmap)",
    )
    args = ap.parse_args(argv)
    start_run(args)

    from ntq_jax import artifacts, data, make_env
    from ntq_jax.experiment import config as C

    overrides = list(args.set)
    if args.planner:
        overrides.append(f"planner.name={args.planner}")
    cfg = C.load(args.config, overrides)
    envs = args.env or list(cfg.envs)
    out = Path(args.out) if args.out else Path(cfg.out_dir) / "data"
    check_writable_folder(out, "--out")  # before any work
    made = {name: make_env(name) for name in envs}  # every env valid before any work
    from ntq_jax.experiment.pipeline import check_planners

    check_planners(cfg, made)
    executor = executor_of(args, cfg)

    def one(name):
        return data.generate_datasets(
            made[name],
            C.data_options(cfg, name),
            out,
            env_name=name,
            progress=not args.no_progress,
            figure=not args.no_figures,
            executor=executor,
        )

    if executor.name == "local" or len(made) == 1:
        summaries = map(one, made)
    else:  # every environment's chunks in flight at once: one driver thread per environment
        executor.start()  # in the main thread
        pool = ThreadPoolExecutor(len(made), thread_name_prefix="ntq_jax-env")
        summaries = pool.map(one, made)
    results = {}
    for name, s in zip(made, summaries):
        results[name] = s
        state = (
            "already complete (verified)"
            if s["skipped"]
            else (
                f"done in {s['timings']['total']:.1f} s"
                + (
                    f" (reused {s['reused_queries']} planned queries)"
                    if s["reused_queries"]
                    else ""
                )
            )
        )
        print(f"{name}: {s['env_dir']} {state}")
        for ds, why in s.get("damaged", {}).items():
            print(
                f"  {ds}: damaged ({why}); "
                + ("rewritten" if ds in s.get("rewritten", []) else "left as it is")
            )
        for ds, st in s["datasets"].items():
            print(
                f"  {ds}: {st['queries']} queries, {st['solved']} solved, {st['samples']} "
                f"samples, pruned {st['fraction_pruned']:.1%}, mean waypoints "
                f"{st['mean_waypoints']:.2f}, blocked {st['blocked_fraction']:.3f} "
                f"(gamma_nt {st['gamma_nt']})"
            )
    artifacts.write_json(out / "generate_summary.json", results, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
