"""Rigid rectangle in SE(2): the state is ``(x, y, theta)`` with theta in radians.

* Footprint: a ``length x width`` rectangle centred on ``(x, y)``, its length
  along the heading ``theta``; valid when all four corners lie in the
  workspace and its distance to every obstacle is ``> padding`` (exact,
  separating axes plus vertex distances; see :func:`ntq_jax.geometry.rect_hits_box`).
* Steering: straight line in position, shortest arc in angle.
* Cost metric: ``||dp|| + angle_weight * |dtheta|`` with dtheta on the shortest
  arc. The default ``angle_weight = 0.5`` is OMPL's own SE(2) distance (the
  SO(2) component weighted 0.5), so the metric is the path length that OMPL's
  BIT* minimises in the paper's setting.
* ``steer_to`` checks states spaced at most ``resolution`` apart in that metric.
  Between two checked states every point of the body moves at most
  ``resolution * max(1, R / angle_weight)`` with ``R`` the half diagonal, so a
  collision that penetrates deeper than that is always found; narrower
  grazes can be missed (the usual discretised check, as in OMPL and MPNet).
* Angles: every method that reads a user-given ``theta`` first reduces it to
  ``[-pi, pi)`` with :func:`reduce_angle` (accurate to about 1e-6 rad for
  ``|theta| < ANGLE_LIMIT``), so ``theta + 2 pi k`` behaves like ``theta``; a
  ``|theta| >= ANGLE_LIMIT`` (float32 angles there are several radians apart,
  they carry no heading) becomes NaN: invalid, and its motions blocked.
* ``certified_steer_to_batch`` (:mod:`ntq_jax.robots.certified`) proves every
  configuration of a motion clear instead, from :meth:`RigidBody.clearance`
  and the sweep bound ``|dp| + r_max |dtheta|`` (``r_max`` the half diagonal).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from ntq_jax import geometry, validation
from ntq_jax.geometry import World
from ntq_jax.robots.base import DiscretizedSteering, wrap_angle
from ntq_jax.robots.certified import CertifiedSteering

Array = jax.Array

#: ``|theta|`` at and beyond which a state is invalid: about 2^24 periods, where float32
#: angles are 8 rad apart and :func:`reduce_angle`'s split of ``k`` is no longer exact.
ANGLE_LIMIT = 1.0e8

# 2 pi in 12-bit parts (the last one in float32); |k| < 2^24 split in two 12-bit halves
# makes every product k_half * part exact, so x - k * 2 pi is exact up to the last steps.
_TWO_PI_PARTS = (
    6.283203125,
    -1.7814338207244873e-05,
    -3.4824552130885422e-09,
    2.4893487878679954e-13,
)
_INV_TWO_PI = 0.15915493667125702
_PI32 = 3.1415927410125732  # float32(pi) > pi: float32 angles >= it are >= pi
_PI32_BELOW = 3.1415925025939941  # the largest float32 < pi


def _reduce_by(x: Array, k: Array) -> Array:
    """``x - k * 2 pi`` for float32 integers ``|k| < 2^24``, exact except the last steps."""
    kh = jnp.round(k * jnp.float32(2.0**-12)) * jnp.float32(2.0**12)
    kl = k - kh
    r = x
    for part in _TWO_PI_PARTS[:3]:
        r = r - kh * jnp.float32(part)
        r = r - kl * jnp.float32(part)
    return r - k * jnp.float32(_TWO_PI_PARTS[3])


def _sub_periods(r: Array, k: Array) -> Array:
    """``r - k * 2 pi`` for small float32 integers ``|k| < 2^12`` (every product exact)."""
    for part in _TWO_PI_PARTS:
        r = r - k * jnp.float32(part)
    return r


def reduce_angle(theta: Array) -> Array:
    """``theta`` (float32) wrapped to ``[-pi, pi)``, to about 1e-6 rad for ``|theta| < ANGLE_LIMIT``.

    Unlike ``jnp.mod(theta + pi, 2 pi) - pi`` (whose ``theta + pi`` and float32
    ``2 pi`` lose the angle for large ``theta``: off by ~1 rad at 1e7), it
    subtracts ``k * 2 pi`` in exact pieces (Cody-Waite reduction with a split
    ``k``), in plain vectorisable arithmetic. The identity for float32 ``theta``
    in ``[-pi, pi)``; NaN, infinite and ``|theta| >= ANGLE_LIMIT`` give NaN (no
    heading: the state is invalid and its motions blocked).
    """
    x = jnp.asarray(theta, jnp.float32)
    x = jnp.where(jnp.abs(x) < ANGLE_LIMIT, x, jnp.nan)
    r = _reduce_by(x, jnp.round(x * jnp.float32(_INV_TWO_PI)))
    # the rounded k above may be off by 1 or 2 for large theta; r is small now
    r = _sub_periods(r, jnp.round(r * jnp.float32(_INV_TWO_PI)))
    # float32 angles in [-pi, pi) are exactly those within +-_PI32_BELOW; one within an ulp of
    # +-pi may still be outside after rounding, and its wrapped value is the nearest end
    return jnp.where(r >= _PI32, -_PI32_BELOW, jnp.where(r <= -_PI32, _PI32_BELOW, r))


def _reduced(q: Array) -> Array:
    """The state ``(x, y, theta)`` with theta reduced to ``[-pi, pi)``."""
    return jnp.stack([q[0], q[1], reduce_angle(q[2])])


@dataclasses.dataclass(frozen=True)
class RigidBody(DiscretizedSteering, CertifiedSteering):
    """Rectangle robot in SE(2)."""

    length: float = 1.5
    width: float = 0.5
    angle_weight: float = 0.5
    resolution: float = 0.05
    kind: str = dataclasses.field(default="rigid_body", init=False)
    dim: int = dataclasses.field(default=3, init=False)

    def __post_init__(self):
        for name in ("length", "width", "angle_weight", "resolution"):
            v = validation.number(getattr(self, name), f"rigid_body.{name}", minimum=0, strict=True)
            object.__setattr__(self, name, v)

    def longest_motion(self, world: World) -> float:
        """The longest motion between two valid states in the cost metric: the workspace
        diagonal plus ``angle_weight * pi`` (the bound of ``resolution``, see
        :func:`ntq_jax.envs.check_resolution`)."""
        b = world.bounds.tolist() if hasattr(world.bounds, "tolist") else world.bounds
        return math.hypot(b[0][1] - b[0][0], b[1][1] - b[1][0]) + self.angle_weight * math.pi

    @property
    def half_diagonal(self) -> float:
        return 0.5 * math.hypot(self.length, self.width)

    @property
    def periodic(self) -> tuple[bool, ...]:
        """Which state coordinates wrap around: theta wraps around."""
        return (False, False, True)

    @property
    def metric_weights(self) -> tuple[float, ...]:
        """Per-coordinate weights of the cost metric (for nearest-neighbour embeddings)."""
        return (1.0, 1.0, float(self.angle_weight))

    def config_bounds(self, world: World):
        lo = jnp.concatenate([world.bounds[:, 0], jnp.array([-jnp.pi], jnp.float32)])
        hi = jnp.concatenate([world.bounds[:, 1], jnp.array([jnp.pi], jnp.float32)])
        return lo, hi

    def is_valid(self, q: Array, world: World, padding: float) -> Array:
        """Footprint in the workspace and clear of obstacles, at theta reduced to ``[-pi, pi)``
        (:func:`reduce_angle`); False for non-finite ``q`` or ``|theta| >= ANGLE_LIMIT``."""
        return geometry.rect_free(_reduced(q), 0.5 * self.length, 0.5 * self.width, world, padding)

    def interpolate(self, a: Array, b: Array, t: Array) -> Array:
        a2 = reduce_angle(a[2])
        dth = wrap_angle(reduce_angle(b[2]) - a2)
        pos = a[:2] + t * (b[:2] - a[:2])
        return jnp.concatenate([pos, wrap_angle(a2 + t * dth)[None]])

    def distance(self, a: Array, b: Array) -> Array:
        dx, dy = b[0] - a[0], b[1] - a[1]
        dth = wrap_angle(reduce_angle(b[2]) - reduce_angle(a[2]))
        return jnp.sqrt(dx * dx + dy * dy) + self.angle_weight * jnp.abs(dth)

    def clearance(self, q: Array, world: World, padding: float) -> Array:
        """Distance of the footprint to the nearest obstacle minus ``padding``, or to the
        workspace boundary if smaller (negative outside); ``> 0`` iff ``q`` is valid, -1 for
        non-finite ``q`` or ``|theta| >= ANGLE_LIMIT``; theta is reduced as in :meth:`is_valid`."""
        hl, hw = 0.5 * self.length, 0.5 * self.width
        q = _reduced(q)
        c = geometry.rect_clearance(q, hl, hw, world, padding) - padding
        xs, ys = geometry.rect_corners(q[0], q[1], q[2], hl, hw)
        for px, py in zip(xs, ys):
            c = jnp.minimum(c, geometry.wall_clearance(px, py, world.bounds))
        return jnp.where(jnp.isfinite(q[0] + q[1] + q[2]) & jnp.isfinite(c), c, -1.0)

    def part_clearances(self, q: Array, world: World, padding: float) -> Array:
        """``(1,)``: the body is one part (see :mod:`ntq_jax.robots.certified`)."""
        return self.clearance(q, world, padding)[None]

    def part_sweep_bounds(self, a: Array, b: Array) -> Array:
        """``(1,)``: :meth:`sweep_bound`."""
        return self.sweep_bound(a, b)[None]

    def sweep_bound(self, a: Array, b: Array) -> Array:
        """Upper bound on how far any point of the body moves from ``a`` to ``b``:
        ``|dp| + r_max |dtheta|`` (shortest arc)."""
        dx, dy = b[0] - a[0], b[1] - a[1]
        dth = wrap_angle(reduce_angle(b[2]) - reduce_angle(a[2]))
        return jnp.sqrt(dx * dx + dy * dy) + self.half_diagonal * jnp.abs(dth)

    def to_json(self) -> dict:
        return {
            "kind": "rigid_body",
            "length": self.length,
            "width": self.width,
            "angle_weight": self.angle_weight,
            "resolution": self.resolution,
        }
