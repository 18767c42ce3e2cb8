"""What every robot provides, and the discretised ``steer_to`` shared by non-point robots.

A robot is a small, immutable, hashable description (a frozen dataclass with
only Python scalars and tuples), so it can be a static argument of ``jax.jit``.
Its methods are pure functions written for ONE state ``q`` of shape ``(d,)``;
:mod:`ntq_jax.robots.batch` vmaps them over coordinate-major batches.

Required methods (see :class:`Robot`): ``config_bounds``, ``is_valid``,
``interpolate``, ``distance`` (the cost metric), ``steer_to``, and its batched
form ``steer_to_batch`` (for the discretised robots a work queue,
:func:`discretized_steer_to_batch`, that gives the same answers much faster
than ``jax.vmap(steer_to)``).

Optional class attributes: ``row_piece_max`` (the largest in-place piece of a host
batch, :mod:`ntq_jax.robots.rows`) and ``shared_check_programs`` (True when the checks
cost seconds to compile: stages run the shared batched checks instead of fusing copies
of their own, e.g. :func:`ntq_jax.gamma.gamma_nt`'s chunks).
"""

from __future__ import annotations

import math
from typing import Protocol

import jax
import jax.numpy as jnp

from ntq_jax.geometry import World

Array = jax.Array


class Robot(Protocol):
    kind: str
    dim: int

    @property
    def periodic(self) -> tuple[bool, ...]:
        """``(d,)`` which state coordinates are angles that wrap around (the PNet's loss uses
        the shortest arc there)."""

    @property
    def metric_weights(self) -> tuple[float, ...]:
        """``(d,)`` per-coordinate weights ``w`` such that the Euclidean distance of
        ``w * q`` (angles on the circle) approximates the cost metric."""

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

    def steer_to_batch(
        self, a: Array, b: Array, world: World, padding: float, mask: Array | None = None
    ) -> Array:
        """``steer_to`` over coordinate-major ``(d, N)`` batches; ``mask`` False: blocked, unchecked."""

    def to_json(self) -> dict:
        """The robot's parameters in the environment JSON format."""


class DiscretizedSteering:
    """``steer_to`` for robots checked at states at most ``self.resolution`` apart.

    Mixed into the rigid body and the arm (frozen dataclasses with a
    ``resolution`` field): the single-motion check and its batched work queue.
    """

    def steer_to(self, a: Array, b: Array, world: World, padding: float) -> Array:
        return discretized_steer_to(self, a, b, world, padding, self.resolution)

    def steer_to_batch(
        self, a: Array, b: Array, world: World, padding: float, mask: Array | None = None
    ) -> Array:
        """Coordinate-major ``(d, N), (d, N) -> (N,)``: the same answers as ``steer_to``, batched."""
        return discretized_steer_to_batch(self, a, b, world, padding, self.resolution, mask)


def wrap_angle(a: Array) -> Array:
    """Wraps angles to ``[-pi, pi)``."""
    return jnp.mod(a + jnp.pi, 2.0 * jnp.pi) - jnp.pi


CHECK_STRIDE = 16  # coarse-to-fine order: every 16th state first, then the offsets 1..15
QUEUE_LANES = 512  # lanes of the batched work queue (see discretized_steer_to_batch)
CHECKS_PER_STEP = 8  # states each lane checks per iteration of the work queue


def _steps(robot, a: Array, b: Array, resolution: float) -> Array:
    """``n = ceil(distance / resolution)`` (>= 1) intervals; 0 for non-finite input."""
    dist = robot.distance(a, b)
    return jnp.where(jnp.isfinite(dist), jnp.maximum(jnp.ceil(dist / resolution), 1.0), 0.0).astype(
        jnp.int32
    )


def _check_index(c: Array, n: Array) -> Array:
    """The state checked ``c``-th (0-based) in the coarse-to-fine order of ``0..n``.

    The order visits ``o, o + S, o + 2 S, ...`` for ``o = 0, 1, ..., S - 1``
    (``S = CHECK_STRIDE``): a permutation of ``0..n``, so every state is checked
    exactly once, but a collision that spans ``S`` or more consecutive states is
    found within the first ``n / S + 1`` checks instead of wherever it lies along
    the path. Closed form, so any number of checks can be indexed at once: the
    pass ``o`` holds ``q + 1`` states for ``o <= n mod S`` and ``q = n // S``
    for the others, hence starts at ``o q + min(o, n mod S + 1)``.
    """
    q, r1 = n // CHECK_STRIDE, n % CHECK_STRIDE + 1
    o = jnp.zeros_like(c)
    for k in range(1, CHECK_STRIDE):
        o = o + (k * q + jnp.minimum(k, r1) <= c).astype(c.dtype)
    return o + CHECK_STRIDE * (c - (o * q + jnp.minimum(o, r1)))


def discretized_steer_to(
    robot, a: Array, b: Array, world: World, padding: float, resolution: float
) -> Array:
    """Checks the states at ``t = k / n``, ``k = 0..n``, ``n = ceil(distance(a, b) / resolution)``.

    Consecutive checked states are at most ``resolution`` apart in the robot's
    cost metric, endpoints included; the motion is free iff all of them are
    valid. They are checked in the coarse-to-fine order of :func:`_check_index`,
    and the loop stops at the first invalid one. Non-finite input is reported as
    blocked without looping. This is the one-query kernel (``jax.vmap`` runs
    every lane until the longest is done); batches go through
    :func:`discretized_steer_to_batch`, which gives the same answers.
    """
    n = _steps(robot, a, b, resolution)

    def cond(carry):
        k, ok = carry
        return ok & (k <= n)

    def body(carry):
        k, _ = carry
        t = _check_index(k, n).astype(a.dtype) / n.astype(a.dtype)
        return k + 1, robot.is_valid(robot.interpolate(a, b, t), world, padding)

    return jax.lax.while_loop(cond, body, (jnp.int32(0), n > 0))[1]


def _longest_first(n: Array) -> Array:
    """Indices ordering ``n`` (``(N,)`` int32, >= 0) from largest to smallest, approximately.

    One sort of packed int32 keys ``(n, index)`` (cheaper than ``argsort`` on
    CPU): the index takes ``ceil(log2 N)`` bits and ``n`` the rest,
    shifted right as far as needed to fit, so huge ``n`` (or huge ``N``) group into
    equal-key runs ordered by index. The work queue only needs roughly
    longest-first, to keep the tail short.
    """
    num = n.shape[0]
    idx_bits = max(1, (num - 1).bit_length())
    key_bits = 31 - idx_bits
    top_bits = 32 - jax.lax.clz(jnp.max(n))
    coarse = n >> jnp.maximum(top_bits - key_bits, 0)
    key = (((1 << key_bits) - 1 - coarse) << idx_bits) | jnp.arange(num, dtype=jnp.int32)
    return jax.lax.sort(key) & ((1 << idx_bits) - 1)


def flag_queue(flags: Array) -> tuple:
    """A queue for :func:`check_queue`'s ``queue`` of the motions where ``flags`` (``(N,)``
    bool) holds, in index order, without sorting or scattering ``N`` elements.

    The flags are packed into one 32-bit word per 32 motions, with a running count of
    set bits per word (elementwise work and a prefix sum over ``N / 32`` words).
    ``pick(pos)`` finds the word holding the ``pos``-th set flag by comparing ``pos``
    with the counts at the ends of about ``sqrt(N / 32)`` groups of words, then with
    the counts of the words of its group (two small vectorised comparisons, for the
    queue's few lanes at a time), and the flag within the word by a binary search
    over bit counts. Returns ``(pick, work)``, ``work`` the number of set flags.
    """
    num = flags.shape[0]
    words = -(-num // 32)
    f = jnp.pad(flags, (0, words * 32 - num)).reshape(words, 32)
    bit = jnp.left_shift(jnp.uint32(1), jnp.arange(32, dtype=jnp.uint32))
    word = jnp.sum(jnp.where(f, bit, jnp.uint32(0)), axis=1, dtype=jnp.uint32)
    ends = jnp.cumsum(jax.lax.population_count(word).astype(jnp.int32))  # set flags up to each word
    group = max(1, math.isqrt(words))
    groups = -(-words // group)
    grid = jnp.pad(ends, (0, groups * group - words), mode="edge").reshape(groups, group)
    group_ends = grid[:, -1]

    def pick(pos):
        p = pos[..., None]
        g = jnp.minimum(jnp.sum(group_ends <= p, axis=-1, dtype=jnp.int32), groups - 1)
        w = jnp.minimum(g * group + jnp.sum(grid[g] <= p, axis=-1, dtype=jnp.int32), words - 1)
        r = pos - (ends[w] - jax.lax.population_count(word[w]).astype(jnp.int32))
        bits, j = word[w], jnp.zeros_like(pos)
        for s in (16, 8, 4, 2, 1):  # the r-th set bit: the largest j with r set bits below it
            below = jax.lax.population_count(
                bits & (jnp.left_shift(jnp.uint32(1), (j + s).astype(jnp.uint32)) - 1)
            )
            j = jnp.where(below.astype(jnp.int32) <= r, j + s, j)
        return jnp.minimum(w * 32 + j, num - 1)

    return pick, ends[-1]


def discretized_steer_to_batch(
    robot,
    a: Array,
    b: Array,
    world: World,
    padding: float,
    resolution: float,
    mask: Array | None = None,
    lanes: int = QUEUE_LANES,
    per_step: int = CHECKS_PER_STEP,
) -> Array:
    """:func:`discretized_steer_to` for a coordinate-major batch ``(d, N), (d, N) -> (N,)``.

    Same states, same answers, scheduled as a work queue: ``lanes`` lanes each
    check the next ``per_step`` states (in the coarse-to-fine order) of their
    motion per iteration; a lane whose motion is decided (an invalid state, or
    all ``n + 1`` states valid) stores the answer and takes the next motion
    from the queue. A vmapped ``while_loop`` instead runs every lane as long as
    the slowest one, mostly checking nothing. Motions are queued longest first,
    which keeps the tail short. ``mask`` (optional, ``(N,)`` bool) selects the
    motions to check; the others, like non-finite ones, are reported blocked
    without any check. The compiled shape depends only on ``N``, ``lanes`` and
    ``per_step``.
    """
    d, num = a.shape
    if num == 0:
        return jnp.zeros((0,), bool)
    n = jax.vmap(_steps, in_axes=(None, 1, 1, None))(robot, a, b, resolution)
    interpolate = jax.vmap(
        jax.vmap(robot.interpolate, in_axes=(None, None, 0), out_axes=1),
        in_axes=(1, 1, 1),
        out_axes=2,
    )
    # traced once (jit) for the loop's two uses of it, then batched at each
    is_valid = jax.vmap(
        jax.vmap(jax.jit(robot.is_valid, static_argnums=2), in_axes=(1, None, None)),
        in_axes=(1, None, None),
    )

    def valid_at(ap, bp, t):
        return is_valid(interpolate(ap, bp, t), world, padding)

    return check_queue(a, b, n, valid_at, mask, lanes, per_step)


def check_queue(
    a: Array,
    b: Array,
    n: Array,
    valid_at,
    mask: Array | None = None,
    lanes: int = QUEUE_LANES,
    per_step: int = CHECKS_PER_STEP,
    queue: tuple | None = None,
    tail_lanes: int | None = None,
) -> Array:
    """The work queue of :func:`discretized_steer_to_batch` for any per-motion check.

    Motion ``i`` (columns of the coordinate-major ``a``, ``b`` ``(d, N)``) is free
    when ``valid_at`` holds at all ``t = k / n[i]``, ``k = 0..n[i]`` (in the
    coarse-to-fine order of :func:`_check_index`); ``n[i] = 0`` (or ``mask``
    False) reports it blocked unchecked. ``valid_at(ap, bp, t)`` gets the
    lanes' motions ``(d, lanes)`` and fractions ``t`` ``(per_step, lanes)`` and
    returns ``(per_step, lanes)`` bool.

    ``queue``: ``(pick, work)``, the queue given by the caller instead of the
    longest-first sort (e.g. :func:`flag_queue`): ``pick(pos)`` maps queue
    positions (int32, any shape) to motions, and positions ``0 .. work - 1`` must
    list, in any order, exactly the motions with ``n > 0`` (and ``mask``); the
    motions not listed are reported blocked. With a ``queue``, ``n`` may also be a
    function of the motions' indices (computed for the lanes' motions only).

    ``tail_lanes``: once the queue is empty and at most ``tail_lanes`` lanes still
    hold a motion, those motions move to ``tail_lanes`` lanes that each check
    ``per_step * lanes / tail_lanes`` states per iteration (the same states, so
    the same answers): the last long motions then take a few iterations instead of
    ``n / per_step`` iterations that each cost all ``lanes`` lanes' checks.
    """
    d, num = a.shape
    lanes = min(lanes, num)
    if mask is not None:
        n = jnp.where(mask, n, 0)
    if queue is None:
        order = _longest_first(
            n
        )  # the queue, longest motions first; the n = 0 ones (not checked) last
        work = jnp.sum(n > 0, dtype=jnp.int32)  # queue positions >= work hold nothing to check

        def pick(pos):
            return order[jnp.minimum(pos, num - 1)]
    else:
        pick, work = queue
    cache = queue is not None  # the lanes' motions carried through the loop, picked once
    if tail_lanes is None or tail_lanes >= lanes:
        return _queue_loop(a, b, n, valid_at, pick, work, per_step, lanes, cache=cache)
    _, pos, k, out = _queue_loop(
        a, b, n, valid_at, pick, work, per_step, lanes, stop_lanes=tail_lanes, cache=cache
    )
    # the (at most tail_lanes) lanes still busy, moved to the first tail lanes (the others idle)
    busy = pos < work
    slot = jnp.where(busy, jnp.cumsum(busy, dtype=jnp.int32) - 1, tail_lanes)
    pos = jnp.full((tail_lanes,), work, jnp.int32).at[slot].set(pos, mode="drop")
    k = jnp.zeros((tail_lanes,), jnp.int32).at[slot].set(k, mode="drop")
    return _queue_loop(
        a,
        b,
        n,
        valid_at,
        pick,
        work,
        per_step * lanes // tail_lanes,
        tail_lanes,
        (work, pos, k, out),
        cache=cache,
    )


def _queue_loop(
    a,
    b,
    n,
    valid_at,
    pick,
    work,
    per_step: int,
    lanes: int,
    state=None,
    stop_lanes: int | None = None,
    cache: bool = False,
):
    """The loop of :func:`check_queue`, from the first ``lanes`` motions of the queue or from
    ``state = (head, pos, k, out)``: until every lane is idle (returns ``out``), or
    (``stop_lanes``) until the queue is empty and at most ``stop_lanes`` lanes are busy
    (returns the state, the busy lanes' checks from ``k`` on still to do). ``cache``: the
    lanes' motions ``pick(pos)`` are carried through the loop instead of picked twice
    per iteration."""
    d, num = a.shape
    ahead = jnp.arange(per_step, dtype=jnp.int32)[:, None]

    def check(pos, k, i=None):
        """Validity ``(per_step, lanes)`` of the next ``per_step`` states of each lane's motion."""
        if i is None:
            i = pick(pos)
        nq = jnp.maximum(n(i) if callable(n) else n[i], 1)
        t = _check_index(k + ahead, nq).astype(a.dtype) / nq.astype(a.dtype)  # (per_step, lanes)
        # gathered one coordinate row at a time and broadcast over the checks, the
        # states stay coordinate-major with the lanes as the minor axis (d, per_step,
        # lanes): a flat (d, per_step * lanes) layout stops XLA from vectorising
        ap = jnp.stack([a[j][i] for j in range(d)])
        bp = jnp.stack([b[j][i] for j in range(d)])
        return valid_at(ap, bp, t)

    def cond(carry):
        if stop_lanes is None:
            return jnp.any(carry[1] < work)  # some lane still holds a motion
        busy = jnp.sum(carry[1] < work, dtype=jnp.int32)
        return (busy > 0) & ((carry[0] < work) | (busy > stop_lanes))

    def body(carry):
        # ``valid`` comes from the end of the previous iteration: as a loop-carried
        # value it is computed once, in one elementwise loop, where XLA would
        # otherwise fuse the validity test into each of its consumers below
        # (computing it twice, or inside the reduction)
        head, pos, k, valid, out = carry[:5]
        i = carry[5] if cache else pick(pos)
        nq = n(i) if callable(n) else n[i]
        ok = jnp.all(valid | (k + ahead > nq), axis=0)  # checks past the last state do not count
        done = (pos < work) & (~ok | (k + per_step > nq))
        out = out.at[jnp.where(done, i, num)].set(ok, mode="drop")
        # decided lanes take the next motions of the queue
        pos = jnp.where(done, head + jnp.cumsum(done, dtype=jnp.int32) - 1, pos)
        head = head + jnp.sum(done, dtype=jnp.int32)
        k = jnp.where(done, 0, k + per_step)
        if cache:
            i = pick(pos)
            return head, pos, k, check(pos, k, i), out, i
        return head, pos, k, check(pos, k), out

    if state is None:
        pos = jnp.arange(lanes, dtype=jnp.int32)
        state = (jnp.int32(lanes), pos, jnp.zeros_like(pos), jnp.zeros((num,), bool))
    head, pos, k, out = state
    # A boot iteration instead of a check before the loop (the program then holds the
    # validity test once, at the end of ``body``): every lane enters one step behind
    # with all of that step's states valid, so the first pass decides nothing (a lane
    # still holding a motion has ``k <= n``) and moves each lane on to ``k`` unchanged.
    boot = (head, pos, k - per_step, jnp.ones((per_step, lanes), bool), out)
    init = boot + (pick(pos),) if cache else boot
    head, pos, k_end, _, out = jax.lax.while_loop(cond, body, init)[:5]
    if stop_lanes is None:
        return out
    # a loop that never ran hands back its entry state, not the boot's step-behind ``k``
    return head, pos, jnp.where(cond(init), k_end, k), out
