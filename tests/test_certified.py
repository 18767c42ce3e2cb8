"""The certified motion check (:mod:`ntq_jax.robots.certified`) against independent oracles.

What is proven here (shapely >= 2 in float64 on the very same float32 inputs):

1. The distance kernels of :mod:`ntq_jax.geometry` (``segment_box_dist2``,
   ``segment_disc_dist``, ``rect_box_dist2``, ``rect_disc_dist``) and the robots'
   ``clearance`` agree with shapely's exact distances on random cases, most of them
   near-touching or intersecting (distance 0).
2. ``clearance > 0`` exactly when ``is_valid`` (up to a tiny float32 band).
3. Zero false frees: every motion the certified check calls free is clear at every
   state of a dense, independent shapely check 100x finer than the robot's
   ``resolution`` -- and, stronger, clear by a quarter of the check's ``margin``
   (the module promises that motions passing closer than about ``margin / 2`` are
   blocked).
4. Deterministic maps where the discretised check misses a thin obstacle and the
   certified one does not.
5. Certified free => endpoints valid and discretised free; invalid / non-finite /
   masked-out motions are blocked; a zero-length motion of a clear state is free.
6. The point robot: certified == discretised (both exact).

Tolerance of the distance comparisons. The kernels compute in float32 on float32
inputs; the oracle computes in float64 on the same (float32-rounded) inputs, so they
can only differ by the kernels' own rounding: each float32 operation on coordinates
of magnitude ``scale`` rounds by up to ``eps32 * scale / 2`` (eps32 = 1.19e-7, i.e.
1.2e-6 at scale 20), and a distance chains ~10 of them (differences, a projection, a
square root whose input cancels near contact; the rectangle's corners go through the
float32 ``sincos``, ~1e-7 absolute). A near-touching pair that the float32 closed-set
test calls intersecting gets distance 0 where the true distance is of that rounding
order, and vice versa. Hence ``tol = 1e-5 * max(1, scale)`` (scale = the case's
largest coordinate magnitude, ~20): about 80 eps32 * scale, comfortably above the
rounding (measured worst: see ``test_distance_kernels_match_shapely``), yet 10^3-10^4
times smaller than any obstacle size, padding or offset drawn, so a wrong vertex
choice or a wrong sign cannot hide in it. For the arm the float32 forward-kinematics
bound (:func:`_fk_tol`, summed joint angles) is added.

Discs in the oracle are exact: the distance to a closed disc is ``max(|p - c| - r, 0)``
(``shapely.distance`` to the centre point minus the radius). ``Point.buffer`` would be a
polygon whose chords lie up to ``r (1 - cos(pi / 64)) ~ 1e-3 r`` inside the circle,
far coarser than the tolerance.
"""

from __future__ import annotations

import functools
import math
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from test_geometry_oracle import tangent_segments

from ntq_jax import geometry as G
from ntq_jax import make_env
from ntq_jax.batching import map_chunks
from ntq_jax.envs import Env
from ntq_jax.geometry import World
from ntq_jax.presets import PRESETS
from ntq_jax.robots import NLinkArm, RigidBody
from ntq_jax.robots.batch import CERTIFIED_CHUNK, _steer_masked, steer_to_pairs, valid_states
from ntq_jax.robots.certified import CERT_MARGIN

EPS32 = float(np.finfo(np.float32).eps)
F64 = np.float64
# No shrinking: every failure message lists the failing cases verbatim, and shrinking
# would recompile / rerun the expensive checks for every candidate.
PHASES = (Phase.explicit, Phase.reuse, Phase.generate)
seeds = st.integers(0, 2**32 - 1)


def f32(a):
    return np.asarray(a, np.float32)


def kernel_tol(scale):
    """Absolute tolerance of a distance comparison (see the module docstring)."""
    return 1e-5 * np.maximum(scale, 1.0)


def _fk_tol(robot: NLinkArm) -> float:
    """float32 forward-kinematics error bound (as in test_geometry_oracle): link k's absolute
    angle sums k joints, so its rounding is <= k^2 pi eps32, times the reach."""
    n = robot.dim
    return EPS32 * (robot.reach * (n * n * np.pi + 3) + max(abs(v) for v in robot.base))


def wrap64(a):
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


def _logu(rng, lo, hi, n):
    return np.exp(rng.uniform(math.log(lo), math.log(hi), n))


# ---------------------------------------------------------------------------
# Oracle geometry (float64, shapely)
# ---------------------------------------------------------------------------


def rect_corners64(q, hl, hw):
    """Corners ``(N, 4, 2)`` of rectangles at poses ``q`` ``(N, 3)`` (float64)."""
    q = np.asarray(q, F64)
    hl = np.broadcast_to(np.asarray(hl, F64), q.shape[:1])
    hw = np.broadcast_to(np.asarray(hw, F64), q.shape[:1])
    co, si = np.cos(q[:, 2]), np.sin(q[:, 2])
    pts = [
        np.stack([q[:, 0] + a * hl * co - b * hw * si, q[:, 1] + a * hl * si + b * hw * co], 1)
        for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1))
    ]
    return np.stack(pts, 1)


def numpy_fk(robot: NLinkArm, q):
    """Float64 forward kinematics: joint positions ``(N, n + 1, 2)``."""
    q = np.asarray(q, F64)
    pts = np.zeros((q.shape[0], robot.dim + 1, 2))
    pts[:, 0] = robot.base
    phi = np.zeros(q.shape[0])
    for k, length in enumerate(robot.link_lengths):
        phi = phi + q[:, k]
        pts[:, k + 1, 0] = pts[:, k, 0] + length * np.cos(phi)
        pts[:, k + 1, 1] = pts[:, k, 1] + length * np.sin(phi)
    return pts


def box_polys(boxes):
    b = np.asarray(boxes, F64).reshape(-1, 4)
    return shapely.box(b[:, 0] - b[:, 2], b[:, 1] - b[:, 3], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3])


def oracle_obstacle_dists(geoms, world: World):
    """``(N, B + C)`` exact float64 distances of each geometry to each obstacle (0 when they meet)."""
    boxes, discs = np.asarray(world.boxes, F64), np.asarray(world.discs, F64)
    cols = [shapely.distance(geoms, p) for p in box_polys(boxes)]
    cols += [
        np.maximum(shapely.distance(geoms, shapely.Point(d[0], d[1])) - d[2], 0.0) for d in discs
    ]
    return np.stack(cols, 1)


def wall_dist64(pts, bounds):
    """Signed distance of points ``(..., 2)`` to the workspace boundary (> 0 inside)."""
    b = np.asarray(bounds, F64)
    return np.minimum(
        np.minimum(pts[..., 0] - b[0, 0], b[0, 1] - pts[..., 0]),
        np.minimum(pts[..., 1] - b[1, 0], b[1, 1] - pts[..., 1]),
    )


class Obstacles:
    """The world's obstacles as prepared shapely geometries, for the dense validity check."""

    def __init__(self, world: World):
        boxes, discs = np.asarray(world.boxes, F64), np.asarray(world.discs, F64)
        self.geoms = list(box_polys(boxes)) + [shapely.Point(d[0], d[1]) for d in discs]
        self.extra = [0.0] * len(boxes) + [float(d[2]) for d in discs]  # disc = centre + radius
        for g in self.geoms:
            shapely.prepare(g)
        self.bounds = np.asarray(world.bounds, F64)

    def too_close(self, geoms, dist: float):
        """``(S,)`` bool: the geometry is within ``dist`` of an obstacle (distance <= dist; at 0,
        intersecting or touching)."""
        bad = np.zeros(len(geoms), bool)
        for g, r in zip(self.geoms, self.extra):
            bad |= shapely.dwithin(geoms, g, r + dist)
        return bad


# ---------------------------------------------------------------------------
# 1. Distance kernels against shapely
# ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _dist_kernel(name: str):
    fns = {
        "segment_box": lambda c, o: jnp.sqrt(G.segment_box_dist2(c[0], c[1], c[2], c[3], o)),
        "segment_disc": lambda c, o: G.segment_disc_dist(c[0], c[1], c[2], c[3], o),
        "rect_box": lambda c, o: jnp.sqrt(G.rect_box_dist2(c[0], c[1], c[2], c[3], c[4], o)),
        "rect_disc": lambda c, o: G.rect_disc_dist(c[0], c[1], c[2], c[3], c[4], o),
    }
    return jax.jit(jax.vmap(fns[name]))


def rand_obstacles(rng, kind, n):
    if kind == "box":
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
    return f32(np.stack([rng.uniform(0, 20, n), rng.uniform(0, 20, n), _logu(rng, 0.05, 4, n)], 1))


def signed_offsets(rng, n):
    """Offsets from contact: +-10^U(-6, 0.5), a third of them negative (penetrating: distance 0)."""
    mag = 10 ** rng.uniform(-6.0, 0.5, n)
    return np.where(rng.random(n) < 1 / 3, -mag, mag)


def anchor(rng, obst, kind, s):
    """A point at signed offset ``s`` from a random edge / corner of each obstacle (its outward
    unit normal there), so for ``s >= 0`` the point's distance to the obstacle is ``s``."""
    o = obst.astype(F64)
    n = len(o)
    if kind == "disc":
        a = rng.uniform(0, 2 * np.pi, n)
        nx, ny = np.cos(a), np.sin(a)
        return o[:, 0] + (o[:, 2] + s) * nx, o[:, 1] + (o[:, 2] + s) * ny, nx, ny
    cx, cy, hw, hh = o.T
    corner = rng.random(n) < 0.5
    sx, sy = rng.choice([-1.0, 1.0], n), rng.choice([-1.0, 1.0], n)
    vert = rng.random(n) < 0.5
    t = rng.uniform(-1, 1, n)
    a = rng.uniform(0, np.pi / 2, n)
    px = np.where(corner, cx + sx * hw, np.where(vert, cx + sx * hw, cx + t * hw))
    py = np.where(corner, cy + sy * hh, np.where(vert, cy + t * hh, cy + sy * hh))
    nx = np.where(corner, sx * np.cos(a), np.where(vert, sx, 0.0))
    ny = np.where(corner, sy * np.sin(a), np.where(vert, 0.0, sy))
    return px + s * nx, py + s * ny, nx, ny


def region(rng, obst, kind):
    """Uniform points in a box around each obstacle (2 units of margin)."""
    o = obst.astype(F64)
    ex, ey = (o[:, 2] + 2.0, o[:, 3] + 2.0) if kind == "box" else (o[:, 2] + 2.0, o[:, 2] + 2.0)
    return rng.uniform(o[:, 0] - ex, o[:, 0] + ex), rng.uniform(o[:, 1] - ey, o[:, 1] + ey)


def segment_cases(rng, obst, kind):
    """``(n, 4)`` segments: tangent-ish to the obstacle at a signed offset (closest point inside
    the segment or at an end, slightly tilted), random near it, and zero-length."""
    n = len(obst)
    px, py, nx, ny = anchor(rng, obst, kind, signed_offsets(rng, n))
    tangent = tangent_segments(rng, px, py, nx, ny)
    x0, y0 = region(rng, obst, kind)
    x1, y1 = region(rng, obst, kind)
    rand = np.stack([x0, y0, x1, y1], 1)
    zero = np.stack([px, py, px, py], 1)
    cat = rng.choice(3, n, p=[0.65, 0.25, 0.1])
    return f32(np.select([cat[:, None] == 0, cat[:, None] == 1], [tangent, rand], zero))


SPECIAL_THETAS = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2, -np.pi], np.float32)


def rect_cases(rng, obst, kind):
    """``(n, 5)`` rectangles ``(x, y, theta, half_l, half_w)`` touching the obstacle from outside
    at a signed offset (axis-aligned thetas included: edge-to-edge contacts), and random near it."""
    n = len(obst)
    hl, hw = _logu(rng, 0.05, 2.0, n), _logu(rng, 0.05, 2.0, n)
    th = f32(
        np.where(rng.random(n) < 0.4, rng.choice(SPECIAL_THETAS, n), rng.uniform(-np.pi, np.pi, n))
    ).astype(F64)
    px, py, nx, ny = anchor(rng, obst, kind, signed_offsets(rng, n))
    x, y = support_placement(px, py, nx, ny, th, hl, hw)
    rx, ry = region(rng, obst, kind)
    near = rng.random(n) < 0.75
    return f32(np.stack([np.where(near, x, rx), np.where(near, y, ry), th, hl, hw], 1))


def support_placement(px, py, nx, ny, th, hl, hw):
    """The centre that puts the rectangle's extreme point in direction ``-n`` (a corner, or an
    edge's midpoint when the edge is perpendicular to ``n``) at ``p``: the rectangle then lies
    beyond the line through ``p`` perpendicular to ``n``, touching it at ``p``."""
    c, s = np.cos(th), np.sin(th)
    a = -np.sign(nx * c + ny * s)  # along the length
    b = -np.sign(-nx * s + ny * c)  # along the width
    return px - (a * hl * c - b * hw * s), py - (a * hl * s + b * hw * c)


def _distance_case(shape: str, kind: str, seed: int, n: int):
    """Kernel and oracle distances, and the tolerance, of ``n`` random cases."""
    rng = np.random.default_rng(seed)
    obst = rand_obstacles(rng, kind, n)
    if shape == "segment":
        cases = segment_cases(rng, obst, kind)
        geoms = shapely.linestrings(cases.astype(F64).reshape(-1, 2, 2))
    else:
        cases = rect_cases(rng, obst, kind)
        geoms = shapely.polygons(rect_corners64(cases[:, :3], cases[:, 3], cases[:, 4]))
    got = np.asarray(_dist_kernel(f"{shape}_{kind}")(jnp.asarray(cases), jnp.asarray(obst)), F64)
    o = obst.astype(F64)
    if kind == "box":
        want = shapely.distance(geoms, box_polys(o))
    else:
        want = np.maximum(shapely.distance(geoms, shapely.points(o[:, :2])) - o[:, 2], 0.0)
    scale = np.max(np.abs(np.concatenate([cases, obst], 1)), axis=1)
    return cases, obst, got, want, kernel_tol(scale)


@pytest.mark.parametrize(
    "shape, kind", [(s, k) for s in ("segment", "rect") for k in ("box", "disc")]
)
def test_distance_kernels_match_shapely(shape, kind):
    """The one-item distance kernels, vmapped, agree with shapely within ``kernel_tol`` on random
    near-touching, intersecting and far cases (measured worst error 2.2e-6 at scale ~20, i.e.
    < 1 eps32 * scale: the tolerance has a ~60x margin)."""
    stats = []

    @settings(max_examples=4, deadline=None, database=None, phases=PHASES)
    @given(seed=seeds)
    def check(seed):
        cases, obst, got, want, tol = _distance_case(shape, kind, seed, 4096)
        err = np.abs(got - want)
        bad = np.flatnonzero(~(err <= tol))  # NaN counts as bad
        if bad.size:
            rows = "\n".join(
                f"  case={cases[i].tolist()} obstacle={obst[i].tolist()} "
                f"kernel={got[i]!r} shapely={want[i]!r}"
                for i in bad[:5]
            )
            pytest.fail(
                f"{shape}_{kind} distance: {bad.size} cases off by more than the tolerance "
                f"(seed {seed}), e.g.\n{rows}"
            )
        stats.append(
            ((want == 0).sum(), ((want > 0) & (want < 1e-3)).sum(), (want > 1e-3).sum(), len(want))
        )

    check()
    zero, near, far, total = np.sum(stats, 0)
    # the mix: intersecting (distance 0), near-touching (< 1e-3) and clearly apart
    assert zero > 0.1 * total and near > 0.05 * total and far > 0.2 * total, (
        zero,
        near,
        far,
        total,
    )


# ---------------------------------------------------------------------------
# 1b / 2. Robot clearance against shapely, and clearance > 0 iff is_valid
# ---------------------------------------------------------------------------

# The test-side clearance program: one per robot and map shape, shared by every test, padding and
# batch size here. The padding is traced (without a broad-phase index it only enters the
# arithmetic, bit-identical to the static one: the decision made on it, ``index_covers``, needs an
# index, which no map here has), and the states run in chunks of one fixed shape.
CLEARANCE_CHUNK = 4096


@functools.lru_cache(maxsize=None)
def _clearance_fn(robot):
    return jax.jit(jax.vmap(robot.clearance, in_axes=(0, None, None)))


def clearance(robot, world, q, padding):
    assert world.index is None, "a broad-phase index makes the padding static: trace it per padding"
    fn, pad = _clearance_fn(robot), jnp.float32(padding)
    q = f32(q).reshape(-1, robot.dim)
    return map_chunks(lambda x: fn(x, world, pad), q, chunk=CLEARANCE_CHUNK).astype(F64)


def oracle_rigid_clearance(robot: RigidBody, world: World, q, padding):
    corners = rect_corners64(q, 0.5 * robot.length, 0.5 * robot.width)
    obst = oracle_obstacle_dists(shapely.polygons(corners), world).min(1) - padding
    return np.minimum(obst, wall_dist64(corners, world.bounds).min(1))


def oracle_arm_clearance(robot: NLinkArm, world: World, q, padding):
    pts = numpy_fk(robot, q)
    n = robot.dim
    segs = np.stack([pts[:, :-1], pts[:, 1:]], 2).reshape(-1, 2, 2)
    d = oracle_obstacle_dists(shapely.linestrings(segs), world).reshape(len(q), n, -1).min((1, 2))
    return np.minimum(d - padding, wall_dist64(pts, world.bounds).min(1))


CLEAR_WORLD_BOUNDS = [[0.0, 20.0], [0.0, 20.0]]
ARM_BOUNDS = [[-10.0, 10.0], [-10.0, 10.0]]
RIGIDS = [RigidBody(length=1.2, width=0.4), RigidBody(length=2.5, width=1.0)]
ARMS = [NLinkArm((4.0, 3.5)), NLinkArm((2.0, 1.5, 2.5, 1.0, 1.8, 1.2), base=(1.0, -0.5))]
pad_st = st.one_of(st.just(0.0), st.sampled_from([0.4, 0.8]), st.floats(0.125, 1.5, width=32))


def random_world(rng, bounds, nb=3, nd=2):
    b = np.asarray(bounds, F64)
    lo, hi = b[:, 0] + 1.0, b[:, 1] - 1.0
    boxes = np.stack(
        [
            rng.uniform(lo[0], hi[0], nb),
            rng.uniform(lo[1], hi[1], nb),
            _logu(rng, 0.1, 3.0, nb),
            _logu(rng, 0.1, 3.0, nb),
        ],
        1,
    )
    discs = np.stack(
        [rng.uniform(lo[0], hi[0], nd), rng.uniform(lo[1], hi[1], nd), _logu(rng, 0.1, 2.5, nd)], 1
    )
    return World.create(bounds, f32(boxes), f32(discs))


def rigid_states_near(rng, robot: RigidBody, world: World, pad, n):
    """Poses touching a random obstacle's padded boundary at a signed offset, near a wall, and
    uniform."""
    boxes, discs = np.asarray(world.boxes), np.asarray(world.discs)
    k = rng.integers(0, len(boxes) + len(discs), n)
    isbox = k < len(boxes)
    s = pad + signed_offsets(rng, n)
    bx, by, bnx, bny = anchor(rng, boxes[np.minimum(k, len(boxes) - 1)], "box", s)
    dx, dy, dnx, dny = anchor(rng, discs[np.clip(k - len(boxes), 0, len(discs) - 1)], "disc", s)
    px, py = np.where(isbox, bx, dx), np.where(isbox, by, dy)
    nx, ny = np.where(isbox, bnx, dnx), np.where(isbox, bny, dny)
    hl, hw = 0.5 * robot.length, 0.5 * robot.width
    th = f32(
        np.where(rng.random(n) < 0.3, rng.choice(SPECIAL_THETAS, n), rng.uniform(-np.pi, np.pi, n))
    ).astype(F64)
    c, si = np.cos(th), np.sin(th)
    x, y = support_placement(px, py, nx, ny, th, hl, hw)
    b = np.asarray(world.bounds, F64)
    ux, uy = rng.uniform(b[0, 0], b[0, 1], n), rng.uniform(b[1, 0], b[1, 1], n)
    # near a wall: the extreme corner at a signed offset from x = xmin
    wall = rng.random(n) < 0.1
    ux = np.where(wall, b[0, 0] + hl * np.abs(c) + hw * np.abs(si) + signed_offsets(rng, n), ux)
    near = rng.random(n) < 0.7
    return f32(np.stack([np.where(near, x, ux), np.where(near, y, uy), th], 1))


def arm_states(rng, robot: NLinkArm, n):
    """Uniform joint angles, a few beyond the limits."""
    q = rng.uniform(-np.pi, np.pi, (n, robot.dim))
    out = rng.random(n) < 0.02
    q[out, 0] = rng.choice([-1, 1], out.sum()) * rng.uniform(3.2, 4.0, out.sum())
    return f32(q)


@pytest.mark.parametrize("robot", RIGIDS + ARMS, ids=lambda r: f"{r.kind}{r.dim}")
def test_robot_clearance_matches_shapely(robot):
    """``robot.clearance(q, world, padding)`` = min over obstacles of (shapely distance - padding),
    and the boundary term (footprint corners / arm joints to the workspace boundary)."""
    arm = robot.kind == "nlink"
    stats = []

    @settings(max_examples=4, deadline=None, database=None, phases=PHASES)
    @given(seed=seeds, pad=pad_st)
    def check(seed, pad):
        rng = np.random.default_rng(seed)
        world = random_world(rng, ARM_BOUNDS if arm else CLEAR_WORLD_BOUNDS)
        if arm:
            q = arm_states(rng, robot, 4096)
            out = np.any(np.abs(q) > np.float32(np.pi), 1)
            want = np.where(out, -1.0, oracle_arm_clearance(robot, world, q, pad))
            tol = kernel_tol(20.0) + _fk_tol(robot)
        else:
            q = rigid_states_near(rng, robot, world, pad, 4096)
            want = oracle_rigid_clearance(robot, world, q, pad)
            tol = kernel_tol(np.max(np.abs(q[:, :2]), 1) + robot.length)
        got = clearance(robot, world, q, pad)
        bad = np.flatnonzero(~(np.abs(got - want) <= tol))
        if bad.size:
            rows = "\n".join(
                f"  q={q[i].tolist()} kernel={got[i]!r} shapely={want[i]!r}" for i in bad[:5]
            )
            pytest.fail(
                f"{robot} clearance (padding {pad!r}, seed {seed}, world boxes="
                f"{np.asarray(world.boxes).tolist()} discs={np.asarray(world.discs).tolist()}): "
                f"{bad.size} cases off, e.g.\n{rows}"
            )
        stats.append(((np.abs(want) < 1e-2).sum(), (want > 0).sum(), len(want)))

    check()
    near, pos, total = np.sum(stats, 0)
    if not arm:  # the rigid poses are built near contact; the arm's are uniform
        assert near > 0.2 * total, (near, total)
    # non-vacuous: both clear and colliding states among the checked ones, at least 1 % of
    # each (over 4 x 4096 states: 164 or more). The worlds are random: sparse draws gave 93 %
    # and 96 % clear arm states, so a tighter bound fails on valid runs.
    assert 0.01 * total < pos < 0.99 * total, (pos, total)


def boundary_states(rng, env: Env, pad: float, n: int):
    """States near the boundary of the valid set: bisect (on ``is_valid``) between a valid and an
    invalid uniform state, then step off along a random direction by 10^U(-4.5, -0.5) (1 in 20 by
    10^U(-7, -5): within float32 rounding of the boundary)."""
    robot, world = env.robot, env.world
    lo, hi = (np.asarray(v, F64) for v in robot.config_bounds(world))
    q = f32(rng.uniform(lo, hi, (4 * n, robot.dim)))
    v = valid_states(robot, world, q, pad)  # (CHECK_CHUNK rows per call: one program per padding)
    assert v.any() and (~v).any()
    a = q[rng.choice(np.flatnonzero(v), n)].astype(F64)
    b = q[rng.choice(np.flatnonzero(~v), n)].astype(F64)
    for _ in range(30):
        m = 0.5 * (a + b)
        vm = valid_states(robot, world, f32(m), pad)
        a = np.where(vm[:, None], m, a)
        b = np.where(vm[:, None], b, m)
    u = rng.normal(size=a.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    step = np.where(
        rng.random((n, 1)) < 0.05,
        10 ** rng.uniform(-7, -5, (n, 1)),
        10 ** rng.uniform(-4.5, -0.5, (n, 1)),
    )
    return f32(a + u * step)


BAND = 1e-5


def oracle_sure(robot, world: World, q, pad: float, band: float):
    """``(sure_valid, sure_invalid)`` by shapely: valid with ``band`` to spare (every obstacle
    farther than ``pad + band``, corners / joints ``band`` inside the workspace, joints within the
    limits), or invalid beyond ``band`` (an obstacle nearer than ``pad - band``, or -- which also
    covers padding 0 -- the footprint / a link meeting an obstacle shrunk by ``band``; a corner /
    joint ``band`` outside the workspace; a joint beyond the limits)."""
    boxes, discs = np.asarray(world.boxes, F64), np.asarray(world.discs, F64)
    if robot.kind == "rigid_body":
        pts = rect_corners64(q, 0.5 * robot.length, 0.5 * robot.width)
        geoms, per = shapely.polygons(pts), 1
        out = np.zeros(len(q), bool)
    else:
        pts = numpy_fk(robot, q)
        geoms = shapely.linestrings(np.stack([pts[:, :-1], pts[:, 1:]], 2).reshape(-1, 2, 2))
        per = robot.dim
        out = np.any(np.abs(q) > np.float32(np.pi), 1)
    d = oracle_obstacle_dists(geoms, world).reshape(len(q), per, -1).min(1)
    shrunk = [shapely.box(*(b[:2] - b[2:] + band), *(b[:2] + b[2:] - band)) for b in boxes]
    deep = [shapely.intersects(geoms, g) for g in shrunk]
    deep += [shapely.distance(geoms, shapely.Point(c[0], c[1])) < c[2] - band for c in discs]
    deep = np.stack(deep, 1).reshape(len(q), per, -1).any((1, 2))
    wall = wall_dist64(pts, world.bounds).min(1)
    sure_valid = (d > pad + band).all(1) & (wall > band) & ~out
    sure_invalid = (d < pad - band).any(1) | deep | (wall < -band) | out
    return sure_valid, sure_invalid


@pytest.mark.parametrize("name", ["rigid/0", "rigid/1", "rigid/3", "nlink/2", "nlink/4", "nlink/6"])
def test_clearance_positive_iff_valid(name):
    """``clearance > 0`` exactly when ``is_valid``, on states near the valid set's boundary, at
    padding 0 and at the preset's padding.

    The two kernels use different float32 arithmetic (separating axes and squared-distance
    comparisons against ``sqrt(d2) - padding``; the closed ``in_bounds`` against ``> 0`` on the
    wall distance), so they may disagree on states within rounding of the boundary: allowed only
    where ``|clearance| < BAND = 1e-5`` and shapely cannot tell either (the state is neither valid
    nor invalid with ``BAND`` to spare, see :func:`oracle_sure`). Such states must be rare in the
    sample, and so must disagreements.
    """
    env = make_env(name)
    robot = env.robot
    band = BAND + (_fk_tol(robot) if robot.kind == "nlink" else 0.0)
    for pad in (0.0, env.padding):
        rng = np.random.default_rng(zlib.crc32(f"{name} {pad}".encode()))
        q = boundary_states(rng, env, pad, 4096)
        c = clearance(robot, env.world, q, pad)
        valid = valid_states(robot, env.world, q, pad)
        sure_valid, sure_invalid = oracle_sure(robot, env.world, q, pad, band)
        assert not (sure_valid & sure_invalid).any()
        in_band = ~sure_valid & ~sure_invalid
        off = (c > 0) != valid
        bad = np.flatnonzero(off & ~((np.abs(c) < BAND) & in_band))
        assert not bad.size, (
            f"{name} padding {pad}: clearance sign disagrees with is_valid outside "
            f"the band: {[(q[i].tolist(), c[i], valid[i]) for i in bad[:5]]}"
        )
        # and both agree with shapely outside the band
        assert (valid[sure_valid]).all() and not valid[sure_invalid].any()
        # (the arm's band adds the float32 forward-kinematics bound, up to 1.4e-4 for six links)
        assert in_band.mean() < (0.15 if robot.kind == "rigid_body" else 0.25), (
            "too many states within the band",
            in_band.mean(),
        )
        assert off.mean() < 0.01, (name, pad, off.mean())
        assert (np.abs(c) < 1e-2).mean() > 0.3, "states not near the boundary"
        assert 0.2 < valid.mean() < 0.8, valid.mean()


# ---------------------------------------------------------------------------
# 3. Zero false frees (dense shapely check)
# ---------------------------------------------------------------------------

N_MOTIONS = 256  # motions per example
N_UNIFORM = 48  # of them, uniform valid pairs (truncated to a bounded length)
NEAR_CLEARANCE = 0.25  # starts "near obstacles": 0 < clearance < this
DENSE = 100  # the dense check's step: the robot's resolution / DENSE
DELTA = CERT_MARGIN / 4  # certified free must keep this far (the module promises ~margin / 2)

# rigid/0's blocks plus two discs (the presets have boxes only, and every map with other obstacle
# counts costs another compilation), rigid/0's robot and padding (0.4)
RIGID_DISCS = dict(
    PRESETS["rigid/0"], name="rigid/0+discs", discs=[[7.5, 7.5, 0.6], [1.5, 6.0, 0.4]]
)
# (environment, padding): both paddings for the rigid body and the 6-link arm, one each for the
# 2- and 4-link arms (every compiled (robot, padding) costs seconds; the suite has a budget)
PROP3_CASES = [
    ("rigid/0+discs", "zero"),
    ("rigid/0+discs", "data"),
    ("nlink/2", "zero"),
    ("nlink/4", "data"),
    ("nlink/6", "zero"),
    ("nlink/6", "data"),
]


@functools.lru_cache(maxsize=None)
def get_env(name: str) -> Env:
    return Env.from_json(RIGID_DISCS) if name == RIGID_DISCS["name"] else make_env(name)


def motion_length(robot, a, b):
    """The robot's metric (float64): SE(2) ``|dp| + w |dtheta|`` (shortest arc) or Euclidean."""
    a, b = a.astype(F64), b.astype(F64)
    if robot.kind == "rigid_body":
        return np.hypot(*(b[:, :2] - a[:, :2]).T) + robot.angle_weight * np.abs(
            wrap64(b[:, 2] - a[:, 2])
        )
    return np.linalg.norm(b - a, axis=1)


def sample_motions(rng, env: Env, pad: float):
    """``(a, b, near)``: ``N_MOTIONS`` motions, float32. Starts are valid; the first
    ``N_MOTIONS - N_UNIFORM`` start near obstacles (0 < clearance < NEAR_CLEARANCE) and move by a
    small-to-moderate random displacement (1 in 5 a pure translation / single-joint motion, 1 in 5
    a pure rotation for the rigid body); the rest are uniform valid pairs, shortened to a bounded
    length (their end may then be invalid)."""
    robot, world = env.robot, env.world
    rigid = robot.kind == "rigid_body"
    lo, hi = (np.asarray(v, F64) for v in robot.config_bounds(world))
    cand = f32(rng.uniform(lo, hi, (8192, robot.dim)))
    c = clearance(robot, world, cand, pad)
    valid = np.flatnonzero(c > 0)
    near_ok = np.flatnonzero((c > 0) & (c < NEAR_CLEARANCE))
    n_near = N_MOTIONS - N_UNIFORM
    if (
        near_ok.size < n_near
    ):  # few near states on this map: the valid ones with the least clearance
        near_ok = valid[np.argsort(c[valid])[:n_near]]
    a_near = cand[rng.choice(near_ok, n_near)].astype(F64)
    # displacement of metric length L, log-uniform
    L = _logu(rng, 1e-3, 1.0 if rigid else 0.6, n_near)
    u = rng.normal(size=a_near.shape)
    kind = rng.random(n_near)
    if rigid:
        u[kind < 0.2, 2] = 0.0  # pure translation
        u[kind > 0.8, :2] = 0.0  # pure rotation
        m = np.hypot(u[:, 0], u[:, 1]) + robot.angle_weight * np.abs(u[:, 2])
    else:
        single = rng.integers(0, robot.dim, n_near)
        u = np.where((kind < 0.2)[:, None], np.eye(robot.dim)[single] * u, u)
        m = np.linalg.norm(u, axis=1)
    b_near = a_near + u * (L / m)[:, None]
    # uniform valid pairs, shortened to a metric length <= cap
    a_u = cand[rng.choice(valid, N_UNIFORM)].astype(F64)
    b_u = cand[rng.choice(valid, N_UNIFORM)].astype(F64)
    d = b_u - a_u
    if rigid:
        d[:, 2] = wrap64(d[:, 2])
        d[np.abs(d[:, 2]) > np.pi - 0.01, 2] *= 0.5  # no near-antipodal turns (see below)
    lu = motion_length(robot, a_u, a_u + d)
    b_u = a_u + d * np.minimum(1.0, (3.0 if rigid else 0.5) / lu)[:, None]
    a, b = f32(np.concatenate([a_near, a_u])), np.concatenate([b_near, b_u])
    if rigid:
        b[:, 2] = wrap64(b[:, 2])
    b = f32(b)
    if rigid:
        # the robot and the oracle must pick the same shortest arc: no |dtheta| near pi
        assert np.all(np.abs(wrap64(b[:, 2].astype(F64) - a[:, 2].astype(F64))) < np.pi - 1e-3)
    near = np.arange(N_MOTIONS) < n_near
    return a, b, near


def dense_states(robot, a, b, step):
    """Every motion's states ``step`` apart in the robot's metric, both ends included, interpolated
    as the robot does (float64). Returns ``(motion index (S,), states (S, d))``."""
    a, b = a.astype(F64), b.astype(F64)
    n = np.maximum(np.ceil(motion_length(robot, a, b) / step), 1).astype(np.int64)
    idx = np.repeat(np.arange(len(a)), n + 1)
    start = np.concatenate([[0], np.cumsum(n + 1)[:-1]])
    t = (np.arange(idx.size) - start[idx]) / n[idx]
    d = b - a
    if robot.kind == "rigid_body":
        d[:, 2] = wrap64(d[:, 2])  # shortest arc (the angle itself need not be wrapped)
    return idx, a[idx] + t[:, None] * d[idx]


def dense_bad_states(env: Env, obst: Obstacles, states, pad: float, delta: float):
    """``(S,)`` bool: the state is not clear by ``delta`` under shapely: footprint / a link within
    ``pad + delta`` of an obstacle, or a corner / joint closer than ``delta`` to the workspace
    boundary or outside it, or (arm) a joint beyond [-pi, pi]."""
    robot = env.robot
    if robot.kind == "rigid_body":
        pts = rect_corners64(states, 0.5 * robot.length, 0.5 * robot.width)
        bad = obst.too_close(shapely.polygons(pts), pad + delta)
    else:
        pts = numpy_fk(robot, states)
        segs = np.stack([pts[:, :-1], pts[:, 1:]], 2).reshape(-1, 2, 2)
        bad = obst.too_close(shapely.linestrings(segs), pad + delta).reshape(len(states), -1).any(1)
        bad |= np.any(np.abs(states) > F64(np.float32(np.pi)), 1)  # the closed float32 limits
    wall = wall_dist64(pts, obst.bounds).min(1)
    return bad | (wall < delta)


def dense_check(env: Env, a, b, pad: float, delta: float):
    """``(M,)`` bool per motion: some dense state is not clear by ``delta``."""
    if len(a) == 0:
        return np.zeros(0, bool)
    idx, states = dense_states(env.robot, a, b, env.robot.resolution / DENSE)
    bad = dense_bad_states(env, Obstacles(env.world), states, pad, delta)
    return np.bincount(idx[bad], minlength=len(a)) > 0


def certified(env: Env, a, b, pad: float):
    # the default chunk (CERTIFIED_CHUNK): the program Env.steer_to and the pipeline compile
    return np.asarray(steer_to_pairs(env.robot, env.world, a, b, pad, check="certified"), bool)


@pytest.mark.parametrize("name, pad_mode", PROP3_CASES)
def test_certified_has_no_false_frees(name, pad_mode):
    """Every motion the certified check calls free passes a dense shapely check 100x finer than the
    robot's resolution, with every state clear by ``margin / 4`` (so in particular valid)."""
    env = get_env(name)
    pad = 0.0 if pad_mode == "zero" else env.padding
    totals = np.zeros(4, int)

    # 3 examples for the rigid body, 2 for the arms (their dense checks cost more) of 256 motions
    @settings(
        max_examples=3 if env.robot.kind == "rigid_body" else 2,
        deadline=None,
        database=None,
        phases=PHASES,
        suppress_health_check=list(HealthCheck),
    )
    @given(seed=seeds)
    def check(seed):
        rng = np.random.default_rng(seed)
        a, b, near = sample_motions(rng, env, pad)
        free = certified(env, a, b, pad)
        i = np.flatnonzero(free)
        close = dense_check(env, a[i], b[i], pad, DELTA)
        if close.any():
            real = dense_check(env, a[i[close]], b[i[close]], pad, 0.0)  # distance <= padding
            rows = "\n".join(
                f"  a={a[j].tolist()} b={b[j].tolist()} collides={r}"
                for j, r in zip(i[close][:5], real[:5])
            )
            pytest.fail(
                f"{name} padding {pad}: {close.sum()} certified-free motions are not clear "
                f"by {DELTA} ({real.sum()} collide: false frees), seed {seed}:\n{rows}"
            )
        totals[:] += [free.sum(), (~free).sum(), (free & near).sum(), near.sum()]

    check()
    _, n_blocked, near_free, n_near = totals
    # non-vacuous: plenty of motions near obstacles certified free, and plenty blocked
    assert near_free >= 0.2 * n_near, totals
    assert n_blocked >= 0.05 * totals[:2].sum(), totals


# ---------------------------------------------------------------------------
# 4. What the discretised check misses
# ---------------------------------------------------------------------------


def test_certified_catches_thin_box_the_discretised_check_misses():
    """A 0.1-wide wall crossed by a rigid body (resolution 1.0) and swept by an arm (resolution
    1.0 rad): the discretised check steps over it, the certified one blocks, shapely confirms the
    collision."""
    rigid = Env.from_json(
        {
            "name": "thin-rigid",
            "bounds": [[0, 10], [0, 10]],
            "robot": {"kind": "rigid_body", "length": 0.2, "width": 0.2, "resolution": 1.0},
            "boxes": [[5.0, 5.0, 0.05, 1.0]],
            "padding": 0.0,
        }
    )
    # states at x = 3.5, 4.5, 5.5, 6.5 (3 steps of 1.0): the wall x in [4.95, 5.05] lies between
    # (with a turn or a slant: 3 steps too, the states straddle the wall as well)
    ra = np.array([[3.5, 5.0, 0.0], [3.7, 5.0, 0.0], [3.6, 4.8, 0.0], [3.5, 2.0, 0.0]], np.float32)
    rb = np.array([[6.5, 5.0, 0.0], [6.4, 5.0, 0.5], [6.4, 5.1, 0.0], [6.5, 2.0, 0.0]], np.float32)
    arm = Env.from_json(
        {
            "name": "thin-arm",
            "bounds": [[-10, 10], [-10, 10]],
            "robot": {"kind": "nlink", "link_lengths": [3.0, 3.0], "resolution": 1.0},
            "boxes": [[4.0, 0.0, 0.5, 0.05]],
            "padding": 0.0,
        }
    )
    # joint 1 from -0.5 to 1.0 (2 steps: -0.5, 0.25, 1.0): the arm sweeps over the wall at angle 0
    qa = np.array([[-0.5, 0.0], [-0.5, 0.1], [0.6, 0.0]], np.float32)
    qb = np.array([[1.0, 0.0], [1.0, 0.1], [1.0, 0.0]], np.float32)
    for env, a, b, expect_hit, pads in (
        (rigid, ra, rb, [True, True, True, False], (0.0,)),
        (arm, qa, qb, [True, True, False], (0.0,)),
    ):
        for pad in pads:
            disc = np.asarray(env.steer_to(a, b, padding=pad, check="discretized"))
            cert = np.asarray(env.steer_to(a, b, padding=pad, check="certified"))
            hits = dense_check(env, a, b, pad, 0.0)
            assert hits.tolist() == expect_hit, (env.name, pad, hits)
            assert disc.all(), (env.name, pad, disc)  # the discretised check misses the wall ...
            assert cert.tolist() == [not h for h in expect_hit], (
                env.name,
                pad,
                cert,
            )  # ... this one not


# ---------------------------------------------------------------------------
# 5. Certified within discretised; blocked inputs; zero-length motions
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["rigid/0+discs", "nlink/4"])
def test_certified_implies_valid_ends_and_discretised_free(name):
    """Certified free => both endpoints valid and the discretised check free, on the motions of
    the zero-false-free test (near obstacles and uniform) at the preset's padding."""
    env = get_env(name)
    pad = env.padding
    n_cert = 0
    for seed in range(3):
        a, b, _ = sample_motions(np.random.default_rng(seed), env, pad)
        cert = certified(env, a, b, pad)
        disc = np.asarray(
            steer_to_pairs(env.robot, env.world, a, b, pad, chunk=N_MOTIONS, check="discretized"),
            bool,
        )
        va = valid_states(env.robot, env.world, a, pad)
        vb = valid_states(env.robot, env.world, b, pad)
        assert not (cert & ~(va & vb)).any(), "certified free with an invalid endpoint"
        assert not (disc & ~(va & vb)).any()
        # certified free => every state is clear by ~margin / 2 (>> the 1e-5 band in which
        # clearance and is_valid may disagree), so every discretised state is valid: no exception
        bad = np.flatnonzero(cert & ~disc)
        assert not bad.size, [(a[i].tolist(), b[i].tolist()) for i in bad[:5]]
        n_cert += cert.sum()
    assert n_cert > 100, n_cert


def test_blocked_inputs_and_zero_length_motions():
    """Invalid endpoints, NaN / inf coordinates and masked-out motions are blocked; a zero-length
    motion of a valid state with clearance > margin is free (coordinate-major kernel with mask)."""
    # One box and one disc, each repeated to rigid/0+discs' obstacle counts (3 boxes, 2 discs:
    # the same map): with rigid/0's robot and padding (0.4) the certified program (and the
    # clearance one) are the ones test_certified_has_no_false_frees compiles.
    env = Env.from_json(
        {
            "name": "one-box",
            "bounds": [[0, 10], [0, 10]],
            "robot": {"kind": "rigid_body", "length": 1.2, "width": 0.4},
            "boxes": [[5.0, 5.0, 1.0, 1.0]] * 3,
            "discs": [[8.0, 8.0, 0.5]] * 2,
            "padding": 0.4,
        }
    )
    robot, world = env.robot, env.world
    free_q = [2.0, 2.0, 0.3]
    near_q = [7.5, 5.0, 0.0]  # rectangle x in [6.9, 8.1]: 0.9 from the box, clearance 0.5
    inside = [5.0, 5.0, 0.0]
    out = [0.3, 5.0, 0.0]  # a corner at x = -0.3
    nan, inf = float("nan"), float("inf")
    rows = [  # (a, b, mask, expected free)
        (free_q, free_q, True, True),  # zero length, clearance far above the margin
        (near_q, near_q, True, True),
        (free_q, [2.5, 2.0, 0.0], True, True),
        (free_q, [2.5, 2.0, 0.0], False, False),  # masked out
        (free_q, free_q, False, False),
        (inside, inside, True, False),  # invalid endpoint(s)
        (free_q, inside, True, False),
        (inside, free_q, True, False),
        (out, [1.0, 5.0, 0.0], True, False),
        ([nan, 2.0, 0.0], free_q, True, False),
        (free_q, [2.0, nan, 0.0], True, False),
        (free_q, [2.0, 2.0, nan], True, False),
        ([inf, 2.0, 0.0], free_q, True, False),
        (free_q, [2.0, -inf, 0.3], True, False),
        ([nan, nan, nan], [nan, nan, nan], True, False),
    ]
    a = f32([r[0] for r in rows])
    b = f32([r[1] for r in rows])
    mask = np.array([r[2] for r in rows])
    want = [r[3] for r in rows]
    c = clearance(robot, world, f32([free_q, near_q]), 0.4)
    assert (c > CERT_MARGIN).all() and c[1] < 1.0, c
    # the kernel with this mask (the library's masked certified program: rows transposed to
    # coordinate-major, robot.certified_steer_to_batch(a, b, world, 0.4, mask)), the rows padded
    # to its one chunk shape with masked-out zero rows
    n, fill = len(rows), CERTIFIED_CHUNK - len(rows)
    got = np.asarray(
        _steer_masked(
            robot,
            world,
            np.pad(a, ((0, fill), (0, 0))),
            np.pad(b, ((0, fill), (0, 0))),
            np.pad(mask, (0, fill)),
            0.4,
            "certified",
        )
    )
    assert got[:n].tolist() == want
    assert not got[n:].any()  # masked out
    # the public chunked entry point agrees (its padding rows are masked out; several chunks:
    # test_certified_steer_to_compiles_once_for_every_batch_size); a zero-length motion with
    # clearance below the margin is (conservatively) blocked
    tight = f32([[7.0 + CERT_MARGIN / 4, 5.0, 0.0]])  # 0.4 + margin/4 from the box
    assert 0 < clearance(robot, world, tight, 0.4)[0] < CERT_MARGIN
    a2, b2 = np.concatenate([a[mask], tight]), np.concatenate([b[mask], tight])
    assert steer_to_pairs(robot, world, a2, b2, 0.4, check="certified").tolist() == [
        w for w, m in zip(want, mask) if m
    ] + [False]


# ---------------------------------------------------------------------------
# 6. The point robot: certified == discretised (both exact)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["point/0", "point/3"])
def test_point_robot_certified_equals_discretised(name):
    env = make_env(name)
    rng = np.random.default_rng(0)
    lo, hi = env.world.bounds[:, 0], env.world.bounds[:, 1]
    a = f32(rng.uniform(np.asarray(lo) - 0.5, np.asarray(hi) + 0.5, (4096, 2)))
    b = f32(
        np.where(
            rng.random((4096, 1)) < 0.5,
            a + rng.normal(0, 1.0, a.shape),
            rng.uniform(np.asarray(lo), np.asarray(hi), a.shape),
        )
    )
    a[:8, 0] = np.nan
    for pad in (0.0, env.padding):
        cert = np.asarray(env.steer_to(a, b, padding=pad, check="certified"))
        disc = np.asarray(env.steer_to(a, b, padding=pad, check="discretized"))
        assert (cert == disc).all()
        assert 0.1 < cert.mean() < 0.9
        assert not cert[:8].any()


def test_certified_steer_to_compiles_once_for_every_batch_size():
    """Env.steer_to(check="certified") runs in chunks of CERTIFIED_CHUNK rows: a user's
    varying batch sizes share one compiled program with steer_to_pairs, and the answers
    do not depend on the chunk."""
    from ntq_jax.robots.batch import CERTIFIED_CHUNK
    from ntq_jax.robots.batch import _steer_masked as kernel

    env = Env.from_json(
        {
            "name": "thin-arm-2",
            "bounds": [[-10, 10], [-10, 10]],
            "robot": {"kind": "nlink", "link_lengths": [3.0, 3.0], "resolution": 1.0},
            "boxes": [[4.0, 0.0, 0.5, 0.05]],
            "padding": 0.0,
        }
    )
    rng = np.random.default_rng(3)
    n = 2 * CERTIFIED_CHUNK + 5
    a, b = (f32(rng.uniform(-np.pi, np.pi, (n, 2))) for _ in range(2))
    want = np.asarray(
        steer_to_pairs(env.robot, env.world, a, b, 0.0, chunk=256, check="certified"), bool
    )
    assert 0.05 < want.mean() < 0.95
    sizes = [1, 3, 700, CERTIFIED_CHUNK, CERTIFIED_CHUNK + 1, n]
    assert (
        np.asarray(steer_to_pairs(env.robot, env.world, a, b, 0.0, check="certified")) == want
    ).all()  # the default chunk: compiled here, once
    before = kernel._cache_size()
    for m in sizes:
        got = env.steer_to(a[:m], b[:m], check="certified")
        assert got.shape == (m,) and got.dtype == bool
        assert (np.asarray(got) == want[:m]).all(), m
    got = env.steer_to(a[:5].tolist(), b[:5].tolist(), check="certified")  # lists too
    assert (np.asarray(got) == want[:5]).all()
    assert env.steer_to(a[:0], b[:0], check="certified").shape == (0,)
    assert kernel._cache_size() == before
