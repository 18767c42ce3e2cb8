#!/usr/bin/env python
"""States per data path on the Panda: a BIT* record against the roadmap's raw, shortcut and resampled paths.

The Panda's counterpart of ``benchmarks/bench_data_paths.py`` (which reads a
config; the Panda's BIT* record is made by ``benchmarks/bench_panda_bitstar.py``
from a plain query sample instead). On the record's non-trivial queries, plans the
same queries with the roadmap planner at the serial arm's defaults
(``roadmap.ARM_DEFAULTS``) at the data padding, raw (``smooth=False``) and shortcut,
resamples the shortcut paths at several spacings (radians, ``planner.data_paths``:
:func:`ntq_jax.planners.path_modes.shape_paths`), and compares, on the queries both
solved: states per path (mean, median, ratio to BIT*), cost (median ratio to BIT*)
and the samples a path gives to includeData before and after pruning. Also reports
what BIT* checked in its budget (states and motions per query, from the record) and
the spacing whose states per path are nearest BIT*'s. Writes
``<out>/density_<scene>.json`` and prints a Markdown table.

    taskset -c 0 python benchmarks/bench_panda_data_paths.py \\
        --record results/data_paths/panda/bitstar/table_pick_1
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np
from bench_data_paths import density_row, load_record, print_table


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--record", required=True, help="folder of a Panda BIT* record (record.json, N/)"
    )
    ap.add_argument(
        "--spacings",
        default="0.4,0.6,0.8,1.0,1.2,1.4,1.5,1.6,2.0",
        help="resampling spacings of the shortcut paths, radians",
    )
    ap.add_argument("--cache", default="runs/roadmap_cache", help="the roadmap's cache folder")
    ap.add_argument("--out", default="results/data_paths/panda")
    return ap.parse_args(argv)


def bitstar_checks(folder: Path) -> dict:
    """What BIT* checked per query in its budget (states, motions) and its solve seconds."""
    files = sorted((folder / "N").glob("plan_*_*.npz"))
    parts = {
        k: np.concatenate([np.load(f)[k] for f in files])
        for k in ("n_valid", "n_motion", "solve_times", "status")
    }
    out = {"queries": len(parts["status"]), "solved": int((parts["status"] == 0).sum())}
    for k in ("n_valid", "n_motion", "solve_times"):
        v = parts[k].astype(np.float64)
        out[k] = {
            "mean": float(v.mean()),
            "median": float(np.median(v)),
            "min": float(v.min()),
            "max": float(v.max()),
        }
    return out


def matching_spacing(rows: list, bit_mean: float) -> dict:
    """The resampled row whose mean states per path is nearest BIT*'s."""
    res = [r for r in rows if r["mode"].startswith("resampled ")]
    best = min(res, key=lambda r: abs(r["mean_states"] - bit_mean))
    return {
        "spacing": float(best["mode"].split()[1]),
        "mean_states": best["mean_states"],
        "ratio_to_bitstar": best["ratio_to_bitstar"],
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    from ntq_jax import make_env
    from ntq_jax.envs import env_slug
    from ntq_jax.planners import plan
    from ntq_jax.planners.path_modes import shape_paths
    from ntq_jax.planners.roadmap import ARM_DEFAULTS

    record = Path(args.record)
    meta = json.loads((record / "record.json").read_text())
    name = meta["env"]
    env = make_env(name)
    pad = float(meta["padding"])
    q, bp, bl, bs, bc = load_record(record)
    t0 = time.perf_counter()
    raw = plan(env, q, "roadmap", padding=pad, smooth=False, cache_dir=Path(args.cache))
    cut = plan(env, q, "roadmap", padding=pad, cache_dir=Path(args.cache))
    seconds = time.perf_counter() - t0
    both = (bs == 0) & raw.solved & cut.solved
    bit_len, bit_cost = bl[both].astype(np.float64), bc[both]
    seg = bit_cost / np.maximum(bit_len - 1, 1)
    row = functools.partial(density_row, env, pad, both, (bit_len, bit_cost))
    rows = [
        row("bitstar", bp, bl, bc),
        row("raw", raw.paths, raw.lengths, raw.costs),
        row("shortcut", cut.paths, cut.lengths, cut.costs),
    ]
    for s in (float(x) for x in args.spacings.split(",") if x.strip()):
        res, _ = shape_paths(env, cut, s, "roadmap", pad)
        rows.append(row(f"resampled {s:g}", res.paths, res.lengths, res.costs))
    out = {
        "env": name,
        "record": str(record),
        "planner": "roadmap",
        "options": dict(ARM_DEFAULTS, grow_rounds=2, roadmap_seed=0),
        "padding": pad,
        "queries": len(q),
        "solved_by_both": int(both.sum()),
        "bitstar_solved": int((bs == 0).sum()),
        "roadmap_solved": int(cut.solved.sum()),
        "bitstar_time_budget": meta["options"]["time_budget"],
        "bitstar_checks": bitstar_checks(record),
        "bitstar_mean_segment": float(seg.mean()),
        "bitstar_median_segment": float(np.median(seg)),
        "planner_seconds": seconds,
        "rows": rows,
    }
    out["matching_spacing"] = matching_spacing(rows, rows[0]["mean_states"])
    dest = Path(args.out) / f"density_{env_slug(name, env)}.json"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(out, indent=1) + "\n")
    print_table(out, "roadmap", seg, dest)
    c = out["bitstar_checks"]
    print(
        f"BIT* per query: {c['n_valid']['mean']:.0f} states and {c['n_motion']['mean']:.0f} "
        f"motions checked (means), {c['solve_times']['mean']:.2f} s; spacing nearest BIT*'s "
        f"states/path: {out['matching_spacing']}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
