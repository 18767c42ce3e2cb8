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
        return geometry.rect_free(q, 0.5 * self.length, 0.5 * self.width, world, padding)

    def interpolate(self, a: Array, b: Array, t: Array) -> Array:
        dth = wrap_angle(b[2] - a[2])
        pos = a[:2] + t * (b[:2] - a[:2])
        return jnp.concatenate([pos, wrap_angle(a[2] + t * dth)[None]])

    def distance(self, a: Array, b: Array) -> Array:
        dx, dy = b[0] - a[0], b[1] - a[1]
        return jnp.sqrt(dx * dx + dy * dy) + self.angle_weight * jnp.abs(wrap_angle(b[2] - a[2]))

    def clearance(self, q: Array, world: World, padding: float) -> Array:
        """Distance of the footprint to the nearest obstacle minus ``padding``, or to the
        workspace boundary if smaller (negative outside); ``> 0`` iff ``q`` is valid, -1 for
        non-finite ``q``."""
        hl, hw = 0.5 * self.length, 0.5 * self.width
        c = geometry.rect_clearance(q, hl, hw, world) - padding
        xs, ys = geometry.rect_corners(q[0], q[1], q[2], hl, hw)
        for px, py in zip(xs, ys):
            c = jnp.minimum(c, geometry.wall_clearance(px, py, world.bounds))
        return jnp.where(jnp.isfinite(q[0] + q[1] + q[2]) & jnp.isfinite(c), c, -1.0)

    def sweep_bound(self, a: Array, b: Array) -> Array:
        """Upper bound on how far any point of the body moves from ``a`` to ``b``:
        ``|dp| + r_max |dtheta|`` (shortest arc)."""
        dx, dy = b[0] - a[0], b[1] - a[1]
        return jnp.sqrt(dx * dx + dy * dy) + self.half_diagonal * jnp.abs(wrap_angle(b[2] - a[2]))

    def to_json(self) -> dict:
        return {"kind": "rigid_body", "length": self.length, "width": self.width,
                "angle_weight": self.angle_weight, "resolution": self.resolution}
