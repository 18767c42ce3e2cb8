"""Point robot in R^2: the state is the position; steer_to is exact (continuous)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from ntq_jax import geometry
from ntq_jax.geometry import World

Array = jax.Array


@dataclasses.dataclass(frozen=True)
class PointRobot:
    """A point in the plane. Cost metric: Euclidean length."""

    kind: str = dataclasses.field(default="point", init=False)
    dim: int = dataclasses.field(default=2, init=False)

    @property
    def periodic(self) -> tuple[bool, ...]:
        """Which state coordinates wrap around: positions only."""
        return (False, False)

    @property
    def metric_weights(self) -> tuple[float, ...]:
        """Per-coordinate weights of the cost metric (for nearest-neighbour embeddings)."""
        return (1.0, 1.0)

    def config_bounds(self, world: World):
        return world.bounds[:, 0], world.bounds[:, 1]

    def is_valid(self, q: Array, world: World, padding: float) -> Array:
        return jnp.isfinite(q[0] + q[1]) & geometry.point_free(q, world, padding)

    def interpolate(self, a: Array, b: Array, t: Array) -> Array:
        return a + t * (b - a)

    def distance(self, a: Array, b: Array) -> Array:
        d = b - a
        return jnp.sqrt(d[0] * d[0] + d[1] * d[1])

    def steer_to(self, a: Array, b: Array, world: World, padding: float) -> Array:
        """Exact: the closed segment ``a -> b`` is farther than ``padding`` from every obstacle."""
        return geometry.segment_free(a, b, world, padding)

    def steer_to_batch(self, a: Array, b: Array, world: World, padding: float,
                       mask: Array | None = None) -> Array:
        """Coordinate-major ``(2, N), (2, N) -> (N,)``; ``mask`` False reports blocked."""
        free = jax.vmap(self.steer_to, in_axes=(1, 1, None, None))(a, b, world, padding)
        return free if mask is None else free & mask

    def certified_steer_to_batch(self, a: Array, b: Array, world: World, padding: float,
                                 mask: Array | None = None) -> Array:
        """The certified check: the exact segment test already proves every point clear."""
        return self.steer_to_batch(a, b, world, padding, mask)

    def to_json(self) -> dict:
        return {"kind": "point"}
