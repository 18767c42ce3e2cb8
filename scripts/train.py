#!/usr/bin/env python
"""Train the PNet ensemble (one PNet per dataset D0..D3, all four together).

    python scripts/train.py --data runs/x/data/point_0 --config configs/point_small.yaml
    python scripts/train.py --data DIR --config configs/point.yaml --set train.epochs=5 --out OUT

``--data`` is an environment folder written by ``scripts/generate_data.py``
(``env.json`` beside ``D0/ .. D3/``). The output folder (default
``<data>/pnets``) receives ``checkpoints/``, ``history.jsonl``, ``history.csv``,
``curves.png``, ``config.json`` and, when training has finished, ``ensemble/``
(load it with ``ntq_jax.training.load_ensemble(OUT)``). Interrupted (Ctrl-C,
``kill -9``)? Re-run the same command: it resumes from the latest checkpoint.
A checkpoint written with another config, seed or data is refused with a clear
message. The progress bar shows each member's latest minibatch loss. Expected
errors (a bad config, dataset or checkpoint) are one ``error:`` line with the
fix, exit code 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ntq_jax.experiment.cli import UsageError, add_run_options, run_cli, start_run


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--data", type=Path, required=True, help="environment data folder (env.json + D0..D3)"
    )
    add_run_options(
        ap,
        set_example="train.epochs=5",
        figures_help=None,
        config_help="YAML config (its model and train sections are used; "
        "default: the embedded default)",
        cpu_devices_help="JAX CPU devices to create (one per core): the members "
        "train on separate cores; results then differ from a "
        "one-device run at float level. Default 1",
    )
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: DATA/pnets)")
    ap.add_argument(
        "--no-shard", action="store_true", help="never shard the member axis over devices"
    )
    args = ap.parse_args(argv)
    start_run(args)  # --cpu-devices checked and applied before any JAX operation

    from ntq_jax.experiment.config import load, train_args

    cfg = load(args.config, args.set)
    if not (args.data / "env.json").is_file():
        raise UsageError(
            f"--data {args.data}: no env.json there; pass an environment folder "
            "written by scripts/generate_data.py (env.json beside D0..D3)"
        )
    out = args.out or args.data / "pnets"

    import jax

    from ntq_jax import training as T

    print(
        f"training {cfg.model.hidden} PNets on {args.data} -> {out} "
        f"({len(jax.devices())} {jax.default_backend()} device(s))",
        file=sys.stderr,
    )
    t0 = time.perf_counter()
    ens, hist = T.train_from_folder(
        args.data,
        out,
        progress=not args.no_progress,
        shard=False if args.no_shard else None,
        **train_args(cfg),
    )
    dt = time.perf_counter() - t0
    last = {}
    for m in range(hist.train_loss.shape[1]):
        tl = hist.train_loss[:, m]
        vl = hist.val_loss[:, m]
        last[f"D{m}"] = (
            float(tl[~(tl != tl)][-1]) if (tl == tl).any() else float("nan"),
            float(vl[~(vl != vl)][-1]) if (vl == vl).any() else float("nan"),
        )
    for name, (tl, vl) in last.items():
        print(f"{name}: train loss {tl:.5g}  val loss {vl:.5g}")
    print(f"done in {dt:.1f} s; ensemble: {out / 'ensemble'}; curves: {out / 'curves.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
