#!/usr/bin/env python
"""The roadmap planner's search: scipy Dijkstra (the old search) against A* (graph_search).

    python benchmarks/bench_graph_search.py                       # rigid/0 and nlink/6
    python benchmarks/bench_graph_search.py --env rigid/0 --queries 200 --reps 3 --threads 1

Per map: the roadmap of ``plan(env, q, "roadmap")`` (``--milestones``, default
20,000; k by PRM*'s rule; roadmap seed 0), the benchmark's non-trivial queries
(``env.sample_queries(key(0), n, p_nt=1)``, as ``bench_roadmap.py``) and their
checked end edges (``roadmap_ends.query_edges``, timed once: the motion checks the
search starts from). Then, in this process, on the same graph and queries, with
``--threads`` threads each:

* ``dijkstra``: the old search: one scipy CSR of milestones plus every query's
  start and goal, ``scipy.sparse.csgraph.dijkstra`` from chunks of 128 starts
  (single-source, complete trees), paths from the predecessor rows;
* ``astar``: :func:`ntq_jax.planners.graph_search.shortest_paths` on the
  roadmap's ``search_graph`` (built once per roadmap, as the planner keeps it;
  its build time is printed apart).

Prints per-query medians of ``--reps`` interleaved repeats (after one warm-up
each), their ratio, and the agreement of the two: solved sets, the largest
relative cost difference, and how many queries got the identical node sequence.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from common import interleaved, loadavg

SEARCH_CHUNK = 128  # the old search's Dijkstra sources per call


def dijkstra_search(n, rm, qe, threads: int):
    """The old search on ``qe``: ``(cost (Q,), milestone sequences or None)``."""
    import numpy as np
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    nq = len(qe.direct)
    start, goal = n + np.arange(nq), n + nq + np.arange(nq)
    s_row = np.repeat(np.arange(nq), np.diff(qe.start_ptr))
    g_row = np.repeat(np.arange(nq), np.diff(qe.goal_ptr))
    d_row = np.flatnonzero(np.isfinite(qe.direct))
    e0, e1 = rm.edges[:, 0].astype(np.int64), rm.edges[:, 1].astype(np.int64)
    src = np.concatenate([e0, e1, start[s_row], qe.goal_node, start[d_row]])
    dst = np.concatenate([e1, e0, qe.start_node, goal[g_row], goal[d_row]])
    w = np.concatenate([rm.costs, rm.costs, qe.start_cost, qe.goal_cost, qe.direct[d_row]])
    w = np.maximum(w, 1e-12)
    graph = coo_matrix((w, (src, dst)), shape=(n + 2 * nq,) * 2).tocsr()

    def solve(rows):
        dist, pred = dijkstra(graph, directed=True, indices=start[rows], return_predecessors=True)
        d = dist[np.arange(len(rows)), goal[rows]]
        seqs = []
        for r, i in enumerate(rows):
            if not np.isfinite(d[r]):
                seqs.append(None)
                continue
            seq, v = [], pred[r, goal[i]]
            while v != start[i]:
                seq.append(v)
                v = pred[r, v]
            seqs.append(np.array(seq[::-1], np.int32))
        return d, seqs

    chunks = [np.arange(lo, min(nq, lo + SEARCH_CHUNK)) for lo in range(0, nq, SEARCH_CHUNK)]
    with ThreadPoolExecutor(max(1, min(threads, len(chunks)))) as pool:
        parts = list(pool.map(solve, chunks))
    return np.concatenate([p[0] for p in parts]), [s for p in parts for s in p[1]]


def bench_map(name: str, args) -> None:
    import jax
    import numpy as np

    import ntq_jax
    from ntq_jax.planners import graph_search as G
    from ntq_jax.planners import roadmap as R
    from ntq_jax.planners import roadmap_ends as RE

    env = ntq_jax.make_env(name)
    padding = env.resolve_padding(None)
    k = R.prm_star_k(args.milestones, env.dim)
    t0 = time.perf_counter()
    rm = R.roadmap_for(
        env, padding, milestones=args.milestones, k=k, roadmap_seed=0, cache_dir=args.cache_dir
    )
    t_build = time.perf_counter() - t0
    q, _ = env.sample_queries(jax.random.key(0), args.queries, p_nt=1.0)
    q = np.asarray(q, np.float32)
    t0 = time.perf_counter()
    index = R.MetricIndex(env.robot, env.world, rm.milestones)
    qe = RE.query_edges(env.robot, env.world, rm, index, q, k, padding, "discretized").edges
    t_edges = time.perf_counter() - t0
    n = len(rm.milestones)
    metric = G.heuristic_metric(env.robot)

    t0 = time.perf_counter()
    graph = G.search_graph(n, rm.edges, rm.costs, rm.milestones)  # once per roadmap
    t_graph = time.perf_counter() - t0

    def astar():
        return G.shortest_paths(graph, q[:, 1], qe, metric, threads=args.threads)

    old, new = dijkstra_search(n, rm, qe, args.threads), astar()
    med = interleaved(
        {"dijkstra": lambda: dijkstra_search(n, rm, qe, args.threads), "astar": astar}, args.reps
    )
    ok_old, ok_new = np.isfinite(old[0]), np.isfinite(new[0])
    both = ok_old & ok_new
    rel = np.abs(new[0][both] - old[0][both]) / old[0][both]
    same = sum(
        a is not None and b is not None and np.array_equal(a, b) for a, b in zip(old[1], new[1])
    )
    nq = len(q)
    print(
        f"{name}: {n} milestones, {len(rm.edges)} edges, k {k}; roadmap {t_build:.1f} s; "
        f"{nq} queries, end edges {1e3 * t_edges / nq:.2f} ms/query; A*'s graph (once per "
        f"roadmap) {1e3 * t_graph:.0f} ms",
        flush=True,
    )
    print(
        f"  search ms/query: dijkstra {1e3 * med['dijkstra'] / nq:.3f}, "
        f"astar {1e3 * med['astar'] / nq:.3f}, ratio {med['dijkstra'] / med['astar']:.1f}x "
        f"(cores used {interleaved.cores['dijkstra']:.2f} / {interleaved.cores['astar']:.2f}; "
        f"threads {args.threads})",
        flush=True,
    )
    print(
        f"  agreement: solved {ok_old.sum()} / {ok_new.sum()} (same set: "
        f"{bool(np.array_equal(ok_old, ok_new))}), max relative cost difference "
        f"{rel.max(initial=0.0):.2e}, identical paths {same} of {both.sum()}",
        flush=True,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--env", action="append", default=None, help="preset, repeatable (default rigid/0 nlink/6)"
    )
    ap.add_argument("--milestones", type=int, default=20_000)
    ap.add_argument("--queries", type=int, default=500)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--cache-dir", default=None, help="roadmap cache folder")
    args = ap.parse_args(argv)
    print(f"load {loadavg()}", flush=True)
    for name in args.env or ["rigid/0", "nlink/6"]:
        bench_map(name, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
