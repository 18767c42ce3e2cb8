"""Point robot in R^2: the state is the position; steer_to is exact (continuous)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from ntq_jax import broadphase, geometry
from ntq_jax.geometry import World
from ntq_jax.robots.base import check_queue, flag_queue

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

    def steer_to_batch(
        self, a: Array, b: Array, world: World, padding: float, mask: Array | None = None
    ) -> Array:
        """Coordinate-major ``(2, N), (2, N) -> (N,)``; ``mask`` False reports blocked.

        On a world with a broad-phase index (:mod:`ntq_jax.broadphase`) the segments
        are first tested against the boxes near their two ends (all at once; most
        blocked segments of a cluttered map stop here), the rest run through the
        work queue of :func:`ntq_jax.robots.base.check_queue`: lane
        by lane, the index cells along each segment (points ``2 (reach - padding)``
        apart, coarse to fine), each an exact test of the whole segment against the
        cell's boxes, stopping at the first hit. Same answers as the per-segment test.

        When the index has a blocked-cell bitmap (:attr:`ntq_jax.broadphase.ObstacleIndex.blocked`,
        e.g. an imported occupancy grid), the first pass is the bitmap instead: a
        segment whose ends or one of :data:`BITMAP_SAMPLES` evenly spaced points lie
        well inside a cell that lies inside a box is blocked (one byte read per point,
        certain at any padding); only the others are queued (in index order,
        :func:`ntq_jax.robots.base.flag_queue`, without sorting the batch) for the
        exact test above, their cover steps computed for the queue's lanes only, and
        the last long motions finish on :data:`INDEXED_TAIL_LANES` lanes that check
        more cells per step. Same answers.
        """
        if broadphase.index_covers(world, padding, strict=True) and a.shape[1] > 0:
            return _indexed_steer_batch(a, b, world, padding, mask)
        free = jax.vmap(self.steer_to, in_axes=(1, 1, None, None))(a, b, world, padding)
        return free if mask is None else free & mask

    def certified_steer_to_batch(
        self, a: Array, b: Array, world: World, padding: float, mask: Array | None = None
    ) -> Array:
        """The certified check: the exact segment test already proves every point clear."""
        return self.steer_to_batch(a, b, world, padding, mask)

    def to_json(self) -> dict:
        return {"kind": "point"}


#: Index cells each lane of the point robot's broad-phase queue checks per iteration.
INDEXED_CHECKS_PER_STEP = 2

#: Lanes of the queue's tail (:func:`ntq_jax.robots.base.check_queue`) after the bitmap's first pass.
INDEXED_TAIL_LANES = 32

#: Points between the ends of each segment that the blocked-cell bitmap's first pass reads.
BITMAP_SAMPLES = 8


def _indexed_steer_batch(
    a: Array, b: Array, world: World, padding: float, mask: Array | None
) -> Array:
    """:meth:`PointRobot.steer_to_batch` through the broad phase (see there)."""
    x0, y0, x1, y1 = a[0], a[1], b[0], b[1]
    ok = (
        jnp.isfinite(x0 + y0 + x1 + y1)
        & geometry.in_bounds(x0, y0, world.bounds)
        & geometry.in_bounds(x1, y1, world.bounds)
    )
    if world.discs.shape[0]:
        disc_free = jax.vmap(
            lambda p, q: geometry.segment_free(
                p, q, dataclasses.replace(world, boxes=world.boxes[:0], index=None), padding
            ),
            in_axes=(1, 1),
        )(a, b)
        ok = ok & disc_free
    index = world.index
    mask = ok if mask is None else ok & mask
    hits = jax.vmap(
        jax.vmap(geometry.segment_hits_near, in_axes=(None, None, None, None, 0, None, None)),
        in_axes=(0, 0, 0, 0, 1, None, None),
        out_axes=1,
    )

    def valid_at(ap, bp, t):
        return ~hits(ap[0], ap[1], bp[0], bp[1], t, world, padding)

    if index.blocked is not None:
        # the bitmap's first pass: blocked where a sample point is certainly inside a box
        blocked = index.certainly_blocked(x0, y0) | index.certainly_blocked(x1, y1)
        for k in range(1, BITMAP_SAMPLES + 1):
            t = jnp.float32(k / (BITMAP_SAMPLES + 1))
            blocked = blocked | index.certainly_blocked(x0 + t * (x1 - x0), y0 + t * (y1 - y0))
        todo = mask & ~blocked  # finite, so n >= 1: n is computed for the queue's lanes only

        def steps(i):  # sliced here, inside the queue's loop: no copies of the rows
            return geometry.segment_cover_steps(
                a[0][i], a[1][i], b[0][i], b[1][i], index.reach, padding
            )

        return check_queue(
            a,
            b,
            steps,
            valid_at,
            per_step=INDEXED_CHECKS_PER_STEP,
            queue=flag_queue(todo),
            tail_lanes=INDEXED_TAIL_LANES,
        )
    # a cheap first pass over every segment: the boxes near its two ends (where most blocked
    # segments of a cluttered map are caught); only the others enter the work queue
    for t in (0.0, 1.0):
        ok = ok & ~jax.vmap(geometry.segment_hits_near, in_axes=(0, 0, 0, 0, None, None, None))(
            x0, y0, x1, y1, jnp.float32(t), world, padding
        )
    mask = ok & mask
    n = geometry.segment_cover_steps(x0, y0, x1, y1, index.reach, padding)
    return check_queue(a, b, n, valid_at, mask, per_step=INDEXED_CHECKS_PER_STEP)
