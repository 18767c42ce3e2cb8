#!/usr/bin/env python
"""Streaming at scale: plan, shortcut and certify-verify many queries into chunk files.

    python benchmarks/bench_scale.py --env rigid/0 --queries 1000000 --chunk 10000 \\
        --out /tmp/scale_rigid0
    taskset -c 1 python benchmarks/bench_scale.py --queries 30000 --threads 1 --out /tmp/s

Drives :func:`ntq_jax.data.stream.stream_chunks`: chunk ``i`` holds ``--chunk``
queries (half uniform, half non-trivial) from ``fold_in(key(--seed), i)``,
planned on the map's roadmap (``--milestones``, the roadmap kept in
``<out>/roadmaps``) with the certified motion check (``--check``), every path
verified, written atomically as ``<out>/chunk_<i>.npz``. Rerunning the same
command resumes: complete chunks (same settings) are not planned again. A tqdm
bar over the queries shows the rate and the ETA. ``--shard w/W`` makes only the
chunks ``i % W == w`` (one of W processes, e.g. one per core).

At the end it prints and writes ``<out>/scale_<shard>.json``: the chunks planned
now and skipped, per-stage seconds per query (all planned chunks, and without the
median over every complete chunk file of the run: robust to the chunks that paid
compilation or a roadmap build), the peak RSS of the
process, and a projection of 10^6 queries on 2 cores, 16 cores and a Ray cluster
from the median chunk's time per query (labelled a projection: it
assumes the chunks run independently in parallel, one process per core).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from pathlib import Path

RAY_NODES = 8  # nodes of the projected Ray cluster
RAY_CORES = 16  # cores per node
RAY_OVERHEAD = 0.01  # Ray's measured overhead was 0.8 % (BENCHMARKS.md, "Executors")


def _args(argv=None):
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--env", default="rigid/0")
    ap.add_argument("--queries", type=int, default=1_000_000)
    ap.add_argument("--chunk", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--milestones", type=int, default=20_000)
    ap.add_argument("--check", default="certified", choices=["certified", "discretized"])
    ap.add_argument("--threads", type=int, default=None, help="search threads (None: all)")
    ap.add_argument("--max-chunks", type=int, default=None, help="stop after this many chunks")
    ap.add_argument("--shard", default="0/1", help="w/W: only chunks i %% W == w")
    ap.add_argument("--out", required=True)
    ap.add_argument("--no-progress", action="store_true")
    return ap.parse_args(argv)


def _projection(steady_s_per_query: float, n: int = 1_000_000) -> dict:
    """Wall seconds of ``n`` queries at one process per core (a projection)."""
    one = steady_s_per_query * n
    return {
        "label": "projection (chunks independent, one process per core, "
        "median per-query time of the chunk files; not measured)",
        "1e6_on_1_core_s": one,
        "1e6_on_2_cores_s": one / 2,
        "1e6_on_16_cores_s": one / 16,
        f"1e6_on_ray_{RAY_NODES}x{RAY_CORES}_cores_s": one
        / (RAY_NODES * RAY_CORES)
        * (1 + RAY_OVERHEAD),
    }


def main(argv=None) -> int:
    args = _args(argv)
    from ntq_jax import artifacts, make_env
    from ntq_jax.data.stream import STAGES, stream_chunks

    artifacts.enable_compile_cache()
    w, n_w = (int(v) for v in args.shard.split("/"))
    env = make_env(args.env)
    out = Path(args.out)
    options = {"milestones": args.milestones, "cache_dir": str(out / "roadmaps")}
    if args.threads is not None:
        options["threads"] = args.threads
    t0 = time.perf_counter()
    rep = stream_chunks(
        env,
        out,
        n_queries=args.queries,
        chunk=args.chunk,
        seed=args.seed,
        check=args.check,
        options=options,
        max_chunks=args.max_chunks,
        shard=(w, n_w),
        progress=not args.no_progress,
    )
    wall = time.perf_counter() - t0
    per_q = {s: rep.seconds[s] / max(rep.queries, 1) for s in STAGES}
    steady = _median_chunk(out, range(w, -(-args.queries // args.chunk), n_w), STAGES)
    summary = {
        "env": args.env,
        "queries": args.queries,
        "chunk": args.chunk,
        "check": args.check,
        "milestones": args.milestones,
        "shard": args.shard,
        "planned_chunks": len(rep.planned),
        "skipped_chunks": len(rep.skipped),
        "planned_queries": rep.queries,
        "solved": rep.solved,
        "wall_s": wall,
        "cpu_s": time.process_time(),
        "affinity": len(os.sched_getaffinity(0)),
        "load_avg": os.getloadavg(),
        "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        "s_per_query": per_q,
        "median_chunk_s_per_query": steady,
    }
    if steady:
        summary["projection"] = _projection(sum(steady.values()))
    artifacts.write_json(out / f"scale_{w}of{n_w}.json", summary)
    print(json.dumps(summary, indent=1))
    return 0


def _median_chunk(out: Path, indices, stages) -> dict:
    """Per stage, the median over the complete chunk files of seconds per query (robust to
    the chunks that paid compilation or a roadmap build); {} without chunk files."""
    import numpy as np

    from ntq_jax.data.stream import chunk_path

    rows = []
    for i in indices:
        try:
            with np.load(chunk_path(out, i)) as z:
                rows.append(np.asarray(z["timings"], np.float64) / len(z["status"]))
        except (OSError, KeyError, ValueError):
            continue
    if not rows:
        return {}
    med = np.median(np.stack(rows), axis=0)
    return dict(zip(stages, map(float, med)))


if __name__ == "__main__":
    raise SystemExit(main())
