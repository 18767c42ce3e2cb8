#!/usr/bin/env python
"""Plans one map's data query pools with a chosen planner and keeps the chunks as a record.

Example (the paper's own data planner on rigid/0, 3 s per query, one worker)::

    python scripts/record_paths.py --config configs/rigid.yaml --env rigid/0 \\
        --planner bitstar --pools N,U --chunk 50 --workers 1 \\
        --out results/data_paths/bitstar_rigid_0

The pools are the ones ``generate_data.py`` samples for the same config and map
(``U``: uniform queries, ``N``: non-trivial queries; the same seeds, the same
data padding). Each pool is planned in chunks of ``--chunk`` queries into
``<out>/<pool>/plan_<start>_<stop>.npz`` (``queries``, ``paths`` NaN-padded,
``lengths``, ``costs``, ``status`` as :class:`ntq_jax.types.PlanStatus`,
``rejected``), each written atomically when it finishes; rerunning the same
command resumes from the finished chunks; ``--limit`` plans a prefix of each
pool (the full run later resumes from its chunks). ``<out>/record.json`` names the map,
the config and overrides, the planner, its options, the padding, the seed and the
pools' sizes (:mod:`ntq_jax.data.records`).

A record is never overwritten or mixed: a rerun whose arguments differ from its
``record.json`` in any of these (``--workers`` aside) is refused, naming the
difference, and so is a record whose chunk files hold other queries or cannot be
read (naming the file). One recorder at a time: the folder is locked while it
records; a rerun removes the temporary files a killed recorder left.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ntq_jax.experiment.cli import UsageError, positive_int, run_cli


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _parse(argv) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--config", required=True, help="YAML config of the data run")
    ap.add_argument("--env", required=True, help="the map, e.g. rigid/0")
    ap.add_argument("--planner", default=None, help="planner name (default: the config's)")
    ap.add_argument("--pools", default="N,U", help="pools to plan, in order (default N,U)")
    ap.add_argument("--chunk", type=int, default=50, help="queries per chunk file")
    ap.add_argument("--workers", type=int, default=None, help="BIT* worker processes")
    ap.add_argument(
        "--limit",
        type=int,
        default=None,
        help="plan only the first LIMIT queries of each pool (a prefix: the same "
        "chunk files as the full run, which resumes from them)",
    )
    ap.add_argument("--out", required=True, help="output folder of the record")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override (repeatable)",
    )
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = ap.parse_args(argv)
    args.order = [p.strip() for p in args.pools.split(",") if p.strip()]
    if (
        not args.order
        or any(p not in ("U", "N") for p in args.order)
        or len(set(args.order)) < len(args.order)
    ):
        raise UsageError(f"--pools {args.pools}: expected U and/or N, comma-separated (e.g. N,U)")
    positive_int("--chunk", args.chunk)  # before any work: 0 would never advance
    if args.limit is not None:
        positive_int("--limit", args.limit)
    return args


def _open_record(out: Path, meta: dict) -> None:
    """Refuses a record of other arguments, takes the folder's lock, removes the partial
    writes of a killed recorder."""
    from ntq_jax import artifacts
    from ntq_jax.data import records

    records.check_resume(out, meta)  # before anything is written
    out.mkdir(parents=True, exist_ok=True)
    try:
        artifacts.lock_folder(out)
    except artifacts.FolderInUse as e:
        raise UsageError(
            f"{e}: another recorder is writing this record; wait for it to "
            "finish (two would plan the same queries)"
        ) from None
    for folder in (out, *(out / p for p in records.POOLS)):
        artifacts.clean_tmp(folder)


def _main(argv) -> int:
    args = _parse(argv)

    from ntq_jax import artifacts, make_env
    from ntq_jax.data import records
    from ntq_jax.data.generate import resolve_run
    from ntq_jax.data.pools import sample_pools
    from ntq_jax.experiment import config as C
    from ntq_jax.planners.jobs import plan_pool

    overrides = list(args.set)
    if args.planner:
        overrides.append(f"planner.name={args.planner}")
    if args.workers is not None:
        overrides.append(f"planner.workers={args.workers}")
    cfg = C.load(args.config, overrides)
    env = make_env(args.env)
    out = Path(args.out)
    run = resolve_run(
        env, C.data_options(cfg, args.env), Path(cfg.out_dir) / "data", args.env, None
    )  # roadmap cache there
    meta = {
        "env": args.env,
        "config": args.config,
        "overrides": overrides,
        "planner": run.planner_name,
        "options": run.options,
        "padding": run.padding,
        "seed": cfg.seed,
        "pools": {"U": run.n_u, "N": run.n_nt},
        "fingerprint": run.fingerprint,
    }
    _open_record(out, meta)
    pools = sample_pools(
        env,
        run.keys,
        run.n_u,
        run.n_nt,
        run.padding,
        cfg.sampling.n_max,
        not args.no_progress,
        f"{run.slug}: sample queries",
    )
    spans = {"U": (0, pools.n_u), "N": (pools.n_u, len(pools.queries))}
    records.check_chunks(
        out,
        {k: pools.queries[a:b] for k, (a, b) in spans.items()},
        "delete it and run the same command again to plan its queries again",
    )
    artifacts.write_json(out / records.RECORD_FILE, meta, default=artifacts.json_default)
    for name in args.order:
        lo, hi = spans[name]
        if args.limit is not None:
            hi = min(hi, lo + args.limit)
        work = out / name
        work.mkdir(exist_ok=True)
        plan_pool(
            env,
            pools.queries[lo:hi],
            run.plan_fn,
            verify=run.verify,
            padding=run.padding,
            seed=cfg.seed + (0 if name == "U" else 1),
            chunk=args.chunk,
            work=work,
            progress=not args.no_progress,
            desc=f"{run.slug}: {name} ({run.planner_name})",
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
