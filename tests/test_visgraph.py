"""Visibility-graph planner against an independent oracle (shapely + networkx, float64).

The oracle never calls the package's segment kernel: visibility is decided by
shapely on the obstacle union, shortest paths by networkx. Three comparisons:

* ``closed`` mode, degenerate lattice maps (hypothesis): same node set as the
  package, closed-set visibility. Pairs within ``TAU`` of touching are
  ambiguous; the package's lengths must lie between the oracle with and without
  the ambiguous edges (equal when there are none).
* ``closure`` mode, generic maps at padding 0: the TRUE optimum (true box
  corners, segments may touch boxes), against which the package must be within
  the documented ``2 sqrt(2) eps`` per bend.
* padding > 0 with discs: the optimum among inscribed polygons (a lower bound
  of the truth) and among polygons containing the package's circumscribed ones
  (an upper bound).

Every returned path is also re-checked with ``env.steer_to`` at its padding.
"""

import math
import os

import jax
import networkx as nx
import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from shapely.geometry import Point
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

from ntq_jax import Env, make_env
from ntq_jax.envs.env import BUCKET_MIN_ROWS
from ntq_jax.planners.visgraph import VisGraph, benchmark_visgraph, obstacle_vertices
from ntq_jax.types import PlanStatus

TAU = 1e-4  # oracle ambiguity band (workspace units), >> float32 rounding of the kernel
SIDE = 20.0
HSET = settings(
    max_examples=int(os.environ.get("VISGRAPH_EXAMPLES", 8)),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)


# ---------------------------------------------------------------------------
# Oracle
# ---------------------------------------------------------------------------


def segments(a, b):
    return shapely.linestrings(np.stack([np.asarray(a, np.float64), np.asarray(b, np.float64)], 1))


class Oracle:
    """Shortest paths over ``nodes`` among ``obstacles`` (shapely geometries), in float64.

    ``mode="closed"``: a segment touching an obstacle is blocked (the package's
    padding-0 collision test); segments within ``TAU`` of touching are ambiguous.
    ``mode="closure"``: a segment is blocked only when it enters an obstacle's
    interior by more than ``TAU`` (paths may touch: the infimum over free paths).
    """

    def __init__(self, obstacles, nodes, mode):
        union = unary_union(obstacles)
        self.inner = union.buffer(-TAU)
        self.outer = union.buffer(TAU) if mode == "closed" else None
        shapely.prepare(self.inner)
        if self.outer is not None:
            shapely.prepare(self.outer)
        self.nodes = np.asarray(nodes, np.float64)
        v = len(self.nodes)
        ii, jj = np.triu_indices(v, 1)
        lo, hi = self.visible(self.nodes[ii], self.nodes[jj])
        w = np.linalg.norm(self.nodes[ii] - self.nodes[jj], axis=1)
        self.dist, self.weights = {}, {}
        for key, vis in (("lo", lo), ("hi", hi)):
            g = nx.Graph()
            g.add_nodes_from(range(v))
            g.add_weighted_edges_from(zip(ii[vis], jj[vis], w[vis]))
            self.dist[key] = (
                nx.floyd_warshall_numpy(g, nodelist=range(v)) if v else np.zeros((0, 0))
            )
            wm = np.full((v, v), np.inf)
            wm[ii[vis], jj[vis]] = wm[jj[vis], ii[vis]] = w[vis]
            self.weights[key] = wm

    def visible(self, a, b):
        """``(lo, hi)`` visibility: lo includes ambiguous segments, hi only sure ones."""
        if len(a) == 0:
            return np.zeros(0, bool), np.zeros(0, bool)
        segs = segments(a, b)
        lo = ~shapely.intersects(segs, self.inner)
        hi = lo if self.outer is None else ~shapely.intersects(segs, self.outer)
        return lo, hi

    def lengths(self, queries):
        """``(N, 3)``: per query ``L_lo``, ``L_hi`` and the number of nodes on the ``lo`` path."""
        out = np.zeros((len(queries), 3))
        for row, (s, g) in enumerate(np.asarray(queries, np.float64)):
            for k, key in enumerate(("lo", "hi")):
                direct = self.visible(s[None], g[None])[k][0]
                best, hops = (np.linalg.norm(g - s) if direct else np.inf), 0
                if len(self.nodes):
                    vs = self.visible(np.repeat(s[None], len(self.nodes), 0), self.nodes)[k]
                    vg = self.visible(self.nodes, np.repeat(g[None], len(self.nodes), 0))[k]
                    ds = np.where(vs, np.linalg.norm(self.nodes - s, axis=1), np.inf)
                    dg = np.where(vg, np.linalg.norm(self.nodes - g, axis=1), np.inf)
                    tot = ds[:, None] + self.dist[key] + dg[None, :]  # brute force over (i, j)
                    i, j = np.unravel_index(np.argmin(tot), tot.shape)
                    if tot[i, j] < best:
                        best, hops = tot[i, j], self._hops(key, i, j)
                out[row, k] = best
                if key == "lo":
                    out[row, 2] = hops
        return out

    def _hops(self, key, i, j):
        """Number of nodes on a shortest path ``i -> j`` (walk down the distance matrix)."""
        d, w = self.dist[key], self.weights[key]
        count, cur = 1, i
        while cur != j and count <= len(d):
            cur = int(np.argmin(np.abs(w[cur] + d[:, j] - d[cur, j])))
            count += 1
        return count


def box_polys(boxes):
    return [shapely_box(cx - hw, cy - hh, cx + hw, cy + hh) for cx, cy, hw, hh in boxes]


def box_corners(boxes, bounds):
    c = np.array(
        [
            [cx + sx * hw, cy + sy * hh]
            for cx, cy, hw, hh in boxes
            for sx in (-1, 1)
            for sy in (-1, 1)
        ]
    ).reshape(-1, 2)
    inside = (
        (c[:, 0] >= bounds[0][0])
        & (c[:, 0] <= bounds[0][1])
        & (c[:, 1] >= bounds[1][0])
        & (c[:, 1] <= bounds[1][1])
    )
    return np.unique(c[inside], axis=0)


def polygon_vertices(geom, bounds):
    polys = getattr(geom, "geoms", [geom])
    pts = []
    for p in polys:
        for ring in [p.exterior, *p.interiors]:
            pts.append(np.asarray(ring.coords)[:-1])
    pts = np.concatenate(pts) if pts else np.zeros((0, 2))
    inside = (
        (pts[:, 0] >= bounds[0][0])
        & (pts[:, 0] <= bounds[0][1])
        & (pts[:, 1] >= bounds[1][0])
        & (pts[:, 1] <= bounds[1][1])
    )
    return np.unique(pts[inside], axis=0)


# ---------------------------------------------------------------------------
# Maps and queries
# ---------------------------------------------------------------------------

# Compiled programs. ``VisGraph.plan`` compiles its query kernel once per (obstacle counts,
# padding, node count and route buffer rounded up to ``NODE_PAD``). The hypothesis tests'
# random maps would compile it for nearly every example, so they give their maps a fixed
# box count (duplicates of a box: the same free space and, after the build's
# de-duplication, the same nodes) and, while planning, round the tables up to the map's
# candidate node count (``plan_fixed``): the library's own padding (NaN nodes that are
# never visible, routes repeating their last node), just more of it, so every example of a
# test plans with one program (``table_size``). The tests outside hypothesis keep the
# default tables.
LATTICE_BOXES = 10  # the padding-0 tests' box count: 6 lattice boxes, or 6 random boxes + a cage


def pad_boxes(boxes, count):
    """``boxes`` followed by copies of its first box up to ``count`` boxes (the same free space)."""
    boxes = [tuple(b) for b in boxes]
    return boxes + [boxes[0]] * (count - len(boxes))


def plan_fixed(graph, queries):
    """``graph.plan(queries)`` with the tables padded to the candidate node count of the
    graph's obstacles (fixed by their counts; a route never has more nodes than the graph)."""
    cap = len(obstacle_vertices(graph.world, graph.padding, graph.eps, graph.arc_step))
    assert graph.num_nodes <= cap and graph.routes.shape[-1] <= max(cap, 1)
    return graph.plan(queries, table_size=cap)


def make_point_env(boxes, discs=(), padding=0.0):
    return Env.from_json(
        {
            "name": "test",
            "robot": {"kind": "point"},
            "bounds": [[0, SIDE], [0, SIDE]],
            "boxes": [list(b) for b in boxes],
            "discs": [list(d) for d in discs],
            "padding": padding,
        }
    )


def cage(cx, cy, a=1.2, t=0.4):
    """Four overlapping walls enclosing the square of half side ``a`` (no aligned edges)."""
    # opposite walls differ in length by 0.1 so that no two walls share an edge coordinate
    return [
        (cx, cy + a + t / 2, a + t / 2, t / 2),
        (cx, cy - a - t / 2, a + t / 2 + 0.1, t / 2),
        (cx - a - t / 2, cy, t / 2, a + 1.5 * t),
        (cx + a + t / 2, cy, t / 2, a + 1.5 * t + 0.1),
    ]


def edges_apart(b, others, margin):
    """No edge of box ``b`` within ``margin`` of an edge of another box or of the workspace."""
    ex = np.array([b[0] - b[2], b[0] + b[2]])
    ey = np.array([b[1] - b[3], b[1] + b[3]])
    ox = [0.0, SIDE] + [o[0] + s * o[2] for o in others for s in (-1, 1)]
    oy = [0.0, SIDE] + [o[1] + s * o[3] for o in others for s in (-1, 1)]
    return (
        np.min(np.abs(ex[:, None] - np.array(ox)[None])) > margin
        and np.min(np.abs(ey[:, None] - np.array(oy)[None])) > margin
    )


def clear_of_cage(b, c, a=1.2):
    """Box ``b`` stays out of the inside (half side ``a``) of the cage centred at ``c``."""
    return abs(b[0] - c[0]) >= b[2] + a or abs(b[1] - c[1]) >= b[3] + a


def generic_map(seed, n_boxes, margin=0.05):
    """Random boxes in general position (edges pairwise > margin apart) plus a cage with a free inside."""
    rng = np.random.default_rng(seed)
    while True:
        c = rng.uniform(3, SIDE - 3, 2)
        boxes = cage(*c)
        if edges_apart(boxes[0], [], margin) and edges_apart(boxes[2], [], margin):
            break
    while len(boxes) < n_boxes + 4:
        b = (*rng.uniform(0.5, SIDE - 0.5, 2), *rng.uniform(0.3, 2.5, 2))
        if clear_of_cage(b, c) and all(
            edges_apart(x, [y for y in boxes + [b] if y is not x], margin) for x in boxes + [b]
        ):
            boxes.append(tuple(float(v) for v in b))
    return boxes, c


def make_queries(env, seed, n, padding, cage_center=None):
    """Uniform valid pairs, short pairs (often direct), and goals inside the cage."""
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(seed), 3)
    s = env.sample_states(k1, n, padding)
    g = env.sample_states(k2, n, padding)
    q = [np.stack([s, g], 1)]
    near = s[: n // 4] + np.asarray(jax.random.uniform(k3, (n // 4, 2), minval=-1.5, maxval=1.5))
    # padded past BUCKET_MIN_ROWS: the chunk program ``VisGraph.build`` compiled (per-row answers)
    ok = np.asarray(
        env.is_valid(np.concatenate([near, np.repeat(near[:1], BUCKET_MIN_ROWS + 1, 0)]), padding)
    )[: len(near)]
    q.append(np.stack([s[: n // 4][ok], near[ok]], 1))
    if cage_center is not None:
        inside = np.array(cage_center) + np.array([[0.3, -0.2], [-0.25, 0.1]])
        outside = s[np.linalg.norm(s - np.array(cage_center), axis=1) > 3.0][:4]
        q.append(np.stack([outside, np.repeat(inside[:1], 4, 0)], 1))  # walled-in goal
        q.append(inside[None])  # start and goal in the cage: direct
    return np.concatenate(q).astype(np.float32)


# ---------------------------------------------------------------------------
# Checks shared by the tests
# ---------------------------------------------------------------------------


def check_paths(env, res, queries, padding):
    """Paths start/end at the query exactly, are collision-free, and costs are their lengths."""
    a, b = [], []
    for i in range(len(queries)):
        if res.status[i] != PlanStatus.SOLVED:
            assert res.lengths[i] == 0 and np.isinf(res.costs[i])
            assert np.all(np.isnan(res.paths[i]))
            continue
        p = res.path(i)
        assert len(p) >= 2 and not np.any(np.isnan(p))
        assert np.all(np.isnan(res.paths[i, len(p) :]))
        np.testing.assert_array_equal(p[0], queries[i, 0])
        np.testing.assert_array_equal(p[-1], queries[i, 1])
        seg = np.linalg.norm(np.diff(p.astype(np.float64), axis=0), axis=1).sum()
        np.testing.assert_allclose(res.costs[i], seg, rtol=1e-9, atol=1e-9)
        a.append(p[:-1])
        b.append(p[1:])
    if a:  # every segment in one exact-kernel call, padded past BUCKET_MIN_ROWS so that
        # env.steer_to runs the chunk program VisGraph.build compiled (steer_to_pairs)
        a, b = np.concatenate(a), np.concatenate(b)
        size = max(len(a), BUCKET_MIN_ROWS + 1)
        a = np.concatenate([a, np.repeat(a[:1], size - len(a), 0)])
        b = np.concatenate([b, np.repeat(b[:1], size - len(b), 0)])
        free = np.asarray(env.steer_to(a, b, padding=padding))
        assert np.all(free), np.nonzero(~free)[0]


# ---------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------

half_units = st.integers(0, 40).map(lambda k: k / 2)
lattice_box = st.tuples(
    half_units,
    half_units,
    st.integers(1, 8).map(lambda k: k / 2),
    st.integers(1, 8).map(lambda k: k / 2),
)


@HSET
@given(boxes=st.lists(lattice_box, min_size=6, max_size=6), seed=st.integers(0, 2**31 - 1))
def test_lengths_equal_bruteforce_oracle_on_lattice_maps(boxes, seed):
    """Degenerate maps (touching boxes, collinear corners): same nodes, independent visibility."""
    env = make_point_env(pad_boxes(boxes, LATTICE_BOXES))  # + 4 duplicates: the same map
    graph = VisGraph.build(env, 0.0)
    q = make_queries(env, seed, 24, 0.0)
    res = plan_fixed(graph, q)
    check_paths(env, res, q, 0.0)
    ref = Oracle(box_polys(boxes), graph.nodes, "closed").lengths(q)
    lo, hi = ref[:, 0], ref[:, 1]
    assert np.all(res.status != PlanStatus.INVALID)
    assert np.all(res.costs >= lo - 1e-4), (res.costs, lo)
    assert np.all(res.costs <= hi + 1e-4), (res.costs, hi)
    unambiguous = lo == hi
    np.testing.assert_allclose(res.costs[unambiguous], lo[unambiguous], rtol=1e-6, atol=1e-4)
    assert np.all((res.status == PlanStatus.NO_PATH) <= np.isinf(lo))


@HSET
@given(seed=st.integers(0, 2**31 - 1))
def test_padding0_is_the_true_optimum_within_eps_bound(seed):
    """Generic maps at padding 0: L* <= L <= L* + 2 sqrt(2) eps bends (true corners, touching allowed)."""
    boxes, center = generic_map(seed, 6)
    assert len(boxes) == LATTICE_BOXES
    env = make_point_env(boxes)
    graph = VisGraph.build(env, 0.0)
    assert graph.exact
    q = make_queries(env, seed, 30, 0.0, cage_center=center)
    res = plan_fixed(graph, q)
    check_paths(env, res, q, 0.0)
    bounds = [[0, SIDE], [0, SIDE]]
    polys = box_polys(np.asarray(env.world.boxes, np.float64))
    oracle = Oracle(polys, box_corners(np.asarray(env.world.boxes, np.float64), bounds), "closure")
    ref = oracle.lengths(q)
    opt, bends = ref[:, 0], ref[:, 2]
    np.testing.assert_array_equal(res.status == PlanStatus.SOLVED, np.isfinite(opt))
    ok = np.isfinite(opt)
    assert np.all(res.costs[ok] >= opt[ok] - 1e-4)
    assert np.all(res.costs[ok] <= opt[ok] + 2 * math.sqrt(2) * graph.eps * bends[ok] + 1e-4)
    # the walled-in goals are unreachable from outside, reachable from inside (direct)
    assert np.all(res.status[-5:-1] == PlanStatus.NO_PATH) and res.status[-1] == PlanStatus.SOLVED
    assert res.lengths[-1] == 2
    assert np.any(res.lengths == 2) and np.any(res.lengths > 2)


@HSET
@given(seed=st.integers(0, 2**31 - 1))
def test_padded_and_disc_maps_between_inscribed_and_circumscribed_optima(seed):
    """padding 0.8 with a disc: inscribed-polygon optimum <= L <= enlarged-polygon optimum."""
    pad, q_segs = 0.8, 4
    boxes, center = generic_map(seed, 3)
    rng = np.random.default_rng(seed + 1)
    while True:  # a disc clear of the cage (its inside points must stay valid)
        dc, r = rng.uniform(3, SIDE - 3, 2), rng.uniform(0.5, 1.5)
        if np.linalg.norm(dc - np.asarray(center)) > r + pad + 2.5:
            break
    discs = [(*dc, r)]
    env = make_point_env(boxes, discs, pad)
    graph = VisGraph.build(env)  # the environment's padding
    assert graph.padding == pad and not graph.exact and graph.delta > 0
    q = make_queries(env, seed, 30, pad, cage_center=center)
    res = plan_fixed(graph, q)
    check_paths(env, res, q, pad)
    b64 = np.asarray(env.world.boxes, np.float64)
    d64 = np.asarray(env.world.discs, np.float64)
    bounds = [[0, SIDE], [0, SIDE]]
    # polygons inside the true padded obstacles (vertices on the arcs)
    inner = [p.buffer(pad, quad_segs=q_segs) for p in box_polys(b64)] + [
        Point(x, y).buffer(r + pad, quad_segs=q_segs) for x, y, r in d64
    ]
    # polygons containing the package's circumscribed ones, grown by the node offset
    m_box = math.ceil((math.pi / 2) / graph.arc_step - 1e-9)
    m_disc = max(3, math.ceil(2 * math.pi / graph.arc_step - 1e-9))
    grow = 1 / math.cos(math.pi / (4 * q_segs))
    slack = 2 * math.sqrt(2) * graph.eps
    outer = [
        p.buffer((pad / math.cos(math.pi / 4 / m_box) + slack) * grow, quad_segs=q_segs)
        for p in box_polys(b64)
    ] + [
        Point(x, y).buffer(
            ((r + pad) / math.cos(math.pi / m_disc) + slack) * grow, quad_segs=q_segs
        )
        for x, y, r in d64
    ]
    lo = Oracle(inner, polygon_vertices(unary_union(inner), bounds), "closure").lengths(q)[:, 0]
    up = Oracle(outer, polygon_vertices(unary_union(outer), bounds), "closure").lengths(q)
    hi, bends = up[:, 0], up[:, 2]
    solved = res.status == PlanStatus.SOLVED
    assert np.all(res.status != PlanStatus.INVALID)
    assert np.all(res.costs[solved] >= lo[solved] - 1e-4)
    assert np.all(np.isfinite(lo[solved]))
    assert np.all(res.costs <= hi + slack * (bends + 2) + 1e-4)
    assert np.all(res.status[-5:-1] == PlanStatus.NO_PATH) and res.status[-1] == PlanStatus.SOLVED


def test_single_disc_matches_analytic_wrap_length():
    """Tangent-arc-tangent optimum around one disc: L*(R) <= L <= L*(R / cos(pi / m)) + eps terms."""
    r, pad = 3.0, 0.5
    env = make_point_env([], [(10.0, 10.0, r)], pad)
    graph = VisGraph.build(env, pad)
    ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    s = np.stack([10 + 8 * np.cos(ang), 10 + 8 * np.sin(ang)], 1)
    g = np.stack([10 - 7 * np.cos(ang + 0.3), 10 - 7 * np.sin(ang + 0.3)], 1)
    q = np.stack([s, g], 1).astype(np.float32)
    res = graph.plan(q)
    check_paths(env, res, q, pad)

    def wrap(big_r):
        a, b = q[:, 0].astype(np.float64) - 10.0, q[:, 1].astype(np.float64) - 10.0
        da, db = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        theta = np.arccos(np.clip(np.sum(a * b, 1) / (da * db), -1, 1))
        arc = theta - np.arccos(big_r / da) - np.arccos(big_r / db)
        return np.sqrt(da**2 - big_r**2) + np.sqrt(db**2 - big_r**2) + big_r * arc

    m = max(3, math.ceil(2 * math.pi / graph.arc_step - 1e-9))
    low, high = wrap(r + pad), wrap((r + pad) / math.cos(math.pi / m) + graph.eps)
    assert np.all(res.status == PlanStatus.SOLVED)
    assert np.all(res.costs >= low - 1e-4)
    assert np.all(res.costs <= high + 1e-4)
    assert graph.delta == pytest.approx((r + pad) * (1 / math.cos(math.pi / m) - 1))
    # larger tables (table_size) change the compiled program, not the answers
    big = graph.plan(q, table_size=graph.num_nodes + 13)
    for f in ("status", "costs", "lengths", "paths"):
        np.testing.assert_array_equal(getattr(big, f), getattr(res, f), err_msg=f)


def test_invalid_queries_and_empty_maps():
    env = make_point_env([(10.0, 10.0, 2.0, 2.0)])
    graph = VisGraph.build(env, 0.0)
    q = np.array(
        [
            [[10, 10], [1, 1]],  # start inside the box
            [[1, 1], [12, 10]],  # goal on the box boundary (closed set)
            [[np.nan, 1], [1, 1]],  # not finite
            [[1, 1], [25, 1]],  # out of bounds
            [[1, 1], [19, 19]],  # around the box
            [[1, 1], [1, 1]],
        ],
        np.float32,
    )  # zero length
    res = graph.plan(q)
    S, I = PlanStatus.SOLVED, PlanStatus.INVALID
    np.testing.assert_array_equal(res.status, [I, I, I, I, S, S])
    check_paths(env, res, q, 0.0)
    assert res.costs[5] == 0.0 and res.lengths[5] == 2
    assert res.path(0) is None
    empty = VisGraph.build(make_point_env([]), 0.0)
    assert empty.num_nodes == 0
    r2 = empty.plan(q[4:])
    np.testing.assert_allclose(r2.costs, [18 * math.sqrt(2), 0.0], rtol=1e-6)
    assert VisGraph.build(env, 0.0).plan(np.zeros((0, 2, 2))).status.shape == (0,)


def test_nodes_are_offset_corners():
    env = make_point_env([(10.0, 10.0, 2.0, 1.0)])
    v = obstacle_vertices(env.world, 0.0, 1e-3)
    want = [[12.001, 11.001], [7.999, 11.001], [7.999, 8.999], [12.001, 8.999]]
    np.testing.assert_allclose(v, want, atol=1e-9)
    # padding p: every arc vertex is at distance p / cos(beta / 2) + eps from its corner
    v = obstacle_vertices(env.world, 0.8, 1e-3, math.pi / 4)
    assert v.shape == (8, 2)
    corners = np.repeat(np.array([[12, 11], [8, 11], [8, 9], [12, 9]]), 2, 0)
    np.testing.assert_allclose(
        np.linalg.norm(v - corners, axis=1), 0.8 / math.cos(math.pi / 8) + 1e-3
    )


def test_preset_smoke_and_rejections():
    """Any current preset layout: paths check out; benchmark helper runs; non-point robots rejected."""
    env = make_env("point/3")
    for pad in (0.0, None):
        graph = VisGraph.build(env, pad)
        p = graph.padding
        q = make_queries(env, 3, 200, p)
        res = graph.plan(q, chunk_size=64)  # several chunks
        check_paths(env, res, q, p)
    # 64 queries: one chunk of 64, the program of the padding-0 plan above (``n`` only sets
    # the batch the helper times)
    stats = benchmark_visgraph(env, 64, repeats=1)
    assert stats["n"] == 64 and stats["queries_per_s"] > 0
    with pytest.raises(ValueError, match="point robot"):
        VisGraph.build(make_env("rigid/0"))
    with pytest.raises(ValueError, match=r"\(N, 2, 2\)"):
        VisGraph.build(env, 0.0).plan(np.zeros((3, 2)))
