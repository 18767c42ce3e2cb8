"""What every robot provides, and the discretised ``steer_to`` shared by non-point robots.

A robot is a small, immutable, hashable description (a frozen dataclass with
only Python scalars and tuples), so it can be a static argument of ``jax.jit``.
Its methods are pure functions written for ONE state ``q`` of shape ``(d,)``;
:mod:`ntq_jax.robots.batch` vmaps them over coordinate-major batches.

Required methods (see :class:`Robot`): ``config_bounds``, ``is_valid``,
``interpolate``, ``distance`` (the cost metric), ``steer_to``.
"""

from __future__ import annotations

from typing import Protocol

import jax
import jax.numpy as jnp

from ntq_jax.geometry import World

Array = jax.Array


class Robot(Protocol):
    kind: str
    dim: int

    def config_bounds(self, world: World) -> tuple[Array, Array]:
        """``(low, high)``, each ``(d,)``: the box that uniform sampling draws from."""

    def is_valid(self, q: Array, world: World, padding: float) -> Array:
        """True when ``q`` is finite, within the configuration bounds and collision-free."""

    def interpolate(self, a: Array, b: Array, t: Array) -> Array:
        """The state at fraction ``t`` in ``[0, 1]`` of the steering curve from ``a`` to ``b``."""

    def distance(self, a: Array, b: Array) -> Array:
        """The cost metric: length of the steering curve from ``a`` to ``b``."""

    def steer_to(self, a: Array, b: Array, world: World, padding: float) -> Array:
        """True when the steering curve from ``a`` to ``b`` is collision-free."""

    def to_json(self) -> dict:
        """The robot's parameters in the environment JSON format."""


def wrap_angle(a: Array) -> Array:
    """Wraps angles to ``[-pi, pi)``."""
    return jnp.mod(a + jnp.pi, 2.0 * jnp.pi) - jnp.pi


def discretized_steer_to(robot, a: Array, b: Array, world: World, padding: float,
                         resolution: float) -> Array:
    """Checks the states at ``t = k / n``, ``k = 0..n``, ``n = ceil(distance(a, b) / resolution)``.

    Consecutive checked states are at most ``resolution`` apart in the robot's
    cost metric, endpoints included. The loop stops at the first invalid state
    (under ``vmap`` it runs until every lane is done). Non-finite input is
    reported as blocked without looping.
    """
    dist = robot.distance(a, b)
    finite = jnp.isfinite(dist)
    n = jnp.where(finite, jnp.maximum(jnp.ceil(dist / resolution), 1.0), 0.0).astype(jnp.int32)

    def cond(carry):
        k, ok = carry
        return ok & (k <= n)

    def body(carry):
        k, _ = carry
        t = k.astype(a.dtype) / n.astype(a.dtype)
        return k + 1, robot.is_valid(robot.interpolate(a, b, t), world, padding)

    _, ok = jax.lax.while_loop(cond, body, (jnp.int32(0), finite))
    return ok
