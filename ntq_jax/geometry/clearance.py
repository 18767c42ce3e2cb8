"""Euclidean distances between closed shapes (0 when they intersect): the clearance of the certified motion check."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ntq_jax import broadphase
from ntq_jax.broadphase import fold
from ntq_jax.geometry.shapes import (
    _SENTINEL_DISC,
    RectPose,
    _point_box_dist2,
    _point_obb_dist2,
    pose_hits_box,
    rect_pose,
    segment_cover_steps,
    segment_hits_box,
)
from ntq_jax.geometry.world import World

Array = jax.Array


# ---------------------------------------------------------------------------
# Distance kernels (clearance of the certified motion check)
# ---------------------------------------------------------------------------
#
# Euclidean distances between closed shapes, 0 when they intersect. Used by the
# certified ``steer_to`` (:mod:`ntq_jax.robots.certified`), which needs how far
# a configuration is from collision, not only whether it collides. The
# intersection tests are the exact ``*_hits_*`` kernels above; for disjoint
# convex shapes the distance is attained at a vertex of one of them, which is
# what the vertex terms below compute. Only the point-to-segment projection
# divides, guarded against zero-length segments.


def _point_segment_dist2(px, py, x0, y0, dx, dy, dd):
    """Squared distance from a point to the closed segment ``(x0, y0) + [0, 1] (dx, dy)``."""
    wx, wy = px - x0, py - y0
    t = jnp.clip((wx * dx + wy * dy) / jnp.where(dd > 0.0, dd, 1.0), 0.0, 1.0)
    ex, ey = wx - t * dx, wy - t * dy
    return ex * ex + ey * ey


def segment_box_dist2(x0, y0, x1, y1, box: Array) -> Array:
    """Squared distance between the closed segment and the closed box (0 when they meet).

    Disjoint: the distance is attained at a segment endpoint (to the box) or at
    a box corner (to the segment), and among the corners only the one nearest
    the segment's line (chosen as in :func:`segment_hits_box`) can beat the
    endpoints.
    """
    cx, cy, hw, hh = box[0], box[1], box[2], box[3]
    dx, dy = x1 - x0, y1 - y0
    cross = (0.5 * (x0 + x1) - cx) * dy - (0.5 * (y0 + y1) - cy) * dx
    px = cx + jnp.where(cross * dy > 0.0, hw, -hw)
    py = cy + jnp.where(cross * dx > 0.0, -hh, hh)
    d2 = jnp.minimum(
        jnp.minimum(_point_box_dist2(x0, y0, box), _point_box_dist2(x1, y1, box)),
        _point_segment_dist2(px, py, x0, y0, dx, dy, dx * dx + dy * dy),
    )
    return jnp.where(segment_hits_box(x0, y0, x1, y1, box, 0.0), 0.0, d2)


def segment_disc_dist(x0, y0, x1, y1, disc: Array) -> Array:
    """Distance between the closed segment and the closed disc (0 when they meet)."""
    dx, dy = x1 - x0, y1 - y0
    d2 = _point_segment_dist2(disc[0], disc[1], x0, y0, dx, dy, dx * dx + dy * dy)
    return jnp.maximum(jnp.sqrt(d2) - disc[2], 0.0)


def rect_box_dist2(x, y, theta, half_l: float, half_w: float, box: Array) -> Array:
    """Squared distance between the oriented rectangle and the box (0 when they meet).

    Disjoint convex polygons: the minimum over the rectangle's corners to the
    box and the box's corners to the rectangle.
    """
    return pose_box_dist2(rect_pose(x, y, theta, half_l, half_w), box)


def pose_box_dist2(pose: RectPose, box: Array) -> Array:
    """:func:`rect_box_dist2` for a rectangle given by :func:`~ntq_jax.geometry.rect_pose`."""
    x, y, s, c, half_l, half_w = pose.x, pose.y, pose.s, pose.c, pose.half_l, pose.half_w
    cx, cy, hw, hh = box[0], box[1], box[2], box[3]
    d2 = _point_box_dist2(pose.xs[0], pose.ys[0], box)
    for px, py in zip(pose.xs[1:], pose.ys[1:]):
        d2 = jnp.minimum(d2, _point_box_dist2(px, py, box))
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            d2 = jnp.minimum(
                d2, _point_obb_dist2(cx + sx * hw, cy + sy * hh, x, y, c, s, half_l, half_w)
            )
    return jnp.where(pose_hits_box(pose, box, 0.0), 0.0, d2)


def rect_disc_dist(x, y, theta, half_l: float, half_w: float, disc: Array) -> Array:
    """Distance between the oriented rectangle and the closed disc (0 when they meet)."""
    return pose_disc_dist(rect_pose(x, y, theta, half_l, half_w), disc)


def pose_disc_dist(pose: RectPose, disc: Array) -> Array:
    """:func:`rect_disc_dist` for a rectangle given by :func:`~ntq_jax.geometry.rect_pose`."""
    d2 = _point_obb_dist2(
        disc[0], disc[1], pose.x, pose.y, pose.c, pose.s, pose.half_l, pose.half_w
    )
    return jnp.maximum(jnp.sqrt(d2) - disc[2], 0.0)


def wall_clearance(x, y, bounds: Array) -> Array:
    """Signed distance from ``(x, y)`` to the workspace's boundary: > 0 inside, < 0 outside."""
    return jnp.minimum(
        jnp.minimum(x - bounds[0, 0], bounds[0, 1] - x),
        jnp.minimum(y - bounds[1, 0], bounds[1, 1] - y),
    )


def segment_clearance(x0, y0, x1, y1, world: World, padding: float = 0.0) -> Array:
    """Distance from the closed segment to the nearest obstacle (``inf`` without obstacles).

    With a broad-phase index that covers ``padding`` (the clearance the caller
    will subtract), a lower bound instead: the exact distance when it is below
    the cap ``(reach + padding) / 2``, else at least the cap (> ``padding``), so
    the sign of ``clearance - padding`` is exact (:mod:`ntq_jax.broadphase`).
    """
    c = jnp.float32(jnp.inf)
    nb = world.boxes.shape[0]
    if nb and broadphase.index_covers(world, padding, strict=True):
        c = _segment_clearance_indexed(x0, y0, x1, y1, world, padding)
    elif nb > broadphase.UNROLL_MAX:
        d2 = fold(
            world.boxes,
            lambda box: segment_box_dist2(x0, y0, x1, y1, box),
            jnp.float32(jnp.inf),
            jnp.minimum,
            broadphase.SENTINEL_BOX,
        )
        c = jnp.sqrt(d2)
    elif nb:
        d2 = segment_box_dist2(x0, y0, x1, y1, world.boxes[0])
        for i in range(1, world.boxes.shape[0]):
            d2 = jnp.minimum(d2, segment_box_dist2(x0, y0, x1, y1, world.boxes[i]))
        c = jnp.sqrt(d2)
    if world.discs.shape[0] > broadphase.UNROLL_MAX:
        return fold(
            world.discs,
            lambda disc: segment_disc_dist(x0, y0, x1, y1, disc),
            c,
            jnp.minimum,
            _SENTINEL_DISC,
        )
    for i in range(world.discs.shape[0]):
        c = jnp.minimum(c, segment_disc_dist(x0, y0, x1, y1, world.discs[i]))
    return c


def _segment_clearance_indexed(x0, y0, x1, y1, world: World, padding: float) -> Array:
    """Broad-phase segment clearance, capped (see :func:`segment_clearance`): the cells of
    points spaced for a half-gap of ``(reach - padding) / 2``."""
    reach = world.index.reach
    half = 0.5 * (reach - padding)
    cap = jnp.float32(reach - half)  # every box nearer than this is found
    n = segment_cover_steps(x0, y0, x1, y1, reach - half, padding)

    def body(k, d2):
        t = k.astype(jnp.float32) / jnp.maximum(n, 1).astype(jnp.float32)
        px, py = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
        return broadphase.fold_candidates(
            world.index.candidates(px, py),
            lambda box: segment_box_dist2(x0, y0, x1, y1, box),
            d2,
            jnp.minimum,
            cheap=False,
        )

    d2 = jax.lax.fori_loop(0, n + 1, body, cap * cap)
    return jnp.where(n > 0, jnp.sqrt(d2), jnp.nan)


def rect_clearance(
    pose: Array, half_l: float, half_w: float, world: World, padding: float = 0.0
) -> Array:
    """Distance from the oriented rectangle at ``pose`` to the nearest obstacle (``inf`` without).

    With a broad-phase index that covers ``padding`` and the rectangle's half
    diagonal ``rho``, a lower bound instead: exact below the cap ``reach - rho``
    (> ``padding``), at least the cap otherwise (:mod:`ntq_jax.broadphase`).
    """
    x, y, th = pose[0], pose[1], pose[2]
    rect = rect_pose(x, y, th, half_l, half_w)
    c = jnp.float32(jnp.inf)
    nb = world.boxes.shape[0]
    rho = math.hypot(half_l, half_w)
    if nb and broadphase.index_covers(world, padding, rho, strict=True):
        cap = jnp.float32(world.index.reach - rho)
        d2 = broadphase.fold_candidates(
            world.index.candidates(x, y),
            lambda box: pose_box_dist2(rect, box),
            cap * cap,
            jnp.minimum,
            cheap=False,
        )
        c = jnp.sqrt(d2)
    elif nb > broadphase.UNROLL_MAX:
        d2 = fold(
            world.boxes,
            lambda box: pose_box_dist2(rect, box),
            jnp.float32(jnp.inf),
            jnp.minimum,
            broadphase.SENTINEL_BOX,
        )
        c = jnp.sqrt(d2)
    elif nb:
        d2 = pose_box_dist2(rect, world.boxes[0])
        for i in range(1, world.boxes.shape[0]):
            d2 = jnp.minimum(d2, pose_box_dist2(rect, world.boxes[i]))
        c = jnp.sqrt(d2)
    if world.discs.shape[0] > broadphase.UNROLL_MAX:
        return fold(
            world.discs, lambda disc: pose_disc_dist(rect, disc), c, jnp.minimum, _SENTINEL_DISC
        )
    for i in range(world.discs.shape[0]):
        c = jnp.minimum(c, pose_disc_dist(rect, world.discs[i]))
    return c
