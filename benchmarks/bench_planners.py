"""Grid planners side by side: batched JAX A* (JPS) vs pyastar2d (C++) vs a plain heapq A* in Python.

Same grid, same queries, one process. The grid is the environment's occupancy
grid from the package's rasteriser (default ``point/3`` at 0.1 resolution with
the environment's padding, 200x200). Two query sets are timed:

* ``uniform``: start and goal uniform over the free cells (unreachable pairs,
  if the grid has several components, are answered by the JAX planner from its
  component labels while the other two search the whole component);
* ``reachable``: the same sampling restricted to start/goal pairs in the same
  component (every query needs a search: the fair speed comparison).

Graphs: the JAX A* and the heapq A* solve the same graph (8-connected, straight
step 1, diagonal sqrt(2), no corner cutting) and their costs are checked equal.
pyastar2d (``allow_diagonal=True``) solves a slightly different one: every move
costs the target cell's weight (1), so diagonal moves cost 1, and corners may be
cut. Its timings are for the same grids and queries; its paths are not
comparable cost-wise.

Usage:
    python benchmarks/bench_planners.py [--env point/3] [--resolution 0.1]
        [--queries 1000] [--repeats 5] [--heapq-queries 1000] [--seed 0]
        [--random-boxes K]   # a random 20x20 map of K inflated boxes instead of --env
        [--visgraph-queries 100000] [--plan-queries 1000]

Reports the median wall time over repeats (JAX: after one compiling call, with
the per-grid tables built once and timed separately), queries per second, and
the ratios to pyastar2d.

Then, on the environment itself (not with ``--random-boxes``):

* the visibility-graph planner (``VisGraph.plan``, lengths and paths) on
  ``--visgraph-queries`` uniform valid queries at padding 0 and at the
  environment's padding: build time and queries per second;
* the public entry point end to end, ``ntq_jax.plan(env, q, "astar")`` (grid,
  snapping, A*, shortcutting, exact verification) and ``"visgraph"`` on
  ``--plan-queries`` queries of ``env.sample_queries`` (p_nt = 0.5), at
  padding 0: queries per second, per-stage times, and the distribution of the
  smoothed A* cost over the visibility-graph optimum.
"""

from __future__ import annotations

import argparse
import heapq
import math
import statistics
import time

import jax
import numpy as np

from ntq_jax.planners.astar import astar, prepare_grid
from ntq_jax.types import PlanStatus

SQ2 = math.sqrt(2.0)


# ---------------------------------------------------------------------------
# Grids
# ---------------------------------------------------------------------------


def env_grid(name: str, resolution: float) -> np.ndarray:
    """Occupancy grid of a package environment (its own padding), via the package's rasteriser."""
    import ntq_jax

    return np.asarray(ntq_jax.make_env(name).rasterize(resolution), bool)


def random_box_grid(
    rng, n_boxes: int, size: float = 20.0, resolution: float = 0.1, padding: float = 0.8
) -> np.ndarray:
    """A random map: ``n_boxes`` boxes in a ``size`` x ``size`` square, inflated by ``padding``.

    A cell is occupied when its centre is within ``padding`` of a box (the
    package's clearance convention); row = y cell, column = x cell.
    """
    n = int(round(size / resolution))
    c = (np.arange(n) + 0.5) * resolution
    x, y = np.meshgrid(c, c)
    occ = np.zeros((n, n), bool)
    for _ in range(n_boxes):
        cx, cy = rng.uniform(1, size - 1, 2)
        hw, hh = rng.uniform(0.3, 2.0, 2)
        dx = np.maximum(np.abs(x - cx) - hw, 0)
        dy = np.maximum(np.abs(y - cy) - hh, 0)
        occ |= dx * dx + dy * dy <= padding * padding
    return occ


def components(occ: np.ndarray) -> np.ndarray:
    """4-connected component labels (the no-corner-cutting 8-grid has the same components)."""
    from scipy import ndimage

    lab, _ = ndimage.label(~occ)
    return lab


def sample_queries(rng, occ, n, reachable: bool):
    free = np.argwhere(~occ)
    lab = components(occ)
    starts, goals = [], []
    while len(starts) < n:
        i = rng.integers(0, len(free), size=(2 * n, 2))
        s, g = free[i[:, 0]], free[i[:, 1]]
        if reachable:
            keep = lab[s[:, 0], s[:, 1]] == lab[g[:, 0], g[:, 1]]
            s, g = s[keep], g[keep]
        starts.extend(s)
        goals.extend(g)
    return np.array(starts[:n], np.int32), np.array(goals[:n], np.int32)


# ---------------------------------------------------------------------------
# A plain A* in Python (same graph as the JAX planner)
# ---------------------------------------------------------------------------


def heapq_astar(occ: np.ndarray, start, goal) -> float:
    """Textbook A* with a binary heap: 8-connected, no corner cutting, octile heuristic."""
    h, w = occ.shape
    free = (~occ).ravel().tolist()
    s = int(start[0]) * w + int(start[1])
    t = int(goal[0]) * w + int(goal[1])
    if not (free[s] and free[t]):
        return math.inf
    gr, gc = divmod(t, w)
    moves = [
        (-1, 0, 1.0),
        (1, 0, 1.0),
        (0, -1, 1.0),
        (0, 1, 1.0),
        (-1, -1, SQ2),
        (-1, 1, SQ2),
        (1, -1, SQ2),
        (1, 1, SQ2),
    ]

    def octile(r, c):
        dr, dc = abs(r - gr), abs(c - gc)
        return max(dr, dc) + (SQ2 - 1.0) * min(dr, dc)

    g = {s: 0.0}
    closed = set()
    heap = [(octile(*divmod(s, w)), 0.0, s)]
    while heap:
        _, gu, u = heapq.heappop(heap)
        if u in closed:
            continue
        if u == t:
            return gu
        closed.add(u)
        r, c = divmod(u, w)
        for dr, dc, cost in moves:
            rr, cc = r + dr, c + dc
            if not (0 <= rr < h and 0 <= cc < w):
                continue
            v = rr * w + cc
            if not free[v] or v in closed:
                continue
            if dr and dc and not (free[rr * w + c] and free[r * w + cc]):
                continue  # no corner cutting
            gv = gu + cost
            if gv < g.get(v, math.inf):
                g[v] = gv
                heapq.heappush(heap, (gv + octile(rr, cc), gv, v))
    return math.inf


# ---------------------------------------------------------------------------
# Timing
# ---------------------------------------------------------------------------


def timed(fn, repeats: int):
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times), out


def bench(occ, starts, goals, args, label):
    n = len(starts)
    print(
        f"\n== {label}: {n} queries on a {occ.shape[0]}x{occ.shape[1]} grid "
        f"({occ.mean():.1%} occupied) =="
    )
    rows = []

    # JAX: per-grid tables once, then the batch (compiled on the first call)
    t0 = time.perf_counter()
    graph = jax.block_until_ready(prepare_grid(occ))
    t_prep_first = time.perf_counter() - t0
    t_prep, _, _ = timed(lambda: jax.block_until_ready(prepare_grid(occ)), args.repeats)
    t0 = time.perf_counter()
    res = jax.block_until_ready(astar(graph, starts, goals))
    t_first = time.perf_counter() - t0
    t_jax, t_jax_min, res = timed(
        lambda: jax.block_until_ready(astar(graph, starts, goals)), args.repeats
    )
    status = np.asarray(res.status)
    cost = np.asarray(res.cost)
    print(
        f"JAX A*: first call (compile + run) {t_first:.2f} s; prepare_grid {t_prep * 1e3:.1f} ms "
        f"(first {t_prep_first:.2f} s); solved {np.sum(status == PlanStatus.SOLVED)}/{n}, "
        f"statuses {np.bincount(status, minlength=4).tolist()}"
    )
    rows.append(("JAX A* (JPS, batched)", t_jax, t_jax_min, n))

    # pyastar2d
    try:
        import pyastar2d
    except ImportError:
        pyastar2d = None
        print("pyastar2d: not installed, skipped (pip install pyastar2d)")
    if pyastar2d is not None:
        weights = np.where(occ, np.inf, 1.0).astype(np.float32)
        sl, gl = [tuple(map(int, x)) for x in starts], [tuple(map(int, x)) for x in goals]

        def run_pyastar():
            return [
                pyastar2d.astar_path(weights, a, b, allow_diagonal=True) for a, b in zip(sl, gl)
            ]

        run_pyastar()  # warm-up
        t_py, t_py_min, paths = timed(run_pyastar, args.repeats)
        found = np.array([p is not None for p in paths])
        agree = np.mean(found == (status == PlanStatus.SOLVED))
        print(
            f"pyastar2d: found {found.sum()}/{n} (agrees with JAX on reachability for "
            f"{agree:.1%}); its graph allows corner cutting and diagonal steps cost 1"
        )
        rows.append(("pyastar2d (C++)", t_py, t_py_min, n))

    # heapq A* (slow: fewer queries and repeats)
    m = min(n, args.heapq_queries)
    if m > 0:
        reps = max(1, min(args.repeats, args.heapq_repeats))
        t_hq, t_hq_min, ref = timed(
            lambda: [heapq_astar(occ, a, b) for a, b in zip(starts[:m], goals[:m])], reps
        )
        ref = np.array(ref)
        both = np.isfinite(ref) & np.isfinite(cost[:m])
        same_reach = np.array_equal(np.isfinite(ref), np.isfinite(cost[:m]))
        err = np.max(np.abs(ref[both] - cost[:m][both])) if both.any() else 0.0
        print(
            f"heapq A*: {m} queries x {reps} repeats; same reachability as JAX: {same_reach}; "
            f"max |cost difference| {err:.2e} cells"
        )
        rows.append(("heapq A* (Python)", t_hq, t_hq_min, m))

    py = next((r for r in rows if r[0].startswith("pyastar2d")), None)
    print(
        f"{'planner':26s} {'median s':>10s} {'ms/query':>10s} {'queries/s':>11s} {'vs pyastar2d':>13s}"
    )
    for name, t_med, t_min, k in rows:
        qps = k / t_med
        ratio = f"{qps / (py[3] / py[1]):.2f}x" if py else "n/a"
        print(f"{name:26s} {t_med:10.4f} {t_med / k * 1e3:10.4f} {qps:11.0f} {ratio:>13s}")
    return rows


def bench_visgraph(env_name: str, n: int, seed: int) -> None:
    import ntq_jax
    from ntq_jax.planners.visgraph import benchmark_visgraph

    env = ntq_jax.make_env(env_name)
    for pad in (0.0, env.padding):
        st = benchmark_visgraph(env, n, padding=pad, seed=seed, repeats=3)
        print(
            f"visgraph {env_name} padding {pad}: {st['nodes']} nodes, build {st['build_s']:.2f} s, "
            f"{n} queries in {st['plan_s']:.3f} s = {st['queries_per_s']:.0f} queries/s "
            f"(solved {st['solved']:.1%}, direct {st['direct']:.1%}, {st['devices']} device)"
        )


def bench_plan(env_name: str, n: int, seed: int, repeats: int) -> None:
    import ntq_jax

    env = ntq_jax.make_env(env_name)
    q, _ = env.sample_queries(jax.random.PRNGKey(seed), n, 0.5)
    q = np.asarray(q)
    print(f"\n== ntq_jax.plan on {env_name}, {n} queries (p_nt 0.5), padding 0 ==")
    for planner in ("astar", "visgraph"):
        t0 = time.perf_counter()
        ntq_jax.plan(env, q, planner, padding=0.0)
        first = time.perf_counter() - t0
        t_med, t_min, res = timed(lambda: ntq_jax.plan(env, q, planner, padding=0.0), repeats)
        stages = {
            k: round(v * 1e3, 1)
            for k, v in res.info.items()
            if k.endswith("_time") and isinstance(v, float)
        }
        print(
            f"plan({planner!r}): first call {first:.1f} s; median {t_med:.3f} s = "
            f"{n / t_med:.0f} queries/s; solved {res.solved.mean():.1%}; "
            f"mean waypoints {res.lengths[res.solved].mean():.2f}; stages (ms, last run) {stages}"
        )
        if planner == "astar":
            ast = res
        else:
            vis = res
    both = ast.solved & vis.solved
    r = ast.costs[both] / vis.costs[both]
    print(
        f"smoothed A* cost / visgraph optimum over {both.sum()} queries: min {r.min():.5f}, "
        f"median {np.median(r):.5f}, mean {r.mean():.5f}, p90 {np.percentile(r, 90):.5f}, "
        f"p99 {np.percentile(r, 99):.5f}, max {r.max():.5f}; "
        f"within 1%: {np.mean(r <= 1.01):.1%}, within 5%: {np.mean(r <= 1.05):.1%}"
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="point/3", help="package environment to rasterise")
    p.add_argument("--resolution", type=float, default=0.1)
    p.add_argument(
        "--random-boxes",
        type=int,
        default=0,
        help="use a random 20x20 map of this many boxes (0.8 padding) instead of --env",
    )
    p.add_argument("--queries", type=int, default=1000)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument(
        "--heapq-queries", type=int, default=1000, help="queries for the (slow) heapq A*"
    )
    p.add_argument("--heapq-repeats", type=int, default=1)
    p.add_argument("--sets", default="reachable,uniform", help="query sets to run")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--visgraph-queries",
        type=int,
        default=100_000,
        help="queries for the visibility-graph throughput (0 = skip)",
    )
    p.add_argument(
        "--plan-queries",
        type=int,
        default=1000,
        help="queries for the ntq_jax.plan end-to-end comparison (0 = skip)",
    )
    args = p.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    if args.random_boxes:
        occ = random_box_grid(rng, args.random_boxes, resolution=args.resolution)
        name = f"random map, {args.random_boxes} boxes"
    else:
        occ = env_grid(args.env, args.resolution)
        name = args.env
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform}; grid: {name} at {args.resolution}"
    )
    for kind in args.sets.split(","):
        starts, goals = sample_queries(rng, occ, args.queries, reachable=(kind == "reachable"))
        bench(occ, starts, goals, args, f"{name}, {kind} queries")
    if not args.random_boxes:
        if args.visgraph_queries:
            print()
            bench_visgraph(args.env, args.visgraph_queries, args.seed)
        if args.plan_queries:
            bench_plan(args.env, args.plan_queries, args.seed, args.repeats)


if __name__ == "__main__":
    main()
