"""A* on roadmaps (ntq_jax.planners.graph_search) against scipy's Dijkstra.

The reference searches the graph of the old roadmap search: milestones, every
query's start (outgoing edges only) and goal (incoming edges only) as nodes of
one scipy CSR matrix, Dijkstra from each start. Costs must agree; among paths
of equal cost either search may return any one, so paths are checked by their
own cost.
"""

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

import ntq_jax as nj
from ntq_jax.planners import graph_search as G
from ntq_jax.planners import roadmap as R
from ntq_jax.planners import roadmap_ends as RE
from ntq_jax.robots.batch import distances


def _reference(n: int, edges, costs, qe: G.QueryEdges) -> np.ndarray:
    """Dijkstra (scipy) costs of every query on the combined graph."""
    nq = len(qe.direct)
    start, goal = n + np.arange(nq), n + nq + np.arange(nq)
    s_row = np.repeat(np.arange(nq), np.diff(qe.start_ptr))
    g_row = np.repeat(np.arange(nq), np.diff(qe.goal_ptr))
    d_row = np.flatnonzero(np.isfinite(qe.direct))
    e0, e1 = np.asarray(edges, np.int64).T
    src = np.concatenate([e0, e1, start[s_row], qe.goal_node, start[d_row]])
    dst = np.concatenate([e1, e0, qe.start_node, goal[g_row], goal[d_row]])
    w = np.concatenate([costs, costs, qe.start_cost, qe.goal_cost, qe.direct[d_row]])
    w = np.maximum(w, G.MIN_EDGE_COST)
    graph = coo_matrix((w, (src, dst)), shape=(n + 2 * nq,) * 2).tocsr()
    dist = dijkstra(graph, directed=True, indices=start)
    return dist[np.arange(nq), goal]


def _path_cost(seq, i, csr, qe: G.QueryEdges) -> float:
    """The cost of query ``i``'s path ``seq`` (milestones), from the edges it uses."""
    if len(seq) == 0:
        return float(max(qe.direct[i], G.MIN_EDGE_COST))
    indptr, indices, costs = csr
    sl = slice(qe.start_ptr[i], qe.start_ptr[i + 1])
    total = max(qe.start_cost[sl][list(qe.start_node[sl]).index(seq[0])], G.MIN_EDGE_COST)
    for a, b in zip(seq[:-1], seq[1:]):
        row = slice(indptr[a], indptr[a + 1])
        total += costs[row][list(indices[row]).index(b)]
    gl = slice(qe.goal_ptr[i], qe.goal_ptr[i + 1])
    total += max(qe.goal_cost[gl][qe.goal_node[gl] == seq[-1]].min(), G.MIN_EDGE_COST)
    return float(total)


def _check(n, edges, costs, states, goals, qe, metric, threads=2):
    csr = G.roadmap_csr(n, edges, costs)
    graph = G.search_graph(n, edges, costs, states)
    got, seqs = G.shortest_paths(graph, goals, qe, metric, threads=threads)
    ref = _reference(n, edges, costs, qe)
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(ref))
    ok = np.isfinite(ref)
    np.testing.assert_allclose(got[ok], ref[ok], rtol=1e-9)
    for i, seq in enumerate(seqs):
        assert (seq is None) == (not ok[i])
        if seq is not None:
            assert _path_cost(seq, i, csr, qe) == pytest.approx(got[i], rel=1e-9)
    return got, seqs


def _metric_cost(metric, a, b):
    """``metric`` in float64 (the kernel's heuristic without its slack)."""
    x = b - a
    x = np.where(metric.periodic, (x + np.pi) % (2 * np.pi) - np.pi, x) * metric.weights
    return sum(np.sqrt((x[..., metric.groups == g] ** 2).sum(-1)) for g in np.unique(metric.groups))


METRICS = {
    "euclid": G.HeuristicMetric(np.ones(2), np.zeros(2, bool), np.zeros(2, np.int64)),
    "se2": G.HeuristicMetric(
        np.array([1.0, 1.0, 0.5]), np.array([False, False, True]), np.array([0, 0, 1])
    ),
    "zero": G.HeuristicMetric(np.zeros(2), np.zeros(2, bool), np.zeros(2, np.int64)),
}


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(2, 40),
    density=st.floats(0.02, 0.4),
    nq=st.integers(1, 6),
    metric=st.sampled_from(sorted(METRICS)),
    seed=st.integers(0, 2**31 - 1),
    ties=st.booleans(),
)
def test_astar_cost_equals_dijkstra_on_random_graphs(n, density, nq, metric, seed, ties):
    rng = np.random.default_rng(seed)
    m = METRICS[metric]
    d = len(m.weights)
    # integer grid states with unit-ish costs make many equal-cost paths
    pts = rng.integers(0, 4, (n + 2 * nq, d)) if ties else rng.uniform(-4, 4, (n + 2 * nq, d))
    pts = pts.astype(np.float64)
    states, starts, goals = pts[:n], pts[n : n + nq], pts[n + nq :]
    i, j = np.triu_indices(n, 1)
    keep = rng.random(len(i)) < density
    edges = np.stack([i[keep], j[keep]], 1)
    stretch = 1.0 if ties else 1.0 + rng.random(len(edges))
    costs = _metric_cost(m, states[edges[:, 0]], states[edges[:, 1]]) * stretch
    rows = {"s": ([], [], []), "g": ([], [], [])}
    for q in range(nq):
        for key, end in (("s", starts[q]), ("g", goals[q])):
            nodes = np.flatnonzero(rng.random(n) < 0.3)
            rows[key][0].extend([q] * len(nodes))
            rows[key][1].extend(nodes)
            rows[key][2].extend(_metric_cost(m, end, states[nodes]) * (1 + rng.random(len(nodes))))
    d_row = np.flatnonzero(rng.random(nq) < 0.3)
    d_c = _metric_cost(m, starts[d_row], goals[d_row]) * 1.5
    qe = G.QueryEdges.from_rows(
        nq, *(np.asarray(a) for a in rows["s"]), *(np.asarray(a) for a in rows["g"]), d_row, d_c
    )
    _check(n, edges, costs, states, goals, qe, m)


def test_unreachable_goal_and_unattached_ends_are_no_path():
    m = METRICS["euclid"]
    states = np.array([[0, 0], [1, 0], [5, 0], [6, 0]], np.float64)
    edges = np.array([[0, 1], [2, 3]])  # two components
    costs = np.array([1.0, 1.0])
    goals = np.array([[6.5, 0], [6.5, 0], [6.5, 0], [1.5, 0]])
    # query 0: start on component {0,1}, goal on {2,3}: unreachable
    # query 1: the start reaches no milestone; query 2: no milestone reaches the goal
    # query 3: start -> 0 -> 1 -> goal
    qe = G.QueryEdges.from_rows(
        4,
        np.array([0, 2, 3]),
        np.array([0, 2, 0]),
        np.ones(3),
        np.array([0, 1, 3]),
        np.array([3, 3, 1]),
        np.ones(3),
        np.zeros(0, np.int64),
        np.zeros(0),
    )
    got, seqs = _check(4, edges, costs, states, goals, qe, m)
    assert [s is None for s in seqs] == [True, True, True, False]
    assert seqs[3].tolist() == [0, 1] and got[3] == 3.0
    assert np.isinf(got[:3]).all()


def test_direct_edge_only_path_is_empty_and_zero_costs_are_raised():
    m = METRICS["euclid"]
    states = np.zeros((2, 2))
    qe = G.QueryEdges.from_rows(
        1,
        np.array([0]),
        np.array([0]),
        np.zeros(1),
        np.array([0]),
        np.array([1]),
        np.zeros(1),
        np.array([0]),
        np.array([0.5]),
    )
    got, seqs = _check(2, np.array([[0, 1]]), np.zeros(1), states, np.zeros((1, 2)), qe, m)
    assert seqs[0].tolist() == [0, 1] and got[0] == pytest.approx(3 * G.MIN_EDGE_COST)


@pytest.mark.parametrize("name", ["point/0", "rigid/0", "nlink/4"])
def test_heuristic_metric_is_the_robots_metric(name):
    env = nj.make_env(name)
    a = np.asarray(env.sample_states(jax.random.key(0), 300), np.float32)
    b = np.asarray(env.sample_states(jax.random.key(1), 300), np.float32)
    ref = distances(env.robot, a, b).astype(np.float64)
    m = G.heuristic_metric(env.robot)
    got = _metric_cost(m, a.astype(np.float64), b.astype(np.float64))
    np.testing.assert_allclose(got, ref, rtol=2e-6, atol=1e-6)
    kernel = np.array(
        [
            G._h(a.astype(np.float64), i, b[i].astype(np.float64), m.weights, m.periodic, m.groups)
            for i in range(20)
        ]
    )
    np.testing.assert_allclose(kernel, got[:20] * (1 - G.HEURISTIC_SLACK), rtol=1e-12)


@pytest.mark.parametrize("name", ["point/3", "rigid/0", "nlink/4"])
def test_roadmap_search_cost_equals_dijkstra(name):
    env = nj.make_env(name)
    padding = env.resolve_padding(None)
    rm = R.roadmap_for(env, padding, milestones=1500, k=R.prm_star_k(1500, env.dim), roadmap_seed=0)
    q, _ = env.sample_queries(jax.random.key(0), 60, p_nt=0.7)
    q = np.asarray(q, np.float32)
    index = R.MetricIndex(env.robot, env.world, rm.milestones)
    qe = RE.query_edges(
        env.robot, env.world, rm, index, q, R.prm_star_k(1500, env.dim), padding, "discretized"
    ).edges
    got, _ = _check(
        len(rm.milestones),
        rm.edges,
        rm.costs,
        rm.milestones,
        q[:, 1],
        qe,
        G.heuristic_metric(env.robot),
    )
    assert np.isfinite(got).mean() > 0.8
    assert R._graph_for(rm) is R._graph_for(rm)  # built once per roadmap
    paths = R._search(
        env.robot, env.world, rm, q, R.prm_star_k(1500, env.dim), padding, 2, "discretized"
    )
    for i, p in enumerate(paths):
        assert (p is None) == np.isinf(got[i])
        if p is not None:
            assert np.array_equal(p[0], q[i, 0]) and np.array_equal(p[-1], q[i, 1])
            cost = np.asarray(distances(env.robot, p[:-1], p[1:]), np.float64)
            assert np.maximum(cost, G.MIN_EDGE_COST).sum() == pytest.approx(got[i], rel=1e-6)


def test_paths_longer_than_the_first_pass_cap():
    m = METRICS["euclid"]
    n = G.PATH_CAP + 40
    states = np.stack([np.arange(n, dtype=np.float64), np.zeros(n)], 1)
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], 1)  # a chain
    goals = np.array([[n, 0.0], [3.5, 0.0]])
    qe = G.QueryEdges.from_rows(
        2,
        np.array([0, 1]),
        np.array([0, 0]),
        np.ones(2),
        np.array([0, 1]),
        np.array([n - 1, 3]),
        np.array([1.0, 0.5]),
        np.zeros(0, np.int64),
        np.zeros(0),
    )
    got, seqs = _check(n, edges, np.ones(n - 1), states, goals, qe, m)
    assert seqs[0].tolist() == list(range(n)) and got[0] == n + 1
    assert seqs[1].tolist() == [0, 1, 2, 3] and got[1] == 4.5
