"""Collision kernels of one item: points, segments and oriented rectangles against boxes and discs.

Padding means clearance: a shape collides with an obstacle when its Euclidean
distance to it is ``<= padding`` (see :mod:`ntq_jax.geometry`)."""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ntq_jax import broadphase
from ntq_jax.broadphase import fold
from ntq_jax.geometry.world import World

Array = jax.Array


# ---------------------------------------------------------------------------
# Trigonometry
# ---------------------------------------------------------------------------

# pi/2 split in three parts (Cody-Waite); the first two have few mantissa bits, so
# ``j * part`` is exact for |j| < 2^15 and the reduction stays accurate for |x| < ~5e4.
_PIO2 = (1.5703125, 4.837512969970703125e-4, 7.54978995489188216e-8)
_SIN = (-1.6666654611e-1, 8.3321608736e-3, -1.9515295891e-4)  # Cephes sinf on [-pi/4, pi/4]
_COS = (4.166664568298827e-2, -1.388731625493765e-3, 2.443315711809948e-5)  # Cephes cosf


def sincos(x: Array) -> tuple[Array, Array]:
    """``(sin x, cos x)`` for float32 ``x``, vectorisable (about 1e-7 absolute error for |x| < 5e4).

    XLA on CPU evaluates ``jnp.sin``/``jnp.cos`` with one scalar library call per
    element (~70 M/s on the development machine); this Cephes-style version
    (reduction by pi/2 in three parts, degree-7/8 polynomials on [-pi/4, pi/4],
    shared by both results) compiles to plain vector arithmetic (~1.8 G/s). The
    rigid body's footprint and the arm's forward kinematics use it. NaN or
    infinite ``x`` give NaN.
    """
    x = jnp.asarray(x, jnp.float32)
    j = jnp.round(x * jnp.float32(2.0 / math.pi))
    r = ((x - j * _PIO2[0]) - j * _PIO2[1]) - j * _PIO2[2]
    r2 = r * r
    s = r + r * r2 * (_SIN[0] + r2 * (_SIN[1] + r2 * _SIN[2]))
    c = 1.0 - 0.5 * r2 + r2 * r2 * (_COS[0] + r2 * (_COS[1] + r2 * _COS[2]))
    quadrant = jnp.where(jnp.isfinite(j), j, 0.0).astype(jnp.int32) & 3
    swap = (quadrant & 1) == 1
    sin = jnp.where(swap, c, s)
    cos = jnp.where(swap, s, c)
    sin = jnp.where(quadrant >= 2, -sin, sin)
    cos = jnp.where((quadrant == 1) | (quadrant == 2), -cos, cos)
    return sin, cos


# ---------------------------------------------------------------------------
# Point kernels
# ---------------------------------------------------------------------------


def in_bounds(x: Array, y: Array, bounds: Array) -> Array:
    """True when ``(x, y)`` lies in the closed workspace rectangle (False for NaN)."""
    return (x >= bounds[0, 0]) & (x <= bounds[0, 1]) & (y >= bounds[1, 0]) & (y <= bounds[1, 1])


def _point_box_dist2(x, y, box):
    dx = jnp.maximum(jnp.abs(x - box[0]) - box[2], 0.0)
    dy = jnp.maximum(jnp.abs(y - box[1]) - box[3], 0.0)
    return dx * dx + dy * dy


def _point_corner_dist2(x, y, box):
    """Squared distance from a point to the box's nearest corner (a point of the box)."""
    dx = jnp.abs(x - box[0]) - box[2]
    dy = jnp.abs(y - box[1]) - box[3]
    return dx * dx + dy * dy


def point_hits_box(x: Array, y: Array, box: Array, padding: float) -> Array:
    """True when the point's distance to the closed box is ``<= padding``."""
    if padding == 0.0:
        return (jnp.abs(x - box[0]) <= box[2]) & (jnp.abs(y - box[1]) <= box[3])
    return _point_box_dist2(x, y, box) <= padding * padding


def point_hits_disc(x: Array, y: Array, disc: Array, padding: float) -> Array:
    """True when the point's distance to the closed disc is ``<= padding``."""
    dx, dy = x - disc[0], y - disc[1]
    r = disc[2] + padding
    return dx * dx + dy * dy <= r * r


def point_free(p: Array, world: World, padding: float) -> Array:
    """True when point ``p`` ``(2,)`` is in bounds and farther than ``padding`` from every obstacle."""
    x, y = p[0], p[1]
    free = in_bounds(x, y, world.bounds)
    free = _fold_boxes(
        world, x, y, padding, 0.0, lambda box: point_hits_box(x, y, box, padding), free
    )
    return fold(
        world.discs,
        lambda disc: point_hits_disc(x, y, disc, padding),
        free,
        _and_not,
        _SENTINEL_DISC,
    )


def _and_not(free, hit):
    return free & ~hit


_SENTINEL_DISC = (1.0e7, 1.0e7, 1.0)


def _fold_boxes(world: World, x, y, padding: float, rho: float, hit, free):
    """``free`` and not ``hit(box)`` for every box a shape within ``rho`` of ``(x, y)`` may
    touch at ``padding``: the index cell's candidates when the index covers it
    (:func:`ntq_jax.broadphase.index_covers`), else all of ``world.boxes``."""
    if broadphase.index_covers(world, padding, rho):
        return broadphase.fold_candidates(world.index.candidates(x, y), hit, free, _and_not)
    return fold(world.boxes, hit, free, _and_not, broadphase.SENTINEL_BOX)


# ---------------------------------------------------------------------------
# Segment kernels
# ---------------------------------------------------------------------------


def _seg_point_interior_close(x0, y0, dx, dy, dd, px, py, r2):
    """Distance from point to the segment's interior (projection in [0, 1]) <= sqrt(r2).

    Division-free: with ``t* = dot / dd`` the squared distance is ``cross^2 / dd``.
    A degenerate segment (``dd == 0``) has no interior: False (its single point is
    tested by the callers' endpoint tests).
    """
    wx, wy = px - x0, py - y0
    dot = wx * dx + wy * dy
    cross = wx * dy - wy * dx
    return (dot >= 0.0) & (dot <= dd) & (cross * cross <= r2 * dd) & (dd > 0.0)


def segment_hits_box(x0, y0, x1, y1, box: Array, padding: float) -> Array:
    """Exact test: distance between segment ``[(x0,y0),(x1,y1)]`` and the box ``<= padding``.

    ``padding == 0``: the separating-axis test (closed sets) on the axes x, y and
    the segment normal.

    ``padding = r > 0``: the box grown by ``r`` is the union of the "plus" (the
    box grown by ``r`` along x, and along y) and the four corner discs. Let the
    distance be attained at segment point ``s*`` and box point ``b*``. Then
    ``s*`` lies in the plus (two separating-axis tests), or ``s*`` is an
    endpoint and ``b*`` a corner (endpoint-to-nearest-corner tests), or
    ``b*`` is the corner nearest the segment's line and ``s*`` is that corner's
    foot point (one corner-to-segment test; the corner follows from the signs of
    the box centre's cross product and the direction, so one corner suffices
    instead of four). Every test compares a true distance, so none can report a
    false collision.
    """
    cx, cy, hw, hh = box[0], box[1], box[2], box[3]
    dx, dy = x1 - x0, y1 - y0
    adx, ady = jnp.abs(dx), jnp.abs(dy)
    ux, uy = 0.5 * (x0 + x1) - cx, 0.5 * (y0 + y1) - cy  # segment midpoint - box centre
    ex, ey = jnp.abs(ux), jnp.abs(uy)
    # cross product of (segment midpoint - box centre) with the direction, and the box's
    # half extent along the segment normal (both times |d|): |cross| <= h iff the line meets the box
    cross = ux * dy - uy * dx
    h = hw * ady + hh * adx
    if padding == 0.0:
        return (ex <= hw + 0.5 * adx) & (ey <= hh + 0.5 * ady) & (jnp.abs(cross) <= h)
    r = padding
    r2 = r * r
    gx, gy, gc = ex - 0.5 * adx, ey - 0.5 * ady, jnp.abs(cross) - h
    wide = (gx <= hw + r) & (gy <= hh) & (gc <= r * ady)  # the box grown by r along x
    tall = (gx <= hw) & (gy <= hh + r) & (gc <= r * adx)  # the box grown by r along y
    # an endpoint near the box but outside the plus is near a corner: its nearest corner suffices
    ends = (_point_corner_dist2(x0, y0, box) <= r2) | (_point_corner_dist2(x1, y1, box) <= r2)
    # the corner nearest the segment's line (smallest |cross| over corners, = |cross| - h)
    px = cx + jnp.where(cross * dy > 0.0, hw, -hw)
    py = cy + jnp.where(cross * dx > 0.0, -hh, hh)
    corner = _seg_point_interior_close(x0, y0, dx, dy, dx * dx + dy * dy, px, py, r2)
    return wide | tall | ends | corner


def segment_hits_disc(x0, y0, x1, y1, disc: Array, padding: float) -> Array:
    """Exact test: distance between the segment and the closed disc ``<= padding``."""
    r = disc[2] + padding
    r2 = r * r
    dx, dy = x1 - x0, y1 - y0
    dd = dx * dx + dy * dy
    e0 = (x0 - disc[0]) ** 2 + (y0 - disc[1]) ** 2 <= r2
    e1 = (x1 - disc[0]) ** 2 + (y1 - disc[1]) ** 2 <= r2
    return e0 | e1 | _seg_point_interior_close(x0, y0, dx, dy, dd, disc[0], disc[1], r2)


def segment_free(
    p0: Array, p1: Array, world: World, padding: float, check_bounds: bool = True
) -> Array:
    """True when the whole closed segment ``p0 -> p1`` is collision-free (exact, continuous).

    The workspace rectangle is convex, so the segment is inside it iff both
    endpoints are.
    """
    x0, y0, x1, y1 = p0[0], p0[1], p1[0], p1[1]
    free = jnp.isfinite(x0 + y0 + x1 + y1)
    if check_bounds:
        free = free & in_bounds(x0, y0, world.bounds) & in_bounds(x1, y1, world.bounds)
    if broadphase.index_covers(world, padding, strict=True):
        free = segment_free_indexed(x0, y0, x1, y1, world, padding, free)
    else:
        free = fold(
            world.boxes,
            lambda box: segment_hits_box(x0, y0, x1, y1, box, padding),
            free,
            _and_not,
            broadphase.SENTINEL_BOX,
        )
    return fold(
        world.discs,
        lambda disc: segment_hits_disc(x0, y0, x1, y1, disc, padding),
        free,
        _and_not,
        _SENTINEL_DISC,
    )


def segment_cover_steps(x0, y0, x1, y1, reach: float, padding: float) -> Array:
    """``n >= 1``: the points ``t = k / n``, ``k = 0..n``, of the segment are close enough
    for the broad phase (every point of the segment within ``reach - padding`` of one of
    them, with a margin for rounding); 0 for a non-finite segment."""
    h = 2.0 * (reach - padding) * (1.0 - 1e-3)
    dx, dy = x1 - x0, y1 - y0
    length = jnp.sqrt(dx * dx + dy * dy)
    n = jnp.maximum(jnp.ceil(length * jnp.float32(1.0 / h)), 1.0)
    return jnp.where(jnp.isfinite(n), jnp.minimum(n, 2.0**30), 0.0).astype(jnp.int32)


def segment_hits_near(x0, y0, x1, y1, t, world: World, padding: float) -> Array:
    """True when the segment is within ``padding`` of a box listed in the index cell of
    its point at fraction ``t`` (the exact test, on the whole segment)."""
    px, py = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
    return ~broadphase.fold_candidates(
        world.index.candidates(px, py),
        lambda box: segment_hits_box(x0, y0, x1, y1, box, padding),
        jnp.bool_(True),
        _and_not,
    )


def segment_free_indexed(x0, y0, x1, y1, world: World, padding: float, free: Array) -> Array:
    """``free`` and the segment clear of every box, through the broad phase: the cells of
    the points of :func:`segment_cover_steps`, in a loop that stops at the first hit."""
    n = segment_cover_steps(x0, y0, x1, y1, world.index.reach, padding)

    def cond(carry):
        k, ok = carry
        return ok & (k <= n)

    def body(carry):
        k, ok = carry
        t = k.astype(jnp.float32) / n.astype(jnp.float32)
        return k + 1, ok & ~segment_hits_near(x0, y0, x1, y1, t, world, padding)

    return jax.lax.while_loop(cond, body, (jnp.int32(0), free & (n > 0)))[1]


# ---------------------------------------------------------------------------
# Oriented rectangle kernels (rigid body footprint)
# ---------------------------------------------------------------------------


class RectPose(NamedTuple):
    """An oriented rectangle placed at a pose: what every rectangle kernel needs of it,
    computed once per pose (:func:`rect_pose`) and shared by the tests against every
    obstacle (so ``sincos`` is traced and evaluated once, not once per obstacle)."""

    x: Array
    y: Array
    s: Array  # sin theta
    c: Array  # cos theta
    xs: tuple  # the 4 corners' x, in the order of :func:`rect_corners`
    ys: tuple
    half_l: float
    half_w: float


def rect_pose(x, y, theta, half_l: float, half_w: float) -> RectPose:
    """The rectangle of half extents ``(half_l, half_w)`` at ``(x, y, theta)``."""
    s, c = sincos(theta)
    xs, ys = _corners(x, y, s, c, half_l, half_w)
    return RectPose(x, y, s, c, tuple(xs), tuple(ys), half_l, half_w)


def _corners(x, y, s, c, half_l, half_w):
    xs, ys = [], []
    for sl, sw in ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)):
        xs.append(x + sl * half_l * c - sw * half_w * s)
        ys.append(y + sl * half_l * s + sw * half_w * c)
    return xs, ys


def rect_corners(x, y, theta, half_l: float, half_w: float):
    """The 4 corners of the oriented rectangle, as two tuples of x and y scalars."""
    s, c = sincos(theta)
    return _corners(x, y, s, c, half_l, half_w)


def _point_obb_dist2(px, py, x, y, c, s, half_l, half_w):
    """Squared distance from a point to the oriented rectangle (0 inside)."""
    rx, ry = px - x, py - y
    u = rx * c + ry * s
    v = -rx * s + ry * c
    du = jnp.maximum(jnp.abs(u) - half_l, 0.0)
    dv = jnp.maximum(jnp.abs(v) - half_w, 0.0)
    return du * du + dv * dv


def rect_hits_box(x, y, theta, half_l: float, half_w: float, box: Array, padding: float) -> Array:
    """Exact test: distance between the oriented rectangle and the box ``<= padding``.

    Intersection: separating-axis theorem over all four candidate axes (box x, y;
    rectangle u, v). For ``padding > 0``: the distance between disjoint convex
    polygons is attained vertex-to-polygon, so also test the rectangle's corners
    against the box and the box's corners against the rectangle.
    """
    return pose_hits_box(rect_pose(x, y, theta, half_l, half_w), box, padding)


def pose_hits_box(pose: RectPose, box: Array, padding: float) -> Array:
    """:func:`rect_hits_box` for a rectangle given by :func:`rect_pose`."""
    x, y, s, c, half_l, half_w = pose.x, pose.y, pose.s, pose.c, pose.half_l, pose.half_w
    cx, cy, hw, hh = box[0], box[1], box[2], box[3]
    ac, as_ = jnp.abs(c), jnp.abs(s)
    tx, ty = cx - x, cy - y
    # Projections of the rectangle's half extents on the world axes and vice versa.
    sat = (
        (jnp.abs(tx) <= hw + half_l * ac + half_w * as_)
        & (jnp.abs(ty) <= hh + half_l * as_ + half_w * ac)
        & (jnp.abs(tx * c + ty * s) <= half_l + hw * ac + hh * as_)
        & (jnp.abs(-tx * s + ty * c) <= half_w + hw * as_ + hh * ac)
    )
    if padding == 0.0:
        return sat
    p2 = padding * padding
    hit = sat
    for px, py in zip(pose.xs, pose.ys):
        hit = hit | (_point_box_dist2(px, py, box) <= p2)
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            hit = hit | (
                _point_obb_dist2(cx + sx * hw, cy + sy * hh, x, y, c, s, half_l, half_w) <= p2
            )
    return hit


def rect_hits_disc(x, y, theta, half_l: float, half_w: float, disc: Array, padding: float) -> Array:
    """Exact test: distance between the oriented rectangle and the disc ``<= padding``."""
    return pose_hits_disc(rect_pose(x, y, theta, half_l, half_w), disc, padding)


def pose_hits_disc(pose: RectPose, disc: Array, padding: float) -> Array:
    """:func:`rect_hits_disc` for a rectangle given by :func:`rect_pose`."""
    r = disc[2] + padding
    return (
        _point_obb_dist2(disc[0], disc[1], pose.x, pose.y, pose.c, pose.s, pose.half_l, pose.half_w)
        <= r * r
    )


def rect_free(pose: Array, half_l: float, half_w: float, world: World, padding: float) -> Array:
    """True when the rectangle at ``pose = (x, y, theta)`` is inside the workspace and clear."""
    x, y, th = pose[0], pose[1], pose[2]
    free = jnp.isfinite(x + y + th)
    rect = rect_pose(x, y, th, half_l, half_w)
    for px, py in zip(rect.xs, rect.ys):
        free = free & in_bounds(px, py, world.bounds)
    free = _fold_boxes(
        world,
        x,
        y,
        padding,
        math.hypot(half_l, half_w),
        lambda box: pose_hits_box(rect, box, padding),
        free,
    )
    return fold(
        world.discs,
        lambda disc: pose_hits_disc(rect, disc, padding),
        free,
        _and_not,
        _SENTINEL_DISC,
    )
