"""The blocked-cell bitmap of the broad-phase index (issue 18) and the point robot's batched
steer_to that uses it: the bitmap is exact on imported grids and never marks a cell that is not
inside a box; the indexed steer_to (bitmap first pass, flag queue, queue tail) gives exactly the
answers of the unindexed exact kernel, on random grid maps and adversarial segments (along cell
edges, through cell corners, endpoints on cell boundaries), at padding 0 and above. The
benchmark maze and arbitrary boxes are in test_blocked_bitmap_steer.py."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ntq_jax as nj
from ntq_jax import broadphase, geometry, grid_maps
from ntq_jax.geometry import World
from ntq_jax.robots import PointRobot, base

GRID = 24  # cells per side of the random grid maps (fixed: one compiled program per setting)
MAX_BOXES = 160  # the boxes of a map padded to this count with far-away sentinels
MAX_K = 24  # an index cell's candidate rows, padded to this count


def _grid_world(occ, res, origin):
    return grid_maps.grid_world(grid_maps.OccupancyGrid(occ, res, origin))


def _padded(world: World, reach: float, cell: float) -> World:
    """``world`` with its index, boxes and candidate lists padded to fixed sizes (sentinels;
    in NumPy, so that no small program is compiled per map)."""
    nb = world.num_boxes
    assert nb <= MAX_BOXES
    sentinel = np.asarray(broadphase.SENTINEL_BOX, np.float32)
    boxes = np.concatenate(
        [np.asarray(world.boxes), np.broadcast_to(sentinel, (MAX_BOXES - nb, 4))]
    )
    index = broadphase.build_index(world.bounds, world.boxes, reach, cell)
    k = index.capacity
    assert k <= MAX_K
    table = np.asarray(index.boxes)
    table = np.concatenate(
        [table, np.broadcast_to(sentinel, (table.shape[0], MAX_K - k, 4))], axis=1
    )
    return dataclasses.replace(
        world, boxes=jnp.asarray(boxes), index=dataclasses.replace(index, boxes=jnp.asarray(table))
    )


_exact = jax.jit(
    lambda a, b, world, padding: jax.vmap(geometry.segment_free, in_axes=(1, 1, None, None))(
        a, b, world, padding
    ),
    static_argnums=3,
)


@functools.partial(jax.jit, static_argnums=3)
def _indexed_and_exact(a, b, worlds, paddings):
    """``[(indexed, exact), ...]``: the indexed steer_to on each of ``worlds`` at its padding
    (static), and the unindexed exact kernel on the same boxes at that padding. One compiled
    program for all the paddings of a setting: the paddings and the index geometry are
    static, and one program compiles in about 60% of the CPU time of the six separate ones."""
    return [
        (
            PointRobot().steer_to_batch(a, b, w, p),
            jax.vmap(geometry.segment_free, in_axes=(1, 1, None, None))(
                a, b, dataclasses.replace(w, index=None), p
            ),
        )
        for w, p in zip(worlds, paddings)
    ]


def _segments(rng, n, res, origin):
    """Random segments of four kinds, coordinate-major: uniform, with grid-vertex endpoints
    (through cell corners), along grid lines (cell edges), and endpoints on cell boundaries."""
    x0, y0 = origin
    span = GRID * res
    out = []
    k = n // 4
    # uniform in the workspace (short and long)
    a = rng.uniform(0, span, (k, 2))
    out.append(
        (
            a,
            np.where(
                rng.random((k, 1)) < 0.5,
                a + rng.normal(0, 2 * res, a.shape),
                rng.uniform(0, span, (k, 2)),
            ),
        )
    )
    # grid vertices: through cell corners (diagonals of cells and of blocks of cells)
    out.append((rng.integers(0, GRID + 1, (k, 2)) * res, rng.integers(0, GRID + 1, (k, 2)) * res))
    # along grid lines: a shared x (or y) that is a cell edge
    line = rng.integers(0, GRID + 1, k) * res
    s, t = rng.uniform(0, span, k), rng.uniform(0, span, k)
    vertical = rng.random(k) < 0.5
    a = np.where(vertical[:, None], np.c_[line, s], np.c_[s, line])
    b = np.where(vertical[:, None], np.c_[line, t], np.c_[t, line])
    out.append((a, b))

    # endpoints on cell boundaries: one coordinate on a grid line, the other anywhere
    def on_edge(m):
        p = rng.uniform(0, span, (m, 2))
        j = rng.integers(0, 2, m)
        p[np.arange(m), j] = rng.integers(0, GRID + 1, m) * res
        return p

    out.append((on_edge(n - 3 * k), on_edge(n - 3 * k)))
    a = np.concatenate([p for p, _ in out]) + [x0, y0]
    b = np.concatenate([q for _, q in out]) + [x0, y0]
    return (jnp.asarray(np.asarray(a.T, np.float32)), jnp.asarray(np.asarray(b.T, np.float32)))


# ---------------------------------------------------------------------------
# The bitmap
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "res, origin", [(1.0, (0.0, 0.0)), (0.05, (-3.2, 1.7)), (0.3, (10.0, -4.0))]
)
def test_bitmap_is_the_grid(res, origin):
    """On an imported grid whose index cells are the grid's (or a multiple of them), the
    bitmap is exactly the occupancy grid at the grid's resolution."""
    rng = np.random.default_rng(3)
    occ = rng.random((GRID, GRID + 5)) < 0.4
    world = _grid_world(occ, res, origin)
    for cell in (res, 2 * res, 3 * res):
        index = broadphase.build_index(world.bounds, world.boxes, 0.5 * cell, cell)
        assert index.blocked is not None
        assert index.bcell == pytest.approx(res, rel=1e-6)
        got = np.asarray(index.blocked).reshape(index.bny, index.bnx)
        np.testing.assert_array_equal(got, occ)


BITMAP_CELLS = 200 * 150  # the most bitmap cells below: cells of at least 0.1 (the thinnest box)


@given(seed=st.integers(0, 10**6), cell=st.sampled_from([0.3, 0.5, 1.0, 1.7]))
@settings(max_examples=30, deadline=None)
def test_bitmap_cells_lie_inside_one_box(seed, cell):
    """Arbitrary boxes: every set cell lies inside one box (conservative), and the bitmap is
    not empty when a box contains whole cells."""
    rng = np.random.default_rng(seed)
    bounds = np.array([[0.0, 20.0], [0.0, 15.0]])
    boxes = np.c_[rng.uniform(0, 20, (40, 2)), rng.uniform(0.05, 2.5, (40, 2))]
    got = broadphase.blocked_bitmap(bounds, boxes, cell, 20.0, min_fill=0.0)
    if got is None:
        return
    blocked, bcell, margin = got
    rows, cols = np.nonzero(blocked)
    lo_x, lo_y = cols * bcell, rows * bcell
    hi_x, hi_y = lo_x + bcell, lo_y + bcell
    tol = 0.5 * margin
    inside = (
        (lo_x[:, None] >= boxes[:, 0] - boxes[:, 2] - tol)
        & (hi_x[:, None] <= boxes[:, 0] + boxes[:, 2] + tol)
        & (lo_y[:, None] >= boxes[:, 1] - boxes[:, 3] - tol)
        & (hi_y[:, None] <= boxes[:, 1] + boxes[:, 3] + tol)
    )
    assert inside.any(axis=1).all()
    # the points certainly_blocked accepts: at least margin inside a set cell, so inside a box;
    # the flat bitmap padded with zeros (never read: its reads are clipped to bnx * bny cells)
    # to one length, so that its eager gather compiles once, not once per bitmap size
    assert blocked.size <= BITMAP_CELLS
    flat = np.zeros(BITMAP_CELLS, np.uint8)
    flat[: blocked.size] = blocked.ravel()
    index = broadphase.ObstacleIndex(
        jnp.zeros((1, 4, 4)),
        0.0,
        0.0,
        20.0,
        1,
        1,
        1.0,
        jnp.asarray(flat),
        bcell,
        blocked.shape[1],
        blocked.shape[0],
        margin,
    )
    pts = rng.uniform(0, 20, (4000, 2)).astype(np.float32)
    hit = np.asarray(index.certainly_blocked(jnp.asarray(pts[:, 0]), jnp.asarray(pts[:, 1])))
    p = pts[hit].astype(np.float64)
    in_box = (np.abs(p[:, None, 0] - boxes[:, 0]) < boxes[:, 2]) & (
        np.abs(p[:, None, 1] - boxes[:, 1]) < boxes[:, 3]
    )
    assert in_box.any(axis=1).all()


def test_no_bitmap_without_whole_cells():
    """A box that contains no whole bitmap cell: no bitmap, and steer_to takes the path
    without the first pass (same answers as the exact kernel)."""
    bounds = np.array([[0.0, 20.0], [0.0, 20.0]])
    boxes = np.array([[5.05, 5.05, 0.3, 0.3]] * 70)  # more than UNROLL_MAX: Env indexes it
    assert broadphase.blocked_bitmap(bounds, boxes, 1.0, 20.0, min_fill=0.0) is None
    env = nj.Env("x", PointRobot(), World.create(bounds, boxes), 0.1)
    assert env.world.index is not None and env.world.index.blocked is None
    rng = np.random.default_rng(0)
    a = rng.uniform(3, 7, (500, 2)).astype(np.float32)
    b = rng.uniform(3, 7, (500, 2)).astype(np.float32)
    ref = _exact(
        jnp.asarray(a.T), jnp.asarray(b.T), dataclasses.replace(env.world, index=None), 0.1
    )
    np.testing.assert_array_equal(np.asarray(env.steer_to(a, b)), np.asarray(ref))


# ---------------------------------------------------------------------------
# The flag queue
# ---------------------------------------------------------------------------


@functools.cache
def _flag_queue_picks(num: int):
    """The jitted ``flags -> (pick(0 .. num - 1), work)``, one per length (the densities share it)."""
    return jax.jit(
        lambda f: (lambda p, w: (p(jnp.arange(num, dtype=jnp.int32)), w))(*base.flag_queue(f))
    )


@pytest.mark.parametrize("num", [1, 31, 32, 33, 1000, 4099])
@pytest.mark.parametrize("density", [0.0, 0.01, 0.5, 1.0])
def test_flag_queue_lists_the_flags_in_order(num, density):
    rng = np.random.default_rng(num)
    flags = rng.random(num) < density
    pick, work = _flag_queue_picks(num)(jnp.asarray(flags))
    ref = np.flatnonzero(flags)
    assert int(work) == len(ref)
    np.testing.assert_array_equal(np.asarray(pick)[: len(ref)], ref)


@functools.partial(jax.jit, static_argnums=3)
def _check_queue_planted(a, n, planted, cache):
    """:func:`base.check_queue` of :func:`test_check_queue_checks_exactly_the_states_of_each_motion`:
    the motions' state counts ``n`` and planted states are arguments, not constants, so every
    queue length shares one compiled program (per ``cache``)."""

    def valid_at(ap, bp, t):
        nq = n[ap[0].astype(jnp.int32)]
        bad = planted[ap[0].astype(jnp.int32)] & (
            jnp.abs(t * nq - ap[1]) < 0.25
        )  # the planted state k = n // 2
        return (t >= 0) & (t <= 1) & ~bad

    queue = base.flag_queue(n > 0) if cache else None
    return base.check_queue(a, a, n, valid_at, lanes=64, per_step=2, queue=queue, tail_lanes=32)


@pytest.mark.parametrize("work", [0, 1, 5, 32, 33, 200])
@pytest.mark.parametrize("cache", [False, True])
def test_check_queue_checks_exactly_the_states_of_each_motion(work, cache):
    """Every queued motion has all its states ``t = k / n`` (``k = 0..n``) checked and no
    other: ``valid_at`` fails outside ``[0, 1]`` and at one planted state, so a motion is
    free exactly when it does not hold the planted state. Queues of 0 to 200 motions on 64
    lanes with a tail of 32, so the first loop runs many iterations, one, or none (at most
    32 motions: the tail takes them from the start)."""
    num = 256
    rng = np.random.default_rng(work)
    n = np.zeros(num, np.int32)
    todo = rng.choice(num, work, replace=False)
    n[todo] = rng.integers(1, 40, work)
    planted = rng.random(num) < 0.5  # these motions are invalid at state k = n // 2
    a = jnp.asarray(np.stack([np.arange(num), n // 2]).astype(np.float32))  # row 0: motion id
    got = _check_queue_planted(a, jnp.asarray(n), jnp.asarray(planted), cache)
    np.testing.assert_array_equal(np.asarray(got), (n > 0) & ~planted)


# ---------------------------------------------------------------------------
# steer_to: indexed with the bitmap against the unindexed exact kernel
# ---------------------------------------------------------------------------

PAD_CELLS = (0.0, 0.1, 0.5)  # the paddings, in cells of the grid


@given(
    seed=st.integers(0, 10**6),
    density=st.sampled_from([0.15, 0.35, 0.6]),
    setting=st.sampled_from([(1.0, (0.0, 0.0), 1), (0.05, (-3.2, 1.7), 2)]),
)
@settings(max_examples=14, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_indexed_steer_equals_exact_on_random_grids(seed, density, setting):
    """Random occupancy grids (exact rectangle cover), index cells of 1 or 2 grid cells,
    padding 0 and fractions of a cell (every map at each of :data:`PAD_CELLS`, through one
    compiled program per setting), segments of the four kinds of :func:`_segments`. The
    settings: unit cells at the origin; and small cells (float32 rounding of cell edges), an
    origin off zero and index cells of two grid cells together (one program each)."""
    res, origin, per_cell = setting
    rng = np.random.default_rng(seed)
    occ = rng.random((GRID, GRID)) < density
    occ[rng.integers(0, GRID), :] = True  # a wall: long boxes
    world = _grid_world(occ, res, origin)
    if world.num_boxes > MAX_BOXES:
        return
    pads = tuple(float(np.float32(c * res)) for c in PAD_CELLS)
    cell = per_cell * res
    worlds = [_padded(world, pad + 0.5 * cell, cell) for pad in pads]
    assert all(w.index.blocked is not None for w in worlds)
    a, b = _segments(rng, 2000, res, origin)
    for pad, (got, ref) in zip(pads, _indexed_and_exact(a, b, worlds, pads)):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(ref), err_msg=f"padding {pad}")


def test_sparse_maps_keep_no_bitmap():
    """Below BITMAP_MIN_FILL set cells the index keeps no bitmap (the path without it)."""
    occ = np.zeros((40, 40), bool)
    occ[5, 3:30] = True  # 27 of 1,600 cells
    world = _grid_world(occ, 1.0, (0.0, 0.0))
    assert broadphase.build_index(world.bounds, world.boxes, 0.5, 1.0).blocked is None
    got = broadphase.blocked_bitmap(world.bounds, world.boxes, 1.0, 40.0, min_fill=0.0)
    assert got is not None and got[0].sum() == 27
