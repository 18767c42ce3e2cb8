"""Batched grid A* (JPS) against scipy's Dijkstra on the same 8-connected, no-corner-cutting graph."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import dijkstra

from ntq_jax.planners import astar as A
from ntq_jax.planners.grid_graph import prepare_grid
from ntq_jax.types import PlanStatus

SQ2 = math.sqrt(2.0)
MOVES = [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]


# ---------------------------------------------------------------------------
# Independent reference: the graph built edge by edge, solved by scipy
# ---------------------------------------------------------------------------


def reference_graph(occ):
    """Sparse adjacency of the 8-grid: straight 1, diagonal sqrt(2) only if both side cells are free."""
    h, w = occ.shape
    free = ~occ

    def is_free(r, c):
        return (
            (0 <= r)
            & (r < h)
            & (0 <= c)
            & (c < w)
            & free[np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)]
        )

    rr, cc = np.nonzero(free)
    rows, cols, wts = [], [], []
    for dr, dc in MOVES:
        ok = is_free(rr + dr, cc + dc)
        if dr and dc:
            ok &= is_free(rr + dr, cc) & is_free(rr, cc + dc)
        rows.append(rr[ok] * w + cc[ok])
        cols.append((rr[ok] + dr) * w + cc[ok] + dc)
        wts.append(np.full(ok.sum(), SQ2 if dr and dc else 1.0))
    return sp.csr_matrix(
        (np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(h * w, h * w)
    )


def random_box_map(rng, h, w, n_boxes, walls=0):
    """Boxes rasterised on an (h, w) grid; each wall is a full row or column with at most one door."""
    occ = np.zeros((h, w), bool)
    for _ in range(n_boxes):
        r0, c0 = rng.integers(0, h), rng.integers(0, w)
        occ[
            r0 : r0 + rng.integers(2, max(3, h // 4)), c0 : c0 + rng.integers(2, max(3, w // 4))
        ] = True
    for k in range(walls):
        if k % 2 == 0:
            r = rng.integers(h // 4, 3 * h // 4)
            occ[r, :] = True
            if rng.random() < 0.5:
                occ[r, rng.integers(0, w)] = False
        else:
            c = rng.integers(w // 4, 3 * w // 4)
            occ[:, c] = True
            if rng.random() < 0.5:
                occ[rng.integers(0, h), c] = False
    return occ


def noise_map(rng, h, w, p):
    """Salt-and-pepper cells: many diagonal squeezes, corners and jump points."""
    return rng.random((h, w)) < p


def sample_queries(rng, occ, n):
    free = np.argwhere(~occ)
    i = rng.integers(0, len(free), size=(n, 2))
    return free[i[:, 0]].astype(np.int32), free[i[:, 1]].astype(np.int32)


def check_paths(occ, res, starts, goals):
    """Every solved path: start..goal, 8-connected, free, no corner cut, step costs sum to the cost."""
    h, w = occ.shape
    status, cost = np.asarray(res.status), np.asarray(res.cost)
    path, plen = np.asarray(res.path), np.asarray(res.path_len)
    wps, nwp = np.asarray(res.waypoints), np.asarray(res.num_waypoints)
    for i in range(len(status)):
        if status[i] != PlanStatus.SOLVED:
            assert plen[i] == 0 and nwp[i] == 0 and np.all(path[i] == -1) and np.isinf(cost[i])
            continue
        p = path[i, : plen[i]]
        assert np.all(path[i, plen[i] :] == -1)
        assert tuple(p[0]) == tuple(starts[i]) and tuple(p[-1]) == tuple(goals[i])
        assert np.all((p >= 0) & (p < [h, w])) and not occ[p[:, 0], p[:, 1]].any()
        d = np.diff(p, axis=0)
        assert np.all(np.abs(d) <= 1) and np.all(np.abs(d).sum(1) >= 1), "not 8-connected"
        diag = np.abs(d).sum(1) == 2
        a = p[:-1][diag]
        dd = d[diag]
        assert (
            not occ[a[:, 0] + dd[:, 0], a[:, 1]].any()
            and not occ[a[:, 0], a[:, 1] + dd[:, 1]].any()
        ), "corner cut"
        np.testing.assert_allclose(np.where(diag, SQ2, 1.0).sum(), cost[i], rtol=1e-5, atol=1e-4)
        # the waypoints are the path's corners: joined by straight or diagonal lines of path cells
        wp = wps[i, : nwp[i]]
        assert np.all(wps[i, nwp[i] :] == -1)
        assert tuple(wp[0]) == tuple(starts[i]) and tuple(wp[-1]) == tuple(goals[i])
        seg = np.diff(wp, axis=0)
        n_cells = np.abs(seg).max(1)
        assert np.all(
            (seg[:, 0] == 0) | (seg[:, 1] == 0) | (np.abs(seg[:, 0]) == np.abs(seg[:, 1]))
        )
        assert n_cells.sum() + 1 == plen[i]
        np.testing.assert_array_equal(p[np.concatenate([[0], np.cumsum(n_cells)])], wp)


# Every call below goes through astar_chunked with CHUNK queries per call, so the
# whole module compiles one program per grid shape (plus one for odd options):
# XLA:CPU takes a few seconds per compilation.
CHUNK = 256
# The 200 x 200 maps are solved in chunks of PLAN_CHUNK instead: the "astar" planner's
# default chunk_size on the 200 x 200 grid of the 20 x 20 point maps at its default
# resolution 0.1, so this is the very program ntq_jax.plan compiles for them (test_plan,
# data generation), shared through the suite's compilation cache. The chunk size only
# decides how the batch is split and padded with invalid queries, which the search skips:
# the answers do not depend on it (test_chunks_are_independent).
PLAN_CHUNK = 1024

MAPS = {
    # name: (builder, number of random queries)
    "boxes_60x90": (lambda rng: random_box_map(rng, 60, 90, 12), 250),
    "walls_60x90": (lambda rng: random_box_map(rng, 60, 90, 6, walls=3), 250),
    "noise_60x90": (lambda rng: noise_map(rng, 60, 90, 0.25), 250),
    "boxes_200x200": (lambda rng: random_box_map(rng, 200, 200, 15), 250),
    "walls_200x200": (lambda rng: random_box_map(rng, 200, 200, 10, walls=2), 250),
}


def solve(occ, starts, goals, chunk=CHUNK, **options):
    return A.astar_chunked(occ, starts, goals, chunk_size=chunk, **options)


@pytest.mark.parametrize("name", list(MAPS))
def test_costs_equal_dijkstra(name):
    builder, n = MAPS[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    occ = builder(rng)
    h, w = occ.shape
    starts, goals = sample_queries(rng, occ, n)
    res = solve(occ, starts, goals, chunk=PLAN_CHUNK if occ.shape == (200, 200) else CHUNK)
    dist = dijkstra(reference_graph(occ), indices=starts[:, 0] * w + starts[:, 1])
    ref = dist[np.arange(n), goals[:, 0] * w + goals[:, 1]]
    status, cost = np.asarray(res.status), np.asarray(res.cost)
    assert not np.any(status == PlanStatus.TIMEOUT) and not np.any(status == PlanStatus.INVALID)
    np.testing.assert_array_equal(status == PlanStatus.SOLVED, np.isfinite(ref))
    np.testing.assert_array_equal(status == PlanStatus.NO_PATH, np.isinf(ref))
    np.testing.assert_allclose(cost, ref, rtol=1e-5, atol=1e-4)
    check_paths(occ, res, starts, goals)
    if name.startswith("walls"):
        assert np.isinf(ref).any(), "the wall maps should have unreachable queries"


def test_invalid_trivial_and_unreachable_queries():
    occ = np.zeros((60, 90), bool)
    occ[:, 45] = True  # two halves, no door
    occ[5, 5] = True
    starts = np.array(
        [
            [0, 0],
            [5, 5],
            [0, 0],
            [-1, 3],
            [0, 90],
            [60, 0],
            [3, 3],
            [0, 0],
            [2, 2],
            [-(10**6), 10**9],
        ]
    )
    goals = np.array(
        [[5, 5], [0, 0], [0, 50], [0, 0], [0, 0], [0, 0], [3, 3], [59, 44], [2, 45], [0, 0]]
    )
    res = solve(occ, starts, goals)
    S, N, I = PlanStatus.SOLVED, PlanStatus.NO_PATH, PlanStatus.INVALID
    np.testing.assert_array_equal(res.status, [I, I, N, I, I, I, S, S, I, I])
    assert float(res.cost[6]) == 0.0 and int(res.path_len[6]) == 1
    np.testing.assert_array_equal(res.path[6, 0], [3, 3])
    np.testing.assert_allclose(float(res.cost[7]), 15 + 44 * SQ2, rtol=1e-6)
    check_paths(occ, res, starts, goals)


def test_no_corner_cutting():
    occ = np.zeros((60, 90), bool)
    occ[0, 1] = True
    occ[11, 10] = occ[10, 11] = True  # (10, 10) and (11, 11) only touch at a corner...
    occ[9:13, 12] = occ[12, 9:13] = occ[9, 9:13] = occ[9:13, 9] = True  # ...inside a closed ring
    starts = np.array([[0, 0], [1, 0], [10, 10]])
    goals = np.array([[1, 1], [0, 0], [11, 11]])
    res = solve(occ, starts, goals)
    np.testing.assert_allclose(
        np.asarray(res.cost)[:2], [2.0, 1.0]
    )  # not sqrt(2): (0, 1) is occupied
    assert int(res.status[2]) == PlanStatus.NO_PATH and np.isinf(float(res.cost[2]))
    check_paths(occ, res, starts, goals)


def test_capacity_is_reported_not_raised():
    rng = np.random.default_rng(3)
    occ = random_box_map(rng, 60, 90, 12, walls=1)
    starts, goals = sample_queries(rng, occ, CHUNK)
    full = solve(occ, starts, goals)
    small = solve(occ, starts, goals, open_capacity=6, max_path_len=60, max_waypoints=6)
    st, st_full = np.asarray(small.status), np.asarray(full.status)
    assert np.any(st == PlanStatus.TIMEOUT) and np.any(st == PlanStatus.SOLVED)
    ok = st == PlanStatus.SOLVED
    np.testing.assert_array_equal(np.asarray(small.cost)[ok], np.asarray(full.cost)[ok])
    assert np.all(
        np.isin(st[st_full == PlanStatus.SOLVED], [PlanStatus.SOLVED, PlanStatus.TIMEOUT])
    )
    assert np.all(st[st_full != PlanStatus.SOLVED] == st_full[st_full != PlanStatus.SOLVED])
    check_paths(occ, small, starts, goals)


def oracle_tables(occ):
    """``(jump (H*W, 8), label (H*W,))`` of :class:`GridGraph`, cell by cell from the definitions.

    Straight move d from a free cell x: walk y = x, x + d, ...; stop with ``-n`` after n
    free steps when the next cell is blocked, or with ``n`` when the n-th cell entered is
    a jump point (a side cell of it free whose neighbour behind it is blocked). Diagonal
    move: the next cell needs both side cells free, and is a jump point when one of the
    two straight moves making up the diagonal finds a jump point from it. Labels: the
    smallest flat index of the 4-connected component (scipy's labelling), H*W if blocked.
    """
    h, w = occ.shape

    def free(r, c):
        return 0 <= r < h and 0 <= c < w and not occ[r, c]

    table = np.zeros((h, w, 8), np.int64)
    for k, (dr, dc) in enumerate(MOVES[:4]):
        pr, pc = dc, dr
        for r, c in zip(*np.nonzero(~occ)):
            n, y = 0, (r, c)
            while free(y[0] + dr, y[1] + dc):
                n += 1
                x, y = y, (y[0] + dr, y[1] + dc)
                if any(
                    free(y[0] + s * pr, y[1] + s * pc) and not free(x[0] + s * pr, x[1] + s * pc)
                    for s in (1, -1)
                ):
                    break
            else:
                n = -n
            table[r, c, k] = n
    for k, (dr, dc) in enumerate(MOVES[4:], start=4):
        kv, kh = MOVES.index((dr, 0)), MOVES.index((0, dc))
        for r, c in zip(*np.nonzero(~occ)):
            n, y = 0, (r, c)
            while free(y[0] + dr, y[1] + dc) and free(y[0] + dr, y[1]) and free(y[0], y[1] + dc):
                n += 1
                y = (y[0] + dr, y[1] + dc)
                if table[y[0], y[1], kv] > 0 or table[y[0], y[1], kh] > 0:
                    break
            else:
                n = -n
            table[r, c, k] = n
    lab, n = ndimage.label(~occ)
    first = {i: h * w for i in range(n + 1)}
    for f, i in enumerate(lab.ravel()):
        first[i] = min(first[i], f) if i else h * w
    return table.reshape(-1, 8), np.array([first[i] for i in lab.ravel()])


@pytest.mark.parametrize("seed", range(4))
def test_grid_tables_equal_the_cell_by_cell_oracle(seed):
    """:func:`prepare_grid`'s jump distances and component labels, on boxes, walls with doors,
    salt-and-pepper noise and degenerate shapes, against :func:`oracle_tables`."""
    rng = np.random.default_rng(seed)
    grids = [
        random_box_map(rng, 23, 31, 6, walls=2),
        noise_map(rng, 17, 19, 0.3),
        noise_map(rng, 1, 12, 0.2),
        noise_map(rng, 9, 1, 0.2),
        np.zeros((5, 7), bool),
        np.ones((3, 4), bool),
    ]
    for occ in grids:
        graph = prepare_grid(occ)
        jump, label = oracle_tables(occ)
        assert graph.jump.dtype == np.int16 and graph.label.dtype == np.int32
        np.testing.assert_array_equal(np.asarray(graph.occ), occ)
        np.testing.assert_array_equal(np.asarray(graph.jump), jump)
        np.testing.assert_array_equal(np.asarray(graph.label), label)


def test_one_compilation_per_shape():
    """Same grid shape and batch size: one compiled program, whatever the grid contents,
    the queries and the batch size (chunks of CHUNK queries)."""
    rng = np.random.default_rng(7)
    occ = random_box_map(rng, 60, 90, 5)
    solve(occ, *sample_queries(rng, occ, CHUNK))  # the program test_costs_equal_dijkstra compiles
    size = A._search_batch._cache_size()
    for k in range(3):
        occ = random_box_map(rng, 60, 90, 4 + 2 * k)
        starts, goals = sample_queries(rng, occ, 100 + 50 * k)
        res = A.astar(
            prepare_grid(occ), *(np.resize(q, (CHUNK, 2)).astype(np.int32) for q in (starts, goals))
        )  # queries repeated
        np.testing.assert_array_equal(res.cost[: len(starts)], solve(occ, starts, goals).cost)
    assert A._search_batch._cache_size() == size


def test_chunks_are_independent():
    rng = np.random.default_rng(11)
    occ = random_box_map(rng, 60, 90, 10, walls=1)
    starts, goals = sample_queries(rng, occ, 300)
    starts[3] = [-5, 2]
    whole = solve(occ, starts, goals)  # two chunks, the second one padded
    first, second = solve(occ, starts[:150], goals[:150]), solve(occ, starts[150:], goals[150:])
    for a, b, c in zip(whole, first, second):
        np.testing.assert_array_equal(a, np.concatenate([b, c]))
    empty = solve(occ, np.zeros((0, 2), int), np.zeros((0, 2), int))
    assert empty.cost.shape == (0,) and empty.path.shape[0] == 0


def test_bad_input_is_rejected():
    occ = np.zeros((10, 10), bool)
    with pytest.raises(ValueError, match="starts and goals"):
        A.astar(occ, np.zeros((3, 2), int), np.zeros((4, 2), int))
    with pytest.raises(ValueError, match="occ must be a 2D"):
        A.astar(np.zeros(10, bool), np.zeros((1, 2), int), np.zeros((1, 2), int))
    with pytest.raises(TypeError, match="outside jax.jit and pass the GridGraph"):
        jax.jit(lambda o: A.astar(o, np.zeros((1, 2), int), np.zeros((1, 2), int)).cost)(occ)
    graph = prepare_grid(occ)  # prepared outside: the search itself may be traced
    cost = jax.jit(lambda g: A.astar(g, np.zeros((1, 2), int), np.full((1, 2), 9)).cost)(graph)
    np.testing.assert_allclose(np.asarray(cost), [9 * math.sqrt(2.0)], rtol=1e-6)
    with pytest.raises(ValueError, match="chunk_size"):
        A.astar_chunked(occ, np.zeros((1, 2), int), np.zeros((1, 2), int), chunk_size=0)


def test_non_bool_and_empty_grids_are_refused():
    """Issue 52 (rough edges 8-10): a non-bool grid is refused, not cast (a uint8 image with
    255 = free used to become all occupied), an empty grid is one ValueError (it was a
    ZeroDivisionError), and ``progress`` receives the 9 tables."""
    q = np.zeros((1, 2), int)
    image = np.full((6, 7), 255, np.uint8)
    bad = {
        "uint8": image,
        "int64": np.zeros((6, 7), np.int64),
        "float32": np.full((6, 7), 0.2, np.float32),
        "float64": np.full((6, 7), np.nan),
        "<U1": np.full((6, 7), "x"),
    }
    for dtype, occ in bad.items():
        with pytest.raises(ValueError, match=rf"bool occupancy grid.*dtype {dtype}.*image < 128"):
            prepare_grid(occ)
        with pytest.raises(ValueError, match=rf"dtype {dtype}"):
            A.astar(occ, q, q)
    res = A.astar(image < 128, q, np.array([[5, 6]]))  # the documented fix plans on the free image
    assert int(res.status[0]) == PlanStatus.SOLVED and np.isfinite(float(res.cost[0]))
    for shape in [(0, 5), (5, 0), (0, 0)]:
        with pytest.raises(ValueError, match="has no cell"):
            A.astar(np.zeros(shape, bool), q, q)
        with pytest.raises(ValueError, match="has no cell"):
            A.astar_chunked(np.zeros(shape, bool), q, q)
    empty = prepare_grid(np.zeros((1, 1), bool))._replace(occ=jnp.zeros((0, 5), bool))
    with pytest.raises(ValueError, match="has no cell"):  # a hand-made GridGraph too
        A.astar(empty, q, q)

    calls = []

    class Bar:
        def __init__(self, **kw):
            calls.append(("open", kw["total"], kw["unit"]))

        def update(self, n=1):
            calls.append(("update", n))

        def set_postfix_str(self, s):
            pass

        def close(self):
            calls.append(("close",))

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.close()

    occ = np.zeros((8, 9), bool)
    graph = prepare_grid(occ, progress=lambda **kw: Bar(**kw))
    assert (
        calls[0] == ("open", 9, "table")
        and calls.count(("update", 1)) == 9
        and calls[-1] == ("close",)
    )
    np.testing.assert_array_equal(np.asarray(graph.jump), np.asarray(prepare_grid(occ).jump))
