#!/usr/bin/env python
"""States per data path: BIT* (a committed record) against the data planner's modes.

On the non-trivial queries of a BIT* record (``scripts/record_paths.py``), plans the
same queries with the config's data planner (raw and shortcut paths), resamples the
shortcut paths at several spacings, and compares, on the queries both solved: states
per path (mean, median, ratio to BIT*), path cost (ratio to BIT*) and the samples a
path gives before and after includeData's pruning (Alg. 4). Writes
``<out>/density_<map>.json`` and prints a Markdown table.

    python benchmarks/bench_data_paths.py --record results/data_paths/bitstar/rigid_0 \\
        --config configs/rigid.yaml --spacings 0.3,0.4,0.5,0.6,0.8
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np


def load_record(folder: Path, pool: str = "N"):
    """The record's chunks of ``pool`` merged: ``(queries, paths, lengths, status, costs)``."""
    files = sorted((folder / pool).glob("plan_*_*.npz"))
    if not files:
        raise SystemExit(f"error: no chunk files in {folder / pool}")
    parts = [np.load(f) for f in files]
    width = max(z["paths"].shape[1] for z in parts)
    d = parts[0]["queries"].shape[2]
    paths = np.concatenate(
        [
            np.pad(
                z["paths"],
                ((0, 0), (0, width - z["paths"].shape[1]), (0, 0)),
                constant_values=np.nan,
            )
            for z in parts
        ]
    ).reshape(-1, width, d)
    cat = {
        k: np.concatenate([z[k] for z in parts]) for k in ("queries", "lengths", "status", "costs")
    }
    return cat["queries"], paths, cat["lengths"], cat["status"], cat["costs"]


def samples(env, paths, lengths, padding):
    """Samples per path before and after pruning (includeData at ``padding``)."""
    from ntq_jax.data.include import include_data

    full = include_data(env, paths, lengths, prune=False, padding=padding)[0]
    kept = include_data(env, paths, lengths, prune=True, padding=padding)[0]
    return len(full) / len(lengths), len(kept) / len(lengths)


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", required=True, help="folder of a BIT* record (record.json, N/)")
    ap.add_argument("--config", required=True)
    ap.add_argument("--spacings", default="0.3,0.4,0.5,0.6,0.8")
    ap.add_argument("--limit", type=int, default=None, help="first LIMIT queries of the record")
    ap.add_argument("--out", default="results/data_paths")
    return ap.parse_args(argv)


def plan_both_modes(env, q, planner, opts, pad):
    """The data planner's raw and shortcut plans of ``q`` and their seconds together."""
    from ntq_jax.planners import plan

    cache = Path("runs") / "roadmap_cache"
    extra = {"cache_dir": cache} if planner == "roadmap" else {}
    t0 = time.perf_counter()
    raw = plan(env, q, planner, padding=pad, smooth=False, **opts, **extra)
    cut = plan(env, q, planner, padding=pad, **opts, **extra)
    return raw, cut, time.perf_counter() - t0


def density_row(env, pad, both, bit, label, paths, lengths, costs) -> dict:
    """One mode's figures on the queries ``both`` solved; ``bit``: BIT*'s (states, costs) there."""
    bit_len, bit_cost = bit
    L = lengths[both].astype(np.float64)
    s_full, s_kept = samples(env, paths[both], lengths[both], pad)
    return {
        "mode": label,
        "mean_states": float(L.mean()),
        "median_states": float(np.median(L)),
        "ratio_to_bitstar": float(L.mean() / bit_len.mean()),
        "cost_ratio_to_bitstar": float(np.median(costs[both] / bit_cost)),
        "samples_per_path": s_full,
        "samples_after_pruning": s_kept,
    }


def print_table(out: dict, planner: str, seg, dest: Path) -> None:
    """The Markdown table of the modes (and where the JSON went)."""
    print(
        f"{out['env']}: {out['solved_by_both']} non-trivial queries solved by BIT* "
        f"({out['bitstar_time_budget']} s) and "
        f"the {planner}; BIT* segment mean {seg.mean():.3f}, median {np.median(seg):.3f}"
    )
    print(
        "| data paths | states/path (mean) | median | / BIT* | cost / BIT* (median) | "
        "samples/path | after pruning |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in out["rows"]:
        print(
            f"| {r['mode']} | {r['mean_states']:.2f} | {r['median_states']:.0f} | "
            f"{r['ratio_to_bitstar']:.2f} | {r['cost_ratio_to_bitstar']:.3f} | "
            f"{r['samples_per_path']:.2f} | {r['samples_after_pruning']:.2f} |"
        )
    print(f"wrote {dest}")


def main(argv=None) -> int:
    args = parse_args(argv)

    from ntq_jax import make_env
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment import config as C
    from ntq_jax.planners.jobs import planner_options
    from ntq_jax.planners.path_modes import shape_paths

    record = Path(args.record)
    meta = json.loads((record / "record.json").read_text())
    name = meta["env"]
    cfg = C.load(args.config, [])
    env = make_env(name)
    pad = float(meta["padding"])
    q, bp, bl, bs, bc = load_record(record)
    if args.limit:
        q, bp, bl, bs, bc = (a[: args.limit] for a in (q, bp, bl, bs, bc))
    planner = cfg.planner.name_for(name)
    opts = {
        k: v
        for k, v in planner_options(C.planner_settings(cfg, name), planner).items()
        if k != "smooth"
    }
    raw, cut, seconds = plan_both_modes(env, q, planner, opts, pad)
    both = (bs == 0) & raw.solved & cut.solved
    n = int(both.sum())
    bit_len = bl[both].astype(np.float64)
    bit_cost = bc[both]
    seg = bit_cost / np.maximum(bit_len - 1, 1)
    row = functools.partial(density_row, env, pad, both, (bit_len, bit_cost))
    rows = [
        row("bitstar", bp, bl, bc),
        row("raw", raw.paths, raw.lengths, raw.costs),
        row("shortcut", cut.paths, cut.lengths, cut.costs),
    ]
    for s in (float(x) for x in args.spacings.split(",") if x.strip()):
        res, _ = shape_paths(env, cut, s, planner, pad)
        rows.append(row(f"resampled {s:g}", res.paths, res.lengths, res.costs))
    out = {
        "env": name,
        "record": str(record),
        "planner": planner,
        "options": opts,
        "padding": pad,
        "queries": int(len(q)),
        "solved_by_both": n,
        "bitstar_time_budget": meta["options"].get("time_budget"),
        "bitstar_mean_segment": float(seg.mean()),
        "bitstar_median_segment": float(np.median(seg)),
        "planner_seconds": seconds,
        "rows": rows,
    }
    dest = Path(args.out) / f"density_{env_slug(name, env)}.json"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(out, indent=1) + "\n")
    print_table(out, planner, seg, dest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
