"""The exact geometry kernels against an independent oracle (shapely / NumPy float64).

Every kernel is checked on >= 10^4 random cases with and without padding (random
padding in [0, 1.5], and exactly 0). Hypothesis draws the seeds, paddings and maps;
each example pushes thousands of cases through the vmapped, jitted kernel at once
and compares them with shapely's exact float64 distances.

Semantics under test: a shape collides when its Euclidean distance to an obstacle
is ``<= padding`` (closed sets, touching is a collision); NaN/inf is invalid.

Tangency band. The kernels compute in float32 on float32 inputs; the oracle
computes in float64 on the very same (float32-rounded) inputs, so the two can
only disagree by the kernels' own float32 rounding. A case is counted only when
``|dist - padding| > band`` with ``band = 1e-6 + 4 * eps32 * scale``, where
``eps32 = 2^-23 ~ 1.19e-7`` and ``scale`` is the largest coordinate magnitude of
the case (~25 here, so band ~ 1.3e-5): each float32 operation on coordinates of
size ``scale`` rounds by up to ``eps32 * scale / 2`` and the kernels chain a few
of them (midpoint, difference, cross product, comparison against a sum). A 1e-6
band alone would be below float32 resolution at coordinate 20 (one ulp there is
1.9e-6). Measured without any band on ~10^5 cases per kernel, the worst
disagreement was 1.05e-6 = 1.2 eps32 * scale, so the band has a ~3x margin and
is still ~10^4 times smaller than the smallest obstacle size or padding drawn:
a real geometric bug cannot hide in it. Cases are drawn so that many fall just
outside the band (offsets from tangency log-uniform down to 1e-6), and the
tests assert that most cases are counted.
For the arm, the band also contains the float32 forward-kinematics error bound
(see ``_fk_tol``).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

from ntq_jax import geometry as G
from ntq_jax.geometry import World
from ntq_jax.robots import NLinkArm, PointRobot, RigidBody
from ntq_jax.robots.batch import is_valid_batch, steer_to_batch

EPS32 = float(np.finfo(np.float32).eps)
N_CASES = 4096  # cases per hypothesis example
N_EXAMPLES = 4  # examples per (kernel, padding mode): >= 1.6e4 cases each
# No shrinking: every failure message already lists the disagreeing cases verbatim, and
# shrinking would recompile the kernels for every candidate padding.
PHASES = (Phase.explicit, Phase.reuse, Phase.generate)
SETTINGS = settings(
    max_examples=N_EXAMPLES,
    deadline=None,
    database=None,
    phases=PHASES,
    suppress_health_check=list(HealthCheck),
)

seeds = st.integers(0, 2**32 - 1)
random_padding = st.floats(
    0.0, 1.5, allow_nan=False, allow_infinity=False, allow_subnormal=False
).filter(lambda p: p > 0.0)
PAD_MODES = {"zero": st.just(0.0), "random": random_padding}


def band(scale):
    """Half-width of the float32 tangency band (see the module docstring)."""
    return 1e-6 + 4.0 * EPS32 * np.maximum(scale, 1.0)


def f32(a):
    return np.asarray(a, np.float32)


# ---------------------------------------------------------------------------
# Case generators (NumPy). Obstacles are per case, so the kernels are vmapped
# over (case, obstacle) pairs and only the padding is static.
# ---------------------------------------------------------------------------


def _logu(rng, lo, hi, n):
    return np.exp(rng.uniform(math.log(lo), math.log(hi), n))


def rand_boxes(rng, n):
    return f32(
        np.stack(
            [
                rng.uniform(0, 20, n),
                rng.uniform(0, 20, n),
                _logu(rng, 0.05, 5, n),
                _logu(rng, 0.05, 5, n),
            ],
            1,
        )
    )


def rand_discs(rng, n):
    return f32(np.stack([rng.uniform(0, 20, n), rng.uniform(0, 20, n), _logu(rng, 0.05, 4, n)], 1))


def tangency_offsets(rng, n, pad):
    """Distances ``pad +- 10^U(-6.5, 0.5)``: most cases just outside the band, both sides."""
    return pad + rng.choice([-1.0, 1.0], n) * 10 ** rng.uniform(-6.0, 0.5, n)


def box_anchor(rng, boxes, s):
    """A point at signed offset ``s`` from a random edge or corner of each box, and the
    outward unit normal there (so the point's distance to the box is ``s`` for ``s >= 0``)."""
    b = boxes.astype(np.float64)
    cx, cy, hw, hh = b.T
    n = len(b)
    corner = rng.random(n) < 0.5
    sx, sy = rng.choice([-1.0, 1.0], n), rng.choice([-1.0, 1.0], n)
    vert = rng.random(n) < 0.5
    t = rng.uniform(-1, 1, n)
    ex = np.where(vert, cx + sx * hw, cx + t * hw)
    ey = np.where(vert, cy + t * hh, cy + sy * hh)
    a = rng.uniform(0, np.pi / 2, n)
    px, py = np.where(corner, cx + sx * hw, ex), np.where(corner, cy + sy * hh, ey)
    nx = np.where(corner, sx * np.cos(a), np.where(vert, sx, 0.0))
    ny = np.where(corner, sy * np.sin(a), np.where(vert, 0.0, sy))
    return px + s * nx, py + s * ny, nx, ny


def disc_anchor(rng, discs, s):
    d = discs.astype(np.float64)
    a = rng.uniform(0, 2 * np.pi, len(d))
    nx, ny = np.cos(a), np.sin(a)
    rr = d[:, 2] + s
    return d[:, 0] + rr * nx, d[:, 1] + rr * ny, nx, ny


def box_region(rng, boxes, pad):
    b = boxes.astype(np.float64)
    m = pad + 2.0
    return (
        rng.uniform(b[:, 0] - b[:, 2] - m, b[:, 0] + b[:, 2] + m),
        rng.uniform(b[:, 1] - b[:, 3] - m, b[:, 1] + b[:, 3] + m),
    )


def disc_region(rng, discs, pad):
    d = discs.astype(np.float64)
    m = d[:, 2] + pad + 2.0
    return rng.uniform(d[:, 0] - m, d[:, 0] + m), rng.uniform(d[:, 1] - m, d[:, 1] + m)


def point_cases(rng, obst, pad, kind):
    n = len(obst)
    anchor, region = (box_anchor, box_region) if kind == "box" else (disc_anchor, disc_region)
    px, py, _, _ = anchor(rng, obst, tangency_offsets(rng, n, pad))
    rx, ry = region(rng, obst, pad)
    near = rng.random(n) < 0.7
    return f32(np.stack([np.where(near, px, rx), np.where(near, py, ry)], 1))


def tangent_segments(rng, px, py, nx, ny):
    """``(n, 4)`` segments through the points ``(px, py)`` along the tangent of the outward
    normal ``(nx, ny)`` (slightly tilted in 70 % of cases), the point at an end or inside."""
    n = len(px)
    tilt = np.where(
        rng.random(n) < 0.3, 0.0, rng.choice([-1, 1], n) * 10 ** rng.uniform(-6, -0.5, n)
    )
    tx = -ny * np.cos(tilt) - nx * np.sin(tilt)
    ty = nx * np.cos(tilt) - ny * np.sin(tilt)
    length = 10 ** rng.uniform(-3, 1.2, n)
    u = rng.choice([0.0, 1.0, 0.5], n, p=[0.2, 0.2, 0.6])
    u = np.where(u == 0.5, rng.random(n), u)
    tangent = np.stack(
        [
            px - u * length * tx,
            py - u * length * ty,
            px + (1 - u) * length * tx,
            py + (1 - u) * length * ty,
        ],
        1,
    )
    return tangent


def segment_cases(rng, obst, pad, kind):
    """Segments ``(n, 4)``: tangent to the padded obstacle (+- a tiny tilt, closest point at an
    endpoint or inside), random, axis-parallel, zero-length, and along the box edges."""
    n = len(obst)
    anchor, region = (box_anchor, box_region) if kind == "box" else (disc_anchor, disc_region)
    px, py, nx, ny = anchor(rng, obst, tangency_offsets(rng, n, pad))
    tangent = tangent_segments(rng, px, py, nx, ny)
    x0, y0 = region(rng, obst, pad)
    x1, y1 = region(rng, obst, pad)
    rand = np.stack([x0, y0, x1, y1], 1)
    horiz = rng.random(n) < 0.5
    axis = np.stack([x0, y0, np.where(horiz, x1, x0), np.where(horiz, y0, y1)], 1)
    zero = np.stack([px, py, px, py], 1)
    cat = rng.choice(5, n, p=[0.45, 0.2, 0.15, 0.1, 0.1])
    segs = np.select([cat[:, None] == k for k in range(4)], [tangent, rand, axis, zero], rand)
    if kind == "box":
        # along an edge line (offset by the padding): x = cx +- (hw + pad), y spanning the edge
        b = obst.astype(np.float32)
        sx = rng.choice([-1.0, 1.0], n).astype(np.float32)
        ex = b[:, 0] + sx * (b[:, 2] + np.float32(pad))
        ya = b[:, 1] - b[:, 3] * np.float32(rng.uniform(-1.5, 1.5, n))
        yb = b[:, 1] + b[:, 3] * np.float32(rng.uniform(-1.5, 1.5, n))
        edge = np.stack([ex, ya, ex, yb], 1)
        swap = rng.random(n) < 0.5  # the same along y
        ey = b[:, 1] + sx * (b[:, 3] + np.float32(pad))
        xa = b[:, 0] - b[:, 2] * np.float32(rng.uniform(-1.5, 1.5, n))
        xb = b[:, 0] + b[:, 2] * np.float32(rng.uniform(-1.5, 1.5, n))
        edge = np.where(swap[:, None], np.stack([xa, ey, xb, ey], 1), edge)
        segs = np.where((cat == 4)[:, None], edge, segs)
    else:
        segs = np.where((cat == 4)[:, None], tangent, segs)
    return f32(segs)


SPECIAL_THETAS = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2, -np.pi], np.float32)


def rect_cases(rng, obst, pad, kind):
    """Rectangles ``(n, 5)`` = (x, y, theta, half_l, half_w): touching the padded obstacle from
    outside at a chosen offset (edge-parallel contacts at theta = 0, pi/2, pi), and random."""
    n = len(obst)
    anchor, region = (box_anchor, box_region) if kind == "box" else (disc_anchor, disc_region)
    hl, hw = _logu(rng, 0.05, 2.0, n), _logu(rng, 0.05, 2.0, n)
    special = rng.random(n) < 0.4
    th = np.where(special, rng.choice(SPECIAL_THETAS, n), rng.uniform(-np.pi, np.pi, n))
    th = f32(th).astype(np.float64)
    px, py, nx, ny = anchor(rng, obst, tangency_offsets(rng, n, pad))
    c, s = np.cos(th), np.sin(th)
    h = hl * np.abs(nx * c + ny * s) + hw * np.abs(-nx * s + ny * c)  # support along the normal
    rx, ry = region(rng, obst, pad)
    near = rng.random(n) < 0.7
    x = np.where(near, px + h * nx, rx)
    y = np.where(near, py + h * ny, ry)
    return f32(np.stack([x, y, th, hl, hw], 1))


def rect_polygons(cases):
    c = cases.astype(np.float64)
    x, y, th, hl, hw = c.T
    co, si = np.cos(th), np.sin(th)
    pts = [
        np.stack([x + a * hl * co - b * hw * si, y + a * hl * si + b * hw * co], 1)
        for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1))
    ]
    return np.stack(pts, 1)  # (n, 4, 2)


# ---------------------------------------------------------------------------
# Oracle
# ---------------------------------------------------------------------------


def box_polys(boxes, shrink=0.0):
    b = boxes.astype(np.float64)
    hw, hh = b[:, 2] - shrink, b[:, 3] - shrink
    return shapely.box(b[:, 0] - hw, b[:, 1] - hh, b[:, 0] + hw, b[:, 1] + hh)


def oracle_dist(geoms, obst, kind, tol):
    """Exact float64 signed distance of each geometry to its obstacle.

    Positive outside. Discs: centre distance minus radius (so negative inside). Boxes: the
    distance when positive; when the geometry touches the box, ``-1`` if it also meets the
    box shrunk by ``tol`` (a collision beyond the band), else ``0`` (inside the band).
    """
    o = obst.astype(np.float64)
    if kind == "disc":
        return shapely.distance(geoms, shapely.points(o[:, :2])) - o[:, 2]
    d = shapely.distance(geoms, box_polys(o))
    deep = (np.minimum(o[:, 2], o[:, 3]) > tol) & shapely.intersects(geoms, box_polys(o, tol))
    return np.where(d > 0, d, np.where(deep, -1.0, 0.0))


def assert_agrees(hit, dist, pad, scale, what, inputs, min_counted=0.6):
    """Zero disagreements outside the band; returns how many cases were counted."""
    hit = np.asarray(hit, bool)
    tol = band(scale)
    counted = np.abs(dist - pad) > tol
    bad = np.flatnonzero(counted & (hit != (dist <= pad)))
    if bad.size:
        rows = "\n".join(
            f"  inputs={inputs[i].tolist()} kernel_hit={hit[i]} oracle_dist={dist[i]!r}"
            for i in bad[:5]
        )
        pytest.fail(
            f"{what} (padding={pad!r}): {bad.size} disagreements outside the tangency band, "
            f"e.g.\n{rows}"
        )
    assert counted.mean() >= min_counted, f"{what}: only {counted.mean():.2f} of the cases counted"
    # the cases must exercise both outcomes
    assert 0.05 < hit[counted].mean() < 0.95, f"{what}: degenerate case mix {hit[counted].mean()}"
    return int(counted.sum())


# ---------------------------------------------------------------------------
# Per-obstacle kernels
# ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _kernel(name: str, padding: float):
    fns = {
        "point_box": lambda c, o: G.point_hits_box(c[0], c[1], o, padding),
        "point_disc": lambda c, o: G.point_hits_disc(c[0], c[1], o, padding),
        "segment_box": lambda c, o: G.segment_hits_box(c[0], c[1], c[2], c[3], o, padding),
        "segment_disc": lambda c, o: G.segment_hits_disc(c[0], c[1], c[2], c[3], o, padding),
        "rect_box": lambda c, o: G.rect_hits_box(c[0], c[1], c[2], c[3], c[4], o, padding),
        "rect_disc": lambda c, o: G.rect_hits_disc(c[0], c[1], c[2], c[3], c[4], o, padding),
    }
    return jax.jit(jax.vmap(fns[name]))


def _run_kernel_case(shape: str, kind: str, pad: float, seed: int):
    rng = np.random.default_rng(seed)
    obst = rand_boxes(rng, N_CASES) if kind == "box" else rand_discs(rng, N_CASES)
    if shape == "point":
        cases = point_cases(rng, obst, pad, kind)
        geoms = shapely.points(cases.astype(np.float64))
    elif shape == "segment":
        cases = segment_cases(rng, obst, pad, kind)
        geoms = shapely.linestrings(cases.astype(np.float64).reshape(-1, 2, 2))
    else:
        cases = rect_cases(rng, obst, pad, kind)
        geoms = shapely.polygons(rect_polygons(cases))
    hit = _kernel(f"{shape}_{kind}", pad)(jnp.asarray(cases), jnp.asarray(obst))
    scale = np.max(np.abs(np.concatenate([cases, obst], 1)), axis=1) + pad
    dist = oracle_dist(geoms, obst, kind, band(scale))
    inputs = np.concatenate([cases, obst], 1)
    return assert_agrees(hit, dist, pad, scale, f"{shape}_hits_{kind}", inputs)


@pytest.mark.parametrize("pad_mode", sorted(PAD_MODES))
@pytest.mark.parametrize(
    "shape, kind", [(s, k) for s in ("point", "segment", "rect") for k in ("box", "disc")]
)
def test_kernel_matches_shapely(shape, kind, pad_mode):
    counted = []

    @SETTINGS
    @given(pad=PAD_MODES[pad_mode], seed=seeds)
    def check(pad, seed):
        counted.append(_run_kernel_case(shape, kind, pad, seed))

    check()
    assert sum(counted) >= 10_000


# ---------------------------------------------------------------------------
# Whole robots through the public batch entry points (bounds + several obstacles)
# ---------------------------------------------------------------------------

BOUNDS = np.array([[0.0, 20.0], [0.0, 20.0]])
coord = st.floats(0.0, 20.0, width=32)
half = st.floats(0.125, 4.0, width=32)
world_st = st.tuples(
    st.lists(st.tuples(coord, coord, half, half), min_size=3, max_size=3),
    st.lists(st.tuples(coord, coord, half), min_size=2, max_size=2),
)


def _world_arrays(world_spec):
    boxes, discs = world_spec
    return f32(boxes), f32(discs)


def _world_dists(geoms, boxes, discs, tol):
    """(N, B + C) oracle signed distances of each geometry to each obstacle."""
    cols = [oracle_dist(geoms, np.repeat(b[None], len(geoms), 0), "box", tol) for b in boxes]
    cols += [oracle_dist(geoms, np.repeat(d[None], len(geoms), 0), "disc", tol) for d in discs]
    return np.stack(cols, 1)


def _bounds_excess(pts, bounds):
    """Largest amount by which any of the points ``(N, k, 2)`` leaves the closed bounds."""
    b = np.asarray(bounds, np.float64)
    e = np.maximum.reduce(
        [b[0, 0] - pts[..., 0], pts[..., 0] - b[0, 1], b[1, 0] - pts[..., 1], pts[..., 1] - b[1, 1]]
    )
    return e.max(axis=-1)


def assert_world_agrees(free, dists, excess, pad, tol, what, inputs, min_counted=0.7):
    """``free`` must be False where a collision / bounds violation is certain beyond the band and
    True where clearance and containment are certain beyond it.

    Returns ``(counted, counted and free)``; the callers check the mix over all examples (one
    hypothesis map may well block everything)."""
    free = np.asarray(free, bool)
    sure_hit = (dists < pad - tol[:, None]).any(1) | (excess > tol)
    sure_free = (dists > pad + tol[:, None]).all(1) & (excess < -tol)
    bad = np.flatnonzero((sure_hit & free) | (sure_free & ~free))
    if bad.size:
        rows = "\n".join(
            f"  inputs={inputs[i].tolist()} kernel_free={free[i]} "
            f"oracle_dists={dists[i].tolist()} bounds_excess={excess[i]!r}"
            for i in bad[:5]
        )
        pytest.fail(
            f"{what} (padding={pad!r}): {bad.size} disagreements outside the band, e.g.\n{rows}"
        )
    counted = sure_hit | sure_free
    assert counted.mean() >= min_counted, f"{what}: only {counted.mean():.2f} counted"
    return np.array([counted.sum(), sure_free.sum()])


def assert_enough(totals):
    """>= 10^4 counted cases, both outcomes well represented."""
    counted, free = totals
    assert counted >= 10_000, counted
    assert 0.05 < free / counted < 0.95, (free, counted)


def _near_world_points(rng, boxes, discs, pad, n):
    """Points near the padded obstacles, near the bounds, and uniform in the workspace."""
    k = rng.integers(0, len(boxes) + len(discs), n)
    bi = np.minimum(k, len(boxes) - 1)
    di = np.clip(k - len(boxes), 0, len(discs) - 1)
    s = tangency_offsets(rng, n, pad)
    bx, by, bnx, bny = box_anchor(rng, boxes[bi], s)
    dx, dy, dnx, dny = disc_anchor(rng, discs[di], s)
    isbox = k < len(boxes)
    px, py = np.where(isbox, bx, dx), np.where(isbox, by, dy)
    nx, ny = np.where(isbox, bnx, dnx), np.where(isbox, bny, dny)
    ux, uy = rng.uniform(-0.5, 20.5, n), rng.uniform(-0.5, 20.5, n)
    edge = rng.random(n) < 0.1  # exactly on or just beside the workspace boundary
    ux = np.where(edge & (rng.random(n) < 0.5), rng.choice([0.0, 20.0, -1e-3, 20.001], n), ux)
    near = rng.random(n) < 0.6
    return np.where(near, px, ux), np.where(near, py, uy), nx, ny


@pytest.mark.parametrize("pad_mode", sorted(PAD_MODES))
def test_point_robot_is_valid_and_steer_to_match_shapely(pad_mode):
    robot = PointRobot()
    counted = {"valid": np.zeros(2, int), "steer": np.zeros(2, int)}

    @SETTINGS
    @given(world_spec=world_st, pad=PAD_MODES[pad_mode], seed=seeds)
    def check(world_spec, pad, seed):
        rng = np.random.default_rng(seed)
        boxes, discs = _world_arrays(world_spec)
        world = World.create(BOUNDS, boxes, discs)
        n = N_CASES
        px, py, nx, ny = _near_world_points(rng, boxes, discs, pad, n)
        pts = f32(np.stack([px, py], 1))
        free = is_valid_batch(robot, world, jnp.asarray(pts), pad)
        geoms = shapely.points(pts.astype(np.float64))
        tol = band(np.max(np.abs(pts), 1) + 20.0 + pad)
        dists = _world_dists(geoms, boxes, discs, tol)
        excess = _bounds_excess(pts.astype(np.float64)[:, None], BOUNDS)
        counted["valid"] += assert_world_agrees(
            free, dists, excess, pad, tol, "PointRobot.is_valid", pts
        )
        # segments: tangent to a padded obstacle at the anchor, or between two random points
        length = 10 ** rng.uniform(-2, 1.3, n)
        u = rng.random(n)
        tx, ty = -ny, nx
        a = np.stack([px - u * length * tx, py - u * length * ty], 1)
        b = np.stack([px + (1 - u) * length * tx, py + (1 - u) * length * ty], 1)
        rnd = rng.random(n) < 0.4
        qx, qy, _, _ = _near_world_points(rng, boxes, discs, pad, n)
        b = np.where(rnd[:, None], np.stack([qx, qy], 1), b)
        b = np.where((rng.random(n) < 0.05)[:, None], a, b)  # zero-length
        a, b = f32(a), f32(b)
        ok = steer_to_batch(robot, world, jnp.asarray(a), jnp.asarray(b), pad)
        segs = np.stack([a, b], 1).astype(np.float64)
        tol = band(np.max(np.abs(segs), (1, 2)) + 20.0 + pad)
        dists = _world_dists(shapely.linestrings(segs), boxes, discs, tol)
        excess = _bounds_excess(segs, BOUNDS)
        counted["steer"] += assert_world_agrees(
            ok, dists, excess, pad, tol, "PointRobot.steer_to", np.concatenate([a, b], 1)
        )

    check()
    assert_enough(counted["valid"])
    assert_enough(counted["steer"])


RIGID_BODIES = [RigidBody(length=1.2, width=0.4), RigidBody(length=2.5, width=1.0)]


@pytest.mark.parametrize("pad_mode", sorted(PAD_MODES))
def test_rigid_body_is_valid_matches_shapely(pad_mode):
    counted = [np.zeros(2, int)]

    @SETTINGS
    @given(
        world_spec=world_st,
        pad=PAD_MODES[pad_mode],
        seed=seeds,
        robot=st.sampled_from(RIGID_BODIES),
    )
    def check(world_spec, pad, seed, robot):
        rng = np.random.default_rng(seed)
        boxes, discs = _world_arrays(world_spec)
        world = World.create(BOUNDS, boxes, discs)
        n = N_CASES
        px, py, nx, ny = _near_world_points(rng, boxes, discs, pad, n)
        hl, hw = 0.5 * robot.length, 0.5 * robot.width
        special = rng.random(n) < 0.4
        th = f32(np.where(special, rng.choice(SPECIAL_THETAS, n), rng.uniform(-np.pi, np.pi, n)))
        c, s = np.cos(th.astype(np.float64)), np.sin(th.astype(np.float64))
        h = hl * np.abs(nx * c + ny * s) + hw * np.abs(-nx * s + ny * c)
        q = f32(np.stack([px + h * nx, py + h * ny, th], 1))
        free = is_valid_batch(robot, world, jnp.asarray(q), pad)
        cases = np.concatenate(
            [q, np.full((n, 1), hl, np.float32), np.full((n, 1), hw, np.float32)], 1
        )
        corners = rect_polygons(cases)
        tol = band(np.max(np.abs(q[:, :2]), 1) + 20.0 + pad)
        dists = _world_dists(shapely.polygons(corners), boxes, discs, tol)
        excess = _bounds_excess(corners, BOUNDS)
        counted.append(assert_world_agrees(free, dists, excess, pad, tol, "RigidBody.is_valid", q))

    check()
    assert_enough(sum(counted))


# ---------------------------------------------------------------------------
# Arm: forward kinematics and link checks
# ---------------------------------------------------------------------------


def numpy_fk(robot: NLinkArm, q):
    """Brute-force float64 forward kinematics: joint positions ``(N, n + 1, 2)``."""
    q = np.asarray(q, np.float64)
    pts = np.zeros((q.shape[0], robot.dim + 1, 2))
    pts[:, 0] = robot.base
    phi = np.zeros(q.shape[0])
    for k, length in enumerate(robot.link_lengths):
        phi = phi + q[:, k]
        pts[:, k + 1, 0] = pts[:, k, 0] + length * np.cos(phi)
        pts[:, k + 1, 1] = pts[:, k, 1] + length * np.sin(phi)
    return pts


def _fk_tol(robot: NLinkArm):
    """float32 FK error bound: the absolute angle of link k sums k joints (|phi| <= k pi), so its
    rounding is <= k^2 pi eps32; cos/sin add ~eps32; each joint position sums the links'
    contributions (<= reach) and the base. Bound: eps32 * (reach * (n^2 pi + 2) + |base| + reach)."""
    n = robot.dim
    return EPS32 * (robot.reach * (n * n * np.pi + 3) + max(abs(v) for v in robot.base))


ARM_BOUNDS = np.array([[-10.0, 10.0], [-10.0, 10.0]])
ARMS = [NLinkArm((4.0, 3.5)), NLinkArm((2.0, 1.5, 2.5, 1.0, 1.8, 1.2), base=(1.0, -0.5))]


@jax.jit
def _arm_fk(link_lengths, base, q):
    """``jax.vmap(robot.forward_kinematics)(q)`` of the arm with these (validated) link lengths
    and base, passed as traced float32 values instead of constants baked into the program, so
    all arms with the same number of links share one compiled program. The method's code is
    unchanged; its float32 operations are the same (the values are float32 numbers either way)."""
    robot = object.__new__(NLinkArm)  # the fields only: the constructor's checks need numbers
    object.__setattr__(robot, "link_lengths", tuple(link_lengths))
    object.__setattr__(robot, "base", tuple(base))
    return jax.vmap(robot.forward_kinematics)(q)


@settings(max_examples=12, deadline=None, database=None, phases=PHASES)
@given(
    lengths=st.lists(st.floats(0.125, 5.0, width=32), min_size=1, max_size=6),
    base=st.tuples(st.floats(-5, 5, width=32), st.floats(-5, 5, width=32)),
    seed=seeds,
)
def test_arm_forward_kinematics_matches_numpy(lengths, base, seed):
    robot = NLinkArm(tuple(lengths), base=base)
    rng = np.random.default_rng(seed)
    q = f32(rng.uniform(-np.pi, np.pi, (2048, robot.dim)))
    got = np.asarray(_arm_fk(f32(robot.link_lengths), f32(robot.base), jnp.asarray(q)))
    np.testing.assert_allclose(got, numpy_fk(robot, q), rtol=0, atol=_fk_tol(robot))


arm_world_st = st.tuples(
    st.lists(
        st.tuples(st.floats(-9, 9, width=32), st.floats(-9, 9, width=32), half, half),
        min_size=3,
        max_size=3,
    ),
    st.lists(
        st.tuples(st.floats(-9, 9, width=32), st.floats(-9, 9, width=32), half),
        min_size=1,
        max_size=1,
    ),
)


@pytest.mark.parametrize("pad_mode", sorted(PAD_MODES))
def test_arm_is_valid_matches_shapely_links(pad_mode):
    counted = [np.zeros(2, int)]

    @settings(
        max_examples=3,
        deadline=None,
        database=None,
        phases=PHASES,
        suppress_health_check=list(HealthCheck),
    )
    @given(
        world_spec=arm_world_st, pad=PAD_MODES[pad_mode], seed=seeds, robot=st.sampled_from(ARMS)
    )
    def check(world_spec, pad, seed, robot):
        rng = np.random.default_rng(seed)
        boxes, discs = _world_arrays(world_spec)
        # an obstacle on the base would block every configuration: not an informative map
        base = shapely.points(np.array([robot.base] * (len(boxes) + len(discs))))
        assume((_world_dists(base[:1], boxes, discs, np.array([0.0])) > pad + 0.25).all())
        world = World.create(ARM_BOUNDS, boxes, discs)
        n = 2 * N_CASES
        q = rng.uniform(-np.pi, np.pi, (n, robot.dim))
        # some joints beyond the limits, some exactly at +-float32(pi) (inside the closed limits)
        pick = rng.random((n, robot.dim))
        sign = rng.choice([-1.0, 1.0], (n, robot.dim))
        q = np.where(pick < 0.02, sign * rng.uniform(3.2, 4.0, (n, robot.dim)), q)
        q = np.where(pick > 0.98, sign * np.float32(np.pi), q)
        q = f32(q)
        free = np.asarray(is_valid_batch(robot, world, jnp.asarray(q), pad))
        pts = numpy_fk(robot, q)
        segs = np.stack([pts[:, :-1], pts[:, 1:]], 2).reshape(-1, 2, 2)  # (N * n, 2, 2)
        tol = np.full(n, band(20.0 + pad) + _fk_tol(robot))
        d = _world_dists(shapely.linestrings(segs), boxes, discs, np.repeat(tol, robot.dim))
        dists = d.reshape(n, robot.dim, -1).min(axis=1)  # per obstacle, the closest link
        excess = _bounds_excess(pts, ARM_BOUNDS)
        # joint limits are an exact float32 comparison against float32(pi): no band needed
        joint_out = np.any(np.abs(q) > np.float32(np.pi), 1)
        assert not free[joint_out].any()
        excess = np.where(joint_out, 1.0, excess)
        counted.append(
            assert_world_agrees(
                free, dists, excess, pad, tol, f"{robot}.is_valid", q, min_counted=0.6
            )
        )

    check()
    assert_enough(sum(counted))


# ---------------------------------------------------------------------------
# Degenerate cases with exact (dyadic) arithmetic: touching is a collision
# ---------------------------------------------------------------------------

EXACT_BOX = np.array([10.0, 10.0, 2.0, 1.0], np.float32)  # x in [8, 12], y in [9, 11]
EXACT_DISC = np.array([10.0, 10.0, 2.0], np.float32)


def _exact_kernel(name, pad, cases, obstacle):
    """``_kernel(name, pad)`` on ``cases`` against ``obstacle``, as a list of bools. The cases
    are padded to N_CASES rows (copies of the first; a per-case kernel) so they run through
    the program of test_kernel_matches_shapely's shape (the same one at padding 0)."""
    cases = np.asarray(cases, np.float32)
    padded = np.concatenate([cases, np.repeat(cases[:1], N_CASES - len(cases), 0)])
    obst = np.tile(np.asarray(obstacle, np.float32), (N_CASES, 1))
    return np.asarray(_kernel(name, pad)(jnp.asarray(padded), jnp.asarray(obst)))[
        : len(cases)
    ].tolist()


@pytest.mark.parametrize("pad", [0.0, 0.5, 0.25])
def test_exact_touching_counts_as_collision(pad):
    p = pad
    # (segment, expected hit)
    cases = [
        ((8.0 - p, 9.5, 8.0 - p, 10.5), True),  # along the left edge, offset = padding
        ((9.0, 11.0 + p, 11.0, 11.0 + p), True),  # along the top edge (horizontal)
        ((5.0, 11.0 + p, 15.0, 11.0 + p), True),  # along the top edge, longer than the box
        ((12.0 + p, 0.0, 12.0 + p, 20.0), True),  # vertical, spanning the whole map
        ((12.0 + p + 2**-10, 0.0, 12.0 + p + 2**-10, 20.0), False),
        ((9.0, 11.0 + p + 2**-10, 11.0, 11.0 + p + 2**-10), False),
        ((10.0, 10.0, 10.0, 10.0), True),  # zero length, inside
        ((12.0 + p, 10.0, 12.0 + p, 10.0), True),  # zero length, on the padded edge
        ((12.0 + p + 2**-10, 10.0, 12.0 + p + 2**-10, 10.0), False),
        ((13.0 + p, 10.0, 12.0 + p, 10.0), True),  # ends on the padded edge
        ((9.0, 12.5 + p, 15.0, 12.5 + p), False),  # parallel, clear
        ((0.0, 0.0, 20.0, 20.0), True),  # through the box
        ((8.0, 9.0 - p, 8.0, 9.0 - p), True),  # zero length, below the corner by the padding
    ]
    got = _exact_kernel("segment_box", pad, [c for c, _ in cases], EXACT_BOX)
    assert got == [e for _, e in cases]
    # touching the disc exactly (padding grows its radius)
    r = 2.0 + p
    dcases = [
        ((8.0, 10.0 + r, 12.0, 10.0 + r), True),
        ((10.0 + r, 10.0, 15.0, 10.0), True),
        ((10.0 + r, 5.0, 10.0 + r, 15.0), True),
        ((10.0 + r + 2**-10, 5.0, 10.0 + r + 2**-10, 15.0), False),
        ((10.0, 10.0, 10.0, 10.0), True),
        ((10.0, 10.0 + r, 10.0, 10.0 + r), True),
    ]
    got = _exact_kernel("segment_disc", pad, [c for c, _ in dcases], EXACT_DISC)
    assert got == [e for _, e in dcases]
    # points
    pts = [[12.0 + p, 10.0], [10.0, 9.0 - p], [12.0 + p + 2**-10, 10.0]]
    assert _exact_kernel("point_box", pad, pts, EXACT_BOX) == [True, True, False]
    # rectangles at theta = 0: edge-to-edge contact with the box at exactly the padding
    rects = [
        [13.0 + p, 10.0, 0.0, 1.0, 0.5],  # left edge x = 12 + p
        [10.0, 11.5 + p, 0.0, 1.0, 0.5],  # bottom edge y = 11 + p
        [13.0 + p + 2**-10, 10.0, 0.0, 1.0, 0.5],
    ]
    assert _exact_kernel("rect_box", pad, rects, EXACT_BOX) == [True, True, False]


def test_workspace_bounds_are_closed():
    world = World.create(BOUNDS, [[10, 10, 1, 1]])
    pts = np.array([[0, 0], [20, 20], [0, 5], [20.0, 5], [-1e-3, 5], [5, 20.001]], np.float32)
    assert (
        np.asarray(is_valid_batch(PointRobot(), world, jnp.asarray(pts), 0.0)).tolist()
        == [True] * 4 + [False] * 2
    )
    a = np.array([[0, 0], [0, 20], [0, 0]], np.float32)
    b = np.array([[0, 20], [20, 20], [0, 20.001]], np.float32)
    assert np.asarray(
        steer_to_batch(PointRobot(), world, jnp.asarray(a), jnp.asarray(b), 0.0)
    ).tolist() == [True, True, False]


# ---------------------------------------------------------------------------
# NaN / inf: invalid and blocked, never an exception
# ---------------------------------------------------------------------------

BAD_VALUES = [np.nan, np.inf, -np.inf]


@pytest.mark.parametrize("pad", [0.0, 0.8])
@pytest.mark.parametrize(
    "robot", [PointRobot(), RigidBody(), NLinkArm((3.0, 3.0))], ids=lambda r: r.kind
)
def test_non_finite_states_are_invalid_and_blocked(robot, pad):
    world = World.create([[-10, 10], [-10, 10]], [[5, 5, 1, 1]], [[-5, -5, 1]])
    d = robot.dim
    good = np.full((1, d), 0.1, np.float32)
    if robot.kind == "point":
        good = np.array([[-8.0, 8.0]], np.float32)
    elif robot.kind == "rigid_body":
        good = np.array([[-8.0, 8.0, 0.3]], np.float32)
    bad = []
    for j in range(d):
        for v in BAD_VALUES:
            s = good.copy()
            s[0, j] = v
            bad.append(s[0])
    for v in (1e30, -3e38, 1e9):  # huge but finite first coordinate (x, or a joint angle)
        s = good.copy()
        s[0, 0] = v
        bad.append(s[0])
    bad = np.array(bad, np.float32)
    goods = np.repeat(good, len(bad), 0)  # the good state in every row: one shape, one program
    assert np.asarray(is_valid_batch(robot, world, jnp.asarray(goods), pad)).all()
    assert not np.asarray(is_valid_batch(robot, world, jnp.asarray(bad), pad)).any()
    assert np.asarray(
        steer_to_batch(robot, world, jnp.asarray(goods), jnp.asarray(goods), pad)
    ).all()
    assert not np.asarray(
        steer_to_batch(robot, world, jnp.asarray(goods), jnp.asarray(bad), pad)
    ).any()
    assert not np.asarray(
        steer_to_batch(robot, world, jnp.asarray(bad), jnp.asarray(goods), pad)
    ).any()
    assert not np.asarray(
        steer_to_batch(robot, world, jnp.asarray(bad), jnp.asarray(bad), pad)
    ).any()


@pytest.mark.parametrize("pad", [0.0, 0.8])
def test_non_finite_inputs_make_the_free_kernels_false(pad):
    world = World.create([[0, 20], [0, 20]], [[5, 5, 1, 1]], [[15, 15, 1]])
    vals = [np.nan, np.inf, -np.inf]
    pts = np.array([[v, 10.0] for v in vals] + [[10.0, v] for v in vals], np.float32)
    assert not np.asarray(
        jax.jit(jax.vmap(lambda p: G.point_free(p, world, pad)))(jnp.asarray(pts))
    ).any()
    good = jnp.asarray(np.tile(np.array([10.0, 10.0], np.float32), (len(pts), 1)))
    seg = jax.jit(jax.vmap(lambda a, b: G.segment_free(a, b, world, pad)))
    assert not np.asarray(seg(jnp.asarray(pts), good)).any()
    assert not np.asarray(seg(good, jnp.asarray(pts))).any()
    seg_nb = jax.jit(jax.vmap(lambda a, b: G.segment_free(a, b, world, pad, check_bounds=False)))
    assert not np.asarray(seg_nb(jnp.asarray(pts), good)).any()
    poses = np.array([[v, 10.0, 0.0] for v in vals] + [[10.0, 10.0, v] for v in vals], np.float32)
    assert not np.asarray(
        jax.jit(jax.vmap(lambda q: G.rect_free(q, 0.6, 0.2, world, pad)))(jnp.asarray(poses))
    ).any()


# ---------------------------------------------------------------------------
# Rasterisation against the same oracle (cell centres)
# ---------------------------------------------------------------------------


@settings(max_examples=4, deadline=None, database=None, phases=PHASES)
@given(world_spec=world_st, pad=st.one_of(st.just(0.0), random_padding))
def test_rasterize_matches_cell_centre_oracle(world_spec, pad):
    boxes, discs = _world_arrays(world_spec)
    world = World.create(BOUNDS, boxes, discs)
    res = 0.25
    occ = G.rasterize(world, res, pad)
    assert occ.shape == (80, 80)
    centres = G.cell_centers(world, res, np.stack(np.indices(occ.shape), -1).reshape(-1, 2))
    tol = np.full(len(centres), band(25.0))
    dists = _world_dists(shapely.points(centres), boxes, discs, tol)
    excess = _bounds_excess(centres[:, None], BOUNDS)
    assert_world_agrees(
        ~occ.ravel(), dists, excess, pad, tol, "rasterize", centres, min_counted=0.9
    )
