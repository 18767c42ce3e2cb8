"""Point-to-point shortest paths on a roadmap: A* per query, compiled with numba.

A query is a start and a goal that are not roadmap nodes: the start has
outgoing edges to some milestones, the goal incoming edges from some
milestones, and the start may have a direct edge to the goal. Each query is
searched on the roadmap plus its own two ends only, so its answer does not
depend on the other queries of the batch.

The heuristic of a node is the robot's cost metric from its state to the goal
(:func:`heuristic_metric`), times ``1 - HEURISTIC_SLACK``. Edge costs are that
metric (computed in float32), so the heuristic is a lower bound of every path
cost up to the float32 rounding of the edge costs, which the slack covers. A
node whose cost improves after its expansion is expanded again, so the search
stays exact for a merely admissible heuristic. The search stops when no open
node can lead to a cheaper goal. The roadmap is searched in reverse Cuthill-McKee
order (:class:`SearchGraph`); among paths of equal cost (to float64 rounding)
the labelling decides which one is returned, so it may differ from another
search's choice.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

__all__ = [
    "HeuristicMetric",
    "heuristic_metric",
    "QueryEdges",
    "SearchGraph",
    "search_graph",
    "roadmap_csr",
    "shortest_paths",
    "HEURISTIC_SLACK",
    "MIN_EDGE_COST",
]

HEURISTIC_SLACK = 1e-5  # relative: covers the float32 rounding of the edge costs
MIN_EDGE_COST = 1e-12  # edge costs are raised to this (coincident states keep an edge)
QUERY_CHUNK = 16  # queries per parallel work item (each item allocates its work arrays)
PATH_CAP = 256  # milestones per path in the first pass; longer paths get a second pass


class HeuristicMetric(NamedTuple):
    """A cost metric on states: the sum over coordinate groups of the Euclidean
    norm of ``weights * diff``, with ``diff`` wrapped to ``[-pi, pi)`` on
    ``periodic`` coordinates.

    ``weights (d,)`` float64 (all zero: the heuristic is 0, plain Dijkstra);
    ``periodic (d,)`` bool; ``groups (d,)`` int64, non-decreasing (each group is a
    run of consecutive coordinates).
    """

    weights: np.ndarray
    periodic: np.ndarray
    groups: np.ndarray


def heuristic_metric(robot) -> HeuristicMetric:
    """The robot's cost metric as a :class:`HeuristicMetric`.

    Point robot, n-link arm and 3-D serial arm: the Euclidean distance of the states
    (the serial arm's joint distance). Rigid body: ``||dxy|| + angle_weight * |wrapped
    dtheta|``. Any other robot: the zero metric (admissible for every robot; the search
    is then Dijkstra).
    """
    from ntq_jax.robots.nlink import NLinkArm
    from ntq_jax.robots.point import PointRobot
    from ntq_jax.robots.rigid_body import RigidBody
    from ntq_jax.robots.serial_arm import SerialArm

    d = int(robot.dim)
    if isinstance(robot, (PointRobot, NLinkArm, SerialArm)):
        return HeuristicMetric(np.ones(d), np.zeros(d, bool), np.zeros(d, np.int64))
    if isinstance(robot, RigidBody):
        return HeuristicMetric(
            np.array([1.0, 1.0, float(robot.angle_weight)]),
            np.array([False, False, True]),
            np.array([0, 0, 1], np.int64),
        )
    return HeuristicMetric(np.zeros(d), np.zeros(d, bool), np.zeros(d, np.int64))


class QueryEdges(NamedTuple):
    """The edges of ``Q`` queries' ends, grouped per query (CSR-like).

    Query ``i``'s start reaches milestone ``start_node[j]`` at cost ``start_cost[j]``
    for ``j`` in ``start_ptr[i]:start_ptr[i+1]``; milestone ``goal_node[j]`` reaches
    its goal at ``goal_cost[j]`` for ``j`` in ``goal_ptr[i]:goal_ptr[i+1]``;
    ``direct (Q,)`` is the cost of the straight start -> goal edge (inf: none).
    Pointers int64 ``(Q + 1,)``, nodes int32, costs float64.
    """

    start_ptr: np.ndarray
    start_node: np.ndarray
    start_cost: np.ndarray
    goal_ptr: np.ndarray
    goal_node: np.ndarray
    goal_cost: np.ndarray
    direct: np.ndarray

    @classmethod
    def from_rows(
        cls, nq: int, s_row, s_node, s_cost, g_row, g_node, g_cost, d_row, d_cost
    ) -> "QueryEdges":
        """From per-edge query rows (any order); ``d_row``: the queries with a direct edge."""

        def group(rows, node, cost):
            order = np.argsort(rows, kind="stable")
            ptr = np.zeros(nq + 1, np.int64)
            np.cumsum(np.bincount(rows, minlength=nq), out=ptr[1:])
            return (
                ptr,
                np.asarray(node)[order].astype(np.int32),
                np.asarray(cost, np.float64)[order],
            )

        direct = np.full(nq, np.inf)
        direct[np.asarray(d_row, np.int64)] = d_cost
        return cls(
            *group(np.asarray(s_row, np.int64), s_node, s_cost),
            *group(np.asarray(g_row, np.int64), g_node, g_cost),
            direct,
        )


# ---------------------------------------------------------------------------
# compiled kernels
# ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _h(states, v, goal, w, per, grp):
    """Metric from ``states[v]`` to ``goal`` (group norms summed; see HeuristicMetric)."""
    total = 0.0
    acc = 0.0
    cur = grp[0]
    for c in range(goal.shape[0]):
        if grp[c] != cur:
            total += np.sqrt(acc)
            acc = 0.0
            cur = grp[c]
        x = goal[c] - states[v, c]
        if per[c]:
            x = x - 2.0 * np.pi * np.floor((x + np.pi) / (2.0 * np.pi))
        x *= w[c]
        acc += x * x
    return (total + np.sqrt(acc)) * (1.0 - HEURISTIC_SLACK)


@njit(cache=True, inline="always")
def _sift_up(keys, nodes, pos, i):
    """Restores the min-heap order above slot ``i``."""
    k, v = keys[i], nodes[i]
    while i > 0:
        p = (i - 1) >> 1
        if keys[p] <= k:
            break
        keys[i], nodes[i] = keys[p], nodes[p]
        pos[nodes[i]] = i
        i = p
    keys[i], nodes[i] = k, v
    pos[v] = i


@njit(cache=True, inline="always")
def _pop(keys, nodes, pos, size):
    """Removes the heap's minimum; returns its node (the heap has ``size - 1`` entries after)."""
    top = nodes[0]
    pos[top] = -1
    size -= 1
    if size == 0:
        return top
    k, v = keys[size], nodes[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and keys[c + 1] < keys[c]:
            c += 1
        if keys[c] >= k:
            break
        keys[i], nodes[i] = keys[c], nodes[c]
        pos[nodes[i]] = i
        i = c
    keys[i], nodes[i] = k, v
    pos[v] = i
    return top


@njit(cache=True, inline="always")
def _push(keys, nodes, pos, size, v, key):
    """Inserts ``v`` with ``key``, or lowers its key if it is in the heap; returns the size."""
    i = pos[v]
    if i < 0:
        i = size
        size += 1
    keys[i] = key
    nodes[i] = v
    _sift_up(keys, nodes, pos, i)
    return size


@njit(cache=True)
def _one_query(
    qi,
    indptr,
    indices,
    costs,
    states,
    goal_state,
    w,
    per,
    grp,
    s_ptr,
    s_node,
    s_cost,
    g_ptr,
    g_node,
    g_cost,
    direct,
    g,
    h,
    pred,
    pos,
    stamp,
    keys,
    nodes,
    goal_w,
    out_row,
):
    """A* for query ``qi`` on milestones ``0..n-1`` (start: ``n``, goal: scalars).

    ``stamp[v] == qi`` marks the nodes this query has seen (their ``g``, ``h``,
    ``pred`` are this query's); ``pos`` (-1 outside the heap) and ``goal_w``
    (inf) are left as found. Writes the path's milestones (start side first) into
    ``out_row`` when they fit. Returns ``(cost, milestones on the path)``; cost
    inf: no path.
    """
    start = indptr.shape[0] - 1
    for j in range(g_ptr[qi], g_ptr[qi + 1]):
        goal_w[g_node[j]] = min(goal_w[g_node[j]], g_cost[j])
    best = direct[qi]
    best_pred = start
    size = 0
    for j in range(s_ptr[qi], s_ptr[qi + 1]):
        v = s_node[j]
        if stamp[v] != qi:
            stamp[v], g[v] = qi, np.inf
            h[v] = _h(states, v, goal_state, w, per, grp)
        if s_cost[j] < g[v]:
            g[v], pred[v] = s_cost[j], start
            size = _push(keys, nodes, pos, size, v, s_cost[j] + h[v])
    while size > 0 and keys[0] < best:
        u = _pop(keys, nodes, pos, size)
        size -= 1
        gu = g[u]
        if gu + goal_w[u] < best:
            best, best_pred = gu + goal_w[u], u
        for j in range(indptr[u], indptr[u + 1]):
            v = indices[j]
            if stamp[v] != qi:
                stamp[v], g[v] = qi, np.inf
                h[v] = _h(states, v, goal_state, w, per, grp)
            ng = gu + costs[j]
            if ng < g[v]:
                g[v], pred[v] = ng, u
                size = _push(keys, nodes, pos, size, v, ng + h[v])
    for i in range(size):
        pos[nodes[i]] = -1
    for j in range(g_ptr[qi], g_ptr[qi + 1]):
        goal_w[g_node[j]] = np.inf
    return best, _write_path(pred, best_pred, start, best < np.inf, out_row)


@njit(cache=True)
def _write_path(pred, last, start, found, out_row):
    """Follows ``pred`` from milestone ``last`` back to ``start``; writes the milestones
    in path order into ``out_row`` when they fit. Returns their count (0 if not found)."""
    if not found:
        return 0
    hops = 0
    v = last
    while v != start:
        hops += 1
        v = pred[v]
    if hops <= out_row.shape[0]:
        v, i = last, hops - 1
        while v != start:
            out_row[i] = v
            i -= 1
            v = pred[v]
    return hops


@njit(cache=True, parallel=True)
def _search_all(indptr, indices, costs, states, goals, w, per, grp, qe, rows, cap):
    """:func:`_one_query` for every query of ``rows``, ``QUERY_CHUNK`` at a time in
    parallel. Returns ``(cost (R,), hops (R,), paths (R, cap) int32)``."""
    s_ptr, s_node, s_cost, g_ptr, g_node, g_cost, direct = qe
    n, nr = indptr.shape[0] - 1, rows.shape[0]
    best = np.full(nr, np.inf)
    hops = np.zeros(nr, np.int64)
    paths = np.full((nr, cap), -1, np.int32)
    n_chunks = (nr + QUERY_CHUNK - 1) // QUERY_CHUNK
    for c in prange(n_chunks):
        g, h, pred = np.empty(n), np.empty(n), np.empty(n, np.int32)
        pos, stamp = np.full(n, -1, np.int32), np.full(n, -1, np.int64)
        keys, nodes, goal_w = np.empty(n), np.empty(n, np.int32), np.full(n, np.inf)
        for r in range(c * QUERY_CHUNK, min(nr, (c + 1) * QUERY_CHUNK)):
            qi = rows[r]
            best[r], hops[r] = _one_query(
                qi,
                indptr,
                indices,
                costs,
                states,
                goals[qi],
                w,
                per,
                grp,
                s_ptr,
                s_node,
                s_cost,
                g_ptr,
                g_node,
                g_cost,
                direct,
                g,
                h,
                pred,
                pos,
                stamp,
                keys,
                nodes,
                goal_w,
                paths[r],
            )
    return best, hops, paths


# ---------------------------------------------------------------------------
# API
# ---------------------------------------------------------------------------


def roadmap_csr(
    n: int, edges: np.ndarray, costs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The undirected roadmap as CSR ``(indptr (n+1,) int64, indices int32, costs float64)``:
    each edge ``(i, j)`` in both directions, costs raised to ``MIN_EDGE_COST``."""
    from scipy.sparse import coo_matrix

    e = np.asarray(edges, np.int64).reshape(-1, 2)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    c = np.maximum(np.tile(np.asarray(costs, np.float64), 2), MIN_EDGE_COST)
    m = coo_matrix((c, (src, dst)), shape=(n, n)).tocsr()  # pairs are unique: nothing summed
    return m.indptr.astype(np.int64), m.indices.astype(np.int32), m.data.astype(np.float64)


class SearchGraph(NamedTuple):
    """The roadmap as the search reads it: CSR ``indptr (n+1,) int64``,
    ``indices`` int32, ``costs`` float64 (each edge in both directions, raised to
    ``MIN_EDGE_COST``) and ``states (n, d)`` float64, over the milestones relabelled
    by ``order (n,)`` int64 (new label -> milestone; reverse Cuthill-McKee, so that
    neighbours lie close in memory)."""

    indptr: np.ndarray
    indices: np.ndarray
    costs: np.ndarray
    states: np.ndarray
    order: np.ndarray


def search_graph(n: int, edges: np.ndarray, costs: np.ndarray, states: np.ndarray) -> SearchGraph:
    """The :class:`SearchGraph` of ``n`` milestones at ``states (n, d)`` joined by
    ``edges (E, 2)`` (unique unordered pairs) of ``costs (E,)``."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    indptr, indices, c = roadmap_csr(n, edges, costs)
    order = reverse_cuthill_mckee(
        csr_matrix((c, indices, indptr), shape=(n, n)), symmetric_mode=True
    ).astype(np.int64)
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n)
    e = rank[np.asarray(edges, np.int64).reshape(-1, 2)]
    st = np.ascontiguousarray(np.asarray(states, np.float64)[order])
    return SearchGraph(*roadmap_csr(n, e, costs), st, order)


def shortest_paths(
    graph: SearchGraph,
    goals: np.ndarray,
    edges: QueryEdges,
    metric: HeuristicMetric,
    threads: int = 1,
) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """Shortest start -> goal path of every query.

    Args:
        graph: the roadmap (:func:`search_graph`); its costs must be at least
            ``metric`` between the edge's states.
        goals: ``(Q, d)`` the queries' goal states.
        edges: the queries' start, goal and direct edges (:class:`QueryEdges`,
            milestones by their index in the roadmap, not in ``graph.order``);
            their costs must be at least ``metric`` between their states.
        metric: the heuristic's metric (:func:`heuristic_metric`).
        threads: numba threads (capped at numba's thread count); the answers do
            not depend on it.

    Returns:
        ``cost (Q,)`` float64 (inf: the goal is unreachable) and per query the
        milestone indices of its path from the start side (int64; empty for the
        direct edge; None when unreachable). The cost is the minimum over all
        paths (edge costs raised to ``MIN_EDGE_COST``), to within the relative
        slack of the heuristic; among paths of equal cost any one may be returned.
    """
    indptr, indices, costs, st, order = graph
    rank = np.empty(len(order), np.int32)
    rank[order] = np.arange(len(order), dtype=np.int32)
    edges = edges._replace(start_node=rank[edges.start_node], goal_node=rank[edges.goal_node])
    gs = np.ascontiguousarray(goals, np.float64)
    if np.any(np.diff(np.asarray(metric.groups)) < 0):
        raise ValueError(f"metric groups must be non-decreasing, got {metric.groups}")
    qe = tuple(
        np.ascontiguousarray(np.maximum(a, MIN_EDGE_COST), np.float64)
        if f.endswith("cost") or f == "direct"
        else np.ascontiguousarray(a)
        for f, a in zip(QueryEdges._fields, edges)
    )
    args = (
        indptr,
        indices,
        costs,
        st,
        gs,
        np.asarray(metric.weights, np.float64),
        np.asarray(metric.periodic, np.bool_),
        np.asarray(metric.groups, np.int64),
        qe,
    )
    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        rows = np.arange(len(gs), dtype=np.int64)
        best, hops, paths = _search_all(*args, rows, PATH_CAP)
        long = np.flatnonzero(hops > PATH_CAP)
        if len(long):
            b2, h2, p2 = _search_all(*args, long, int(hops[long].max()))
    finally:
        numba.set_num_threads(old)
    out: list[np.ndarray | None] = [
        None if not np.isfinite(b) else order[p[:k]] for b, k, p in zip(best, hops, paths)
    ]
    for j, i in enumerate(long):
        out[i] = order[p2[j, : h2[j]]]
    return best, out
