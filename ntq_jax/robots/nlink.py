"""Planar n-link arm: the state is the joint angles, each in ``[-pi, pi]`` (no wrap-around).

* Forward kinematics: link ``k`` starts where link ``k - 1`` ends, at absolute
  angle ``q_1 + ... + q_k`` from the x axis, from ``base``.
* Valid when every joint is in ``[-pi, pi]``, every joint position is inside
  the workspace and every link segment is farther than ``padding`` from every
  obstacle (exact segment tests). Links are not tested against each other (the
  paper does not say; we read the planar arm as links in stacked planes that may cross).
* Steering: straight line in joint space; cost metric: Euclidean joint distance
  (OMPL's RealVector metric, which BIT* minimises).
* ``steer_to`` checks states at most ``resolution`` apart (Euclidean, radians).
  Between two checked states a point at distance ``r`` from the base moves at
  most ``r * sqrt(n) * resolution <= reach * sqrt(n) * resolution`` in the
  workspace, so penetrations deeper than that are always found.
* ``certified_steer_to_batch`` (:mod:`ntq_jax.robots.certified`) proves every
  configuration of a motion clear instead, from :meth:`NLinkArm.clearance`
  and the sweep bound ``sum_j R_j |dq_j|`` (``R_j`` the reach beyond joint j).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from ntq_jax import geometry, validation
from ntq_jax.geometry import World
from ntq_jax.robots.base import DiscretizedSteering
from ntq_jax.robots.certified import CertifiedSteering

Array = jax.Array


@dataclasses.dataclass(frozen=True)
class NLinkArm(DiscretizedSteering, CertifiedSteering):
    """Planar serial arm with revolute joints."""

    link_lengths: tuple[float, ...] = (3.0, 3.0)
    base: tuple[float, float] = (0.0, 0.0)
    resolution: float = 0.02
    kind: str = dataclasses.field(default="nlink", init=False)

    def __post_init__(self):
        lengths = validation.number_list(
            self.link_lengths,
            "nlink.link_lengths",
            "[l1, l2, ...] of link lengths > 0",
            min_length=1,
        )
        for i, v in enumerate(lengths):
            if not v > 0:
                raise ValueError(f"nlink.link_lengths[{i}] is {v:g}: link lengths must be > 0")
        base = validation.number_list(self.base, "nlink.base", "[x, y]", length=2)
        object.__setattr__(self, "link_lengths", lengths)
        object.__setattr__(self, "base", base)
        object.__setattr__(
            self,
            "resolution",
            validation.number(self.resolution, "nlink.resolution", minimum=0, strict=True),
        )

    def longest_motion(self, world: World) -> float:
        """The longest motion between two valid states in the cost metric (radians): the
        diagonal ``2 pi sqrt(n)`` of the joint box ``[-pi, pi]^n`` (the bound of
        ``resolution``, see :func:`ntq_jax.envs.check_resolution`)."""
        return 2.0 * math.pi * math.sqrt(len(self.link_lengths))

    @property
    def dim(self) -> int:
        return len(self.link_lengths)

    @property
    def reach(self) -> float:
        return float(sum(self.link_lengths))

    @property
    def periodic(self) -> tuple[bool, ...]:
        """Which state coordinates wrap around: joint angles in [-pi, pi] do not wrap (as in the paper)."""
        return (False,) * len(self.link_lengths)

    @property
    def metric_weights(self) -> tuple[float, ...]:
        """Per-coordinate weights of the cost metric (for nearest-neighbour embeddings)."""
        return (1.0,) * len(self.link_lengths)

    def config_bounds(self, world: World):
        n = self.dim
        return jnp.full((n,), -jnp.pi, jnp.float32), jnp.full((n,), jnp.pi, jnp.float32)

    def joint_xy(self, q: Array) -> tuple[list[Array], list[Array]]:
        """Joint positions as two lists of ``n + 1`` scalars (x's and y's): base, then link ends."""
        x, y = jnp.float32(self.base[0]), jnp.float32(self.base[1])
        xs, ys = [x], [y]
        phi = jnp.float32(0.0)
        for k, length in enumerate(self.link_lengths):
            phi = phi + q[k]
            sin, cos = geometry.sincos(phi)
            x = x + length * cos
            y = y + length * sin
            xs.append(x)
            ys.append(y)
        return xs, ys

    def forward_kinematics(self, q: Array) -> Array:
        """Joint positions ``(n + 1, 2)``: the base, then the end of each link."""
        xs, ys = self.joint_xy(q)
        return jnp.stack([jnp.stack(xs), jnp.stack(ys)], axis=1)

    def is_valid(self, q: Array, world: World, padding: float) -> Array:
        """Joints in ``[-pi, pi]``, joint positions in the workspace, links clear of obstacles.

        Works on the scalar joint positions of :meth:`joint_xy`, not on the stacked
        ``forward_kinematics`` array: stacked, XLA computes each joint position in
        its own fused loop and recomputes every earlier link's sine and cosine in
        it (measurably slower with many links).
        """
        ok = jnp.all(jnp.isfinite(q)) & jnp.all(jnp.abs(q) <= jnp.pi)
        xs, ys = self.joint_xy(q)
        ok = ok & geometry.in_bounds(xs[0], ys[0], world.bounds)
        for k in range(self.dim):
            ok = ok & geometry.segment_free(
                jnp.stack([xs[k], ys[k]]),
                jnp.stack([xs[k + 1], ys[k + 1]]),
                world,
                padding,
                check_bounds=False,
            )
            ok = ok & geometry.in_bounds(xs[k + 1], ys[k + 1], world.bounds)
        return ok

    def part_clearances(self, q: Array, world: World, padding: float) -> Array:
        """``(n,)``, per link: its distance to the nearest obstacle minus ``padding``, or of
        its end joint (link 1: also the base) to the workspace boundary if smaller (negative
        outside); all ``> 0`` iff ``q`` is valid, all -1 for non-finite ``q`` or a joint
        outside ``[-pi, pi]``."""
        xs, ys = self.joint_xy(q)
        base = geometry.wall_clearance(xs[0], ys[0], world.bounds)
        parts = []
        for k in range(self.dim):
            c = jnp.minimum(
                geometry.segment_clearance(xs[k], ys[k], xs[k + 1], ys[k + 1], world, padding)
                - padding,
                geometry.wall_clearance(xs[k + 1], ys[k + 1], world.bounds),
            )
            parts.append(jnp.minimum(c, base) if k == 0 else c)
        c = jnp.stack(parts)
        ok = jnp.all(jnp.isfinite(q)) & jnp.all(jnp.abs(q) <= jnp.pi) & jnp.all(jnp.isfinite(c))
        return jnp.where(ok, c, -1.0)

    def part_sweep_bounds(self, a: Array, b: Array) -> Array:
        """``(n,)``, per link k: ``sum_{j <= k} R_jk |dq_j|`` with ``R_jk`` the length of links
        ``j..k``, an upper bound on how far any point of link k moves from ``a`` to ``b``."""
        dq = [jnp.abs(b[j] - a[j]) for j in range(self.dim)]
        out = []
        for k in range(self.dim):
            total = jnp.float32(0.0)
            for j in range(k + 1):
                total = total + float(sum(self.link_lengths[j : k + 1])) * dq[j]
            out.append(total)
        return jnp.stack(out)

    def clearance(self, q: Array, world: World, padding: float) -> Array:
        """Distance of the links to the nearest obstacle minus ``padding``, or of a joint to
        the workspace boundary if smaller (negative outside); ``> 0`` iff ``q`` is valid,
        -1 for non-finite ``q`` or a joint outside ``[-pi, pi]``."""
        return jnp.min(self.part_clearances(q, world, padding))

    def sweep_bound(self, a: Array, b: Array) -> Array:
        """Upper bound on how far any point of the arm moves from ``a`` to ``b``:
        ``sum_j R_j |dq_j|``, ``R_j`` the total length of links ``j..n``."""
        total = jnp.float32(0.0)
        reach = 0.0
        for j in reversed(range(self.dim)):
            reach += self.link_lengths[j]
            total = total + reach * jnp.abs(b[j] - a[j])
        return total

    def interpolate(self, a: Array, b: Array, t: Array) -> Array:
        return a + t * (b - a)

    def distance(self, a: Array, b: Array) -> Array:
        return jnp.sqrt(jnp.sum((b - a) ** 2))

    def to_json(self) -> dict:
        return {
            "kind": "nlink",
            "link_lengths": list(self.link_lengths),
            "base": list(self.base),
            "resolution": self.resolution,
        }
