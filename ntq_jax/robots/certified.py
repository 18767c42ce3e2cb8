"""Certified ``steer_to``: a motion is free only when every configuration on it is provably clear.

The discretised check (:mod:`ntq_jax.robots.base`) tests states ``resolution``
apart and can miss a shallow clip of an obstacle between two of them. This
check cannot. It uses the free-piece condition of clearance-based exact
collision checking (Schwarzer, Saha and Latombe, "Exact collision checking of
robot paths", 2002):

* ``c(q)``, the *clearance* of a part of the robot (``robot.part_clearances``;
  the rigid body is one part, the arm one part per link): its distance to the
  nearest obstacle minus the padding, or to the workspace boundary if that is
  nearer. All parts have ``c > 0`` exactly when ``q`` is valid.
* ``D(qa, qb)``, the part's *sweep bound* (``robot.part_sweep_bounds``): an
  upper bound on how far any of its points moves along the motion from ``qa``
  to ``qb``. The rigid body: ``|dp| + r_max |dtheta|`` (``r_max`` the
  rectangle's half diagonal); link ``k`` of the arm: ``sum_{j <= k} R_jk |dq_j|``
  (``R_jk`` the length of links ``j..k``). Both are linear in the motion's
  parameter, so a piece ``[t0, t1]`` of it moves at most ``(t1 - t0) D``.
* A piece is free when, for every part, ``c(q(t0)) + c(q(t1)) > (t1 - t0) D +
  margin``: a configuration in between is within ``(t - t0) D`` of the part's
  geometry at ``t0`` and within ``(t1 - t) D`` of it at ``t1``, and one of the
  two is less than that end's clearance. A configuration with ``c <= 0`` (an
  invalid state) makes the motion blocked.

:func:`certified_steer_to_batch` covers each motion with such pieces, sweeping
from the start (see there). ``margin`` (workspace units) absorbs float32
rounding in the clearances, the interpolated states and the bound, so a motion
that passes closer than about ``margin / 2`` to an obstacle is reported
blocked: the check errs only on the blocked side. The work per motion is
bounded: a motion still undecided after ``max_evals`` clearance evaluations (a
long pass within a hair of an obstacle) is reported **blocked**, never free.

Batches run as a work queue, like the discretised kernel: lanes each sweep one
motion, and a lane whose motion is decided takes the next one. Motions that the
endpoints' clearances alone prove free (short motions far from obstacles) never
enter the queue.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ntq_jax.geometry import World
from ntq_jax.robots.base import _longest_first

Array = jax.Array

CERT_LANES = 512  # lanes of the work queue's first phase (at most; see CERT_LANE_BYTES)
#: Bytes of per-part clearances (``points x parts x lanes`` float32) that the lanes of
#: either phase may hold per iteration: robots with many parts run fewer lanes (a power of
#: two, at least :data:`CERT_MIN_LANES`), so each iteration's clearances stay in the core's
#: cache. The Panda's 749 parts: 4 lanes in the first phase and 2 in the second, ~10x the
#: motions per CPU second of 512 and 32 lanes (12 MB and 3 MB per iteration); the rigid body
#: and the planar arms keep 512 and 32.
CERT_LANE_BYTES = 1 << 17
CERT_MIN_LANES = 2
CERT_POINTS = 8  # configurations each lane evaluates per iteration
CERT_GROWTH = (
    1.5  # initial step of the sweep: CERT_GROWTH * c(front) / D (see certified_steer_to_batch)
)
CERT_PHASE_STEPS = 48  # iterations per motion in the wide first phase
CERT_TAIL_LANES = 32  # lanes of the second phase (the few motions the first left undecided)
CERT_TAIL_POINTS = 32  # configurations per lane and iteration in the second phase
CERT_MAX_EVALS = 2048  # clearance evaluations per motion before it is reported blocked
CERT_MARGIN = 1e-3  # workspace units: float32 safety margin of the free test

MOTION_CHECKS = ("discretized", "certified")  # the values of every ``check=`` argument


class CertifiedSteering:
    """Mixin: :func:`certified_steer_to_batch` as a method, for robots with
    ``part_clearances`` and ``part_sweep_bounds``."""

    def certified_steer_to_batch(
        self, a: Array, b: Array, world: World, padding: float, mask: Array | None = None
    ) -> Array:
        """Coordinate-major ``(d, N), (d, N) -> (N,)``: True only for motions proven free."""
        return certified_steer_to_batch(self, a, b, world, padding, mask)


def certified_steer_to_batch(
    robot,
    a: Array,
    b: Array,
    world: World,
    padding: float,
    mask: Array | None = None,
    *,
    lanes: int = CERT_LANES,
    points: int = CERT_POINTS,
    growth: float = CERT_GROWTH,
    phase_steps: int = CERT_PHASE_STEPS,
    tail_lanes: int = CERT_TAIL_LANES,
    tail_points: int = CERT_TAIL_POINTS,
    max_evals: int = CERT_MAX_EVALS,
    margin: float = CERT_MARGIN,
) -> Array:
    """Certified ``steer_to`` over a coordinate-major batch ``(d, N), (d, N) -> (N,)`` bool.

    True only for motions proven collision-free at ``padding`` (see the module
    docstring). ``mask`` (optional, ``(N,)`` bool): the motions to check; the
    others, like non-finite ones, are reported blocked. The robot provides
    ``part_clearances(q, world, padding)`` and ``part_sweep_bounds(a, b)``, both
    ``(m,)``: the robot's geometry in ``m`` parts (the arm: one per link), each
    with its own clearance and its own bound on how far it moves; a piece of
    motion is free when the free test holds for every part. A part near the base
    moves little, so per-part bounds prove motions in fewer, longer pieces than
    the whole robot's single bound. The compiled shape depends only on ``N`` and
    the static arguments.

    Each lane sweeps its motion from the start: the *front* ``t0`` is the end of
    the proven part ``[0, t0]``. An iteration evaluates ``points`` configurations
    ahead of the front, ``h`` apart, and moves the front over every leading piece
    that the free test proves; the motion is free when the piece from the front
    to the goal is proven, blocked as soon as an evaluated configuration is
    invalid. The first iteration of a motion spreads its points evenly over
    ``[0, 1]`` (most blocked motions are found there); later ones step
    ``h = g min_parts(c(front) / D)`` with ``g`` starting at ``growth``, halved
    after an iteration that proves nothing (``g <= 1`` always proves the first
    piece, so the sweep cannot stall) and doubled after one that proves every
    piece. Free space is crossed in a few large steps; the steps shrink only
    where the robot passes close to an obstacle.

    Two phases keep the tail short: ``lanes`` lanes give each motion up to
    ``phase_steps`` iterations; the few left undecided (long passes close to
    obstacles) continue where they stopped on ``tail_lanes`` lanes evaluating
    ``tail_points`` configurations per iteration, until ``max_evals``
    configurations of the motion were evaluated in all, and are reported blocked
    if still undecided.
    """
    d, num = a.shape
    if num == 0:
        return jnp.zeros((0,), bool)
    part_clearances = jax.jit(robot.part_clearances, static_argnums=2)  # traced once, used 3 times
    clear = jax.vmap(part_clearances, in_axes=(1, None, None), out_axes=1)
    ca, cb = jnp.split(clear(jnp.concatenate([a, b], axis=1), world, padding), 2, axis=1)  # (m, N)
    dist = jax.vmap(robot.part_sweep_bounds, in_axes=(1, 1), out_axes=1)(a, b)  # (m, N)
    ok = jnp.all(ca > 0, axis=0) & jnp.all(cb > 0, axis=0) & jnp.all(jnp.isfinite(dist), axis=0)
    if mask is not None:
        ok = ok & mask
    easy = ok & jnp.all(ca + cb > dist + margin, axis=0)
    hard = ok & ~easy
    sweep = _Sweep(robot, part_clearances, a, b, world, padding, cb, dist, points, margin)
    g0 = jnp.full((num,), growth, a.dtype)
    lanes = min(lanes, cache_lanes(ca.shape[0], points))
    free, left, lo, clo, g = sweep.run(
        hard, jnp.zeros((num,), a.dtype), ca, g0, True, min(lanes, num), phase_steps
    )
    tail_steps = (max_evals - phase_steps * points) // tail_points
    if tail_steps > 0:
        tail = _Sweep(robot, part_clearances, a, b, world, padding, cb, dist, tail_points, margin)
        tail_lanes = min(tail_lanes, cache_lanes(ca.shape[0], tail_points), num)
        free2, left, _, _, _ = tail.run(left, lo, clo, g, False, tail_lanes, tail_steps)
        free = free | free2
    return easy | free


def cache_lanes(parts: int, points: int) -> int:
    """The most lanes (a power of two >= :data:`CERT_MIN_LANES`) whose ``points x parts``
    float32 clearances fit in :data:`CERT_LANE_BYTES`. Lanes only schedule the motions
    (each motion's sweep is its own), so the answers do not depend on them."""
    fit = max(1, CERT_LANE_BYTES // (4 * parts * points))
    return max(CERT_MIN_LANES, 1 << (fit.bit_length() - 1))


class _Sweep:
    """The sweep's work queue over one batch of motions (see :func:`certified_steer_to_batch`).

    Per-part arrays are ``(m, ...)``: clearances ``cb`` and bounds ``dist`` ``(m, N)``.
    """

    def __init__(self, robot, part_clearances, a, b, world, padding, cb, dist, points, margin):
        self.a, self.b, self.world, self.padding = a, b, world, padding
        self.cb, self.dist, self.points, self.margin = cb, dist, points, margin
        self.interpolate = jax.vmap(
            jax.vmap(robot.interpolate, in_axes=(None, None, 0), out_axes=1),
            in_axes=(1, 1, 1),
            out_axes=2,
        )
        # (d, points, lanes) -> (points, m, lanes)
        self.clear = jax.vmap(
            jax.vmap(part_clearances, in_axes=(1, None, None), out_axes=1),
            in_axes=(1, None, None),
            out_axes=0,
        )
        self.ks = jnp.arange(1, points + 1, dtype=a.dtype)[:, None]  # (points, 1)

    def ahead(self, i, lo, clo, g, first):
        """The next ``points`` configurations of the sweeps of motions ``i`` and their clearances."""
        room = jnp.min(clo / jnp.maximum(self.dist[:, i], 1e-30), axis=0)
        step = jnp.minimum(g * room, (1.0 - lo) / self.points)
        step = jnp.where(first, 1.0 / (self.points + 1), step)
        ts = jnp.minimum(lo + step * self.ks, 1.0)  # (points, lanes)
        d = self.a.shape[0]
        ap = jnp.stack([self.a[j][i] for j in range(d)])
        bp = jnp.stack([self.b[j][i] for j in range(d)])
        return ts, self.clear(self.interpolate(ap, bp, ts), self.world, self.padding)

    def run(self, todo, lo0, clo0, g0, first: bool, lanes: int, max_steps: int):
        """Sweeps the motions ``todo`` from their fronts ``lo0`` (clearances ``clo0`` ``(m, N)``,
        step factor ``g0``) for up to ``max_steps`` iterations each.

        Returns ``(free, undecided, lo, clo, g)``: the motions proven free, those still
        undecided, and where their sweeps stopped.
        """
        num = todo.shape[0]
        order = _longest_first(
            jnp.where(
                todo,
                1 + jnp.minimum(jnp.max(self.dist, axis=0) * 64.0, 2.0**30).astype(jnp.int32),
                0,
            )
        )
        work = jnp.sum(todo, dtype=jnp.int32)
        points, margin, dist, cb = self.points, self.margin, self.dist, self.cb

        def motion(pos):
            return order[jnp.minimum(pos, num - 1)]

        def cond(carry):
            return jnp.any(carry[1] < work)

        def body(carry):
            # ``ts, cs`` come from the end of the previous iteration: as loop-carried values
            # they are computed once, where XLA would otherwise fuse the clearance into each
            # of its consumers below and compute it several times
            head, pos, lo, clo, g, steps, ts, cs, free, left, out_lo, out_clo, out_g = carry
            live = pos < work
            i = motion(pos)
            di = dist[:, i]  # (m, lanes)
            steps = steps + 1
            hit = jnp.any(~(cs > 0), axis=(0, 1))
            # move the front over the proven leading pieces: piece k runs from point k - 1
            # (the front for k = 0) to point k; the front passes the first ``moved``
            prev_c = jnp.concatenate([clo[None], cs[:-1]], axis=0)  # (points, m, lanes)
            prev_t = jnp.concatenate([lo[None], ts[:-1]], axis=0)  # (points, lanes)
            proven = jnp.all(prev_c + cs > di * (ts - prev_t)[:, None] + margin, axis=1)
            moved = jnp.sum(jnp.cumsum(~proven, axis=0) == 0, axis=0, dtype=steps.dtype)
            last = jnp.maximum(moved - 1, 0)
            lo = jnp.where(moved > 0, jnp.take_along_axis(ts, last[None], axis=0)[0], lo)
            clo = jnp.where(moved > 0, jnp.take_along_axis(cs, last[None, None], axis=0)[0], clo)
            g = jnp.where(moved == 0, 0.5 * g, jnp.where(moved == points, 2.0 * g, g))
            ok = live & ~hit & jnp.all(clo + cb[:, i] > di * (1.0 - lo) + margin, axis=0)
            out_of_steps = live & ~ok & ~hit & (steps >= max_steps)
            done = live & (ok | hit | out_of_steps)
            at = jnp.where(done, i, num)
            free = free.at[at].set(ok, mode="drop")
            left = left.at[at].set(out_of_steps, mode="drop")
            out_lo = out_lo.at[at].set(lo, mode="drop")
            out_clo = out_clo.at[:, at].set(clo, mode="drop")
            out_g = out_g.at[at].set(g, mode="drop")
            # decided lanes take the next motions of the queue
            pos = jnp.where(done, head + jnp.cumsum(done, dtype=jnp.int32) - 1, pos)
            head = head + jnp.sum(done, dtype=jnp.int32)
            j = motion(pos)
            lo, clo, g = (
                jnp.where(done, lo0[j], lo),
                jnp.where(done, clo0[:, j], clo),
                jnp.where(done, g0[j], g),
            )
            steps = jnp.where(done, 0, steps)
            ts, cs = self.ahead(j, lo, clo, g, done & first)
            return head, pos, lo, clo, g, steps, ts, cs, free, left, out_lo, out_clo, out_g

        # A boot iteration: every lane starts on the queue's first motions with zero
        # clearances ahead, so the first pass through ``body`` decides each of them
        # "hit" (free False, left False; its other writes are placeholders) and its
        # lanes take the same motions afresh from lo0, clo0, g0, evaluating their first
        # points at the end of ``body``. The loop ends only once every motion it took
        # is decided for real, which rewrites all five outputs of that motion. The
        # program thus holds the clearance once per loop rather than once more here.
        pos = jnp.arange(lanes, dtype=jnp.int32)
        i = motion(pos)
        lo, clo, g = lo0[i], clo0[:, i], g0[i]
        no = jnp.zeros((num,), bool)
        m = clo0.shape[0]
        init = (
            jnp.int32(0),
            pos,
            lo,
            clo,
            g,
            jnp.zeros((lanes,), jnp.int32),
            jnp.zeros((points, lanes), lo0.dtype),
            jnp.zeros((points, m, lanes), clo0.dtype),
            no,
            no,
            lo0,
            clo0,
            g0,
        )
        out = jax.lax.while_loop(cond, body, init)
        return out[8:]
