"""Batched, jitted versions of the single-state robot kernels.

Inputs are row-major ``(N, d)`` arrays, as users hold them. Inside the compiled
function they are transposed to coordinate-major ``(d, N)`` and the one-state
kernels are vmapped over the minor axis, so XLA emits one fused elementwise loop
over contiguous rows (the layout the kernels are fast in).

:func:`steer_to_pairs`, :func:`valid_states` and :func:`distances` take host
arrays of any length and run them through one compiled program of a fixed
chunk size (the tail padded and masked): the batched entry points of every
stage above the kernels (includeData, path verification, snapping, ...).
:func:`steer_rows`, :func:`valid_rows` and :func:`distance_rows` (what ``Env``
calls) run any number of rows in pieces of a few power-of-two sizes, read in
place (:mod:`ntq_jax.robots.rows`): full speed at every batch size.

The robot and the padding are static (hashable) arguments; the world is traced,
so a different map with the same obstacle counts reuses the compiled code. The
entry points compile with :data:`ntq_jax.geometry.KERNEL_COMPILER_OPTIONS`.
"""

from __future__ import annotations

import functools

import jax
import numpy as np

from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.robots import rows
from ntq_jax.robots.certified import MOTION_CHECKS
from ntq_jax.robots.rows import (
    RowPlan,
    aligned_head,
    aligned_period,
    host_rows,
    plan_rows,
    run_rows,
)

Array = jax.Array

_kernel_jit = functools.partial(jax.jit, compiler_options=KERNEL_COMPILER_OPTIONS)


@functools.partial(_kernel_jit, static_argnames=("robot", "padding"))
def is_valid_batch(robot, world: World, states: Array, padding: float) -> Array:
    """``(N, d) -> (N,)`` bool."""
    return jax.vmap(robot.is_valid, in_axes=(1, None, None))(states.T, world, padding)


def motion_check(robot, check: str):
    """The coordinate-major batched motion check ``check`` of ``robot``.

    ``"discretized"``: ``robot.steer_to_batch`` (states ``resolution`` apart, the
    paper's check; exact for the point robot). ``"certified"``:
    ``robot.certified_steer_to_batch`` (every configuration proven clear, see
    :mod:`ntq_jax.robots.certified`; the point robot's exact test is already that).
    """
    if check == "discretized":
        return robot.steer_to_batch
    if check == "certified":
        return robot.certified_steer_to_batch
    raise ValueError(f"check must be one of {MOTION_CHECKS}, got {check!r}")


@functools.partial(_kernel_jit, static_argnames=("robot", "padding", "check"))
def _steer_to_batch(robot, world: World, a: Array, b: Array, padding: float, check: str) -> Array:
    return motion_check(robot, check)(a.T, b.T, world, padding)


def steer_to_batch(
    robot, world: World, a: Array, b: Array, padding: float, check: str = "discretized"
) -> Array:
    """``(N, d), (N, d) -> (N,)`` bool, True where the connection is collision-free.

    ``check``: see :func:`motion_check`. One compiled program per robot, padding,
    check and shape, however the arguments are passed.
    """
    return _steer_to_batch(robot, world, a, b, padding, check)


@functools.partial(_kernel_jit, static_argnames=("robot",))
def distance_batch(robot, a: Array, b: Array) -> Array:
    """``(N, d), (N, d) -> (N,)`` cost-metric distances."""
    return jax.vmap(robot.distance, in_axes=(1, 1))(a.T, b.T)


def is_valid_cm(robot, world: World, states_cm: Array, padding: float) -> Array:
    """Coordinate-major ``(d, N) -> (N,)``, for use inside other jitted code."""
    return jax.vmap(robot.is_valid, in_axes=(1, None, None))(states_cm, world, padding)


def steer_to_cm(
    robot,
    world: World,
    a_cm: Array,
    b_cm: Array,
    padding: float,
    mask: Array | None = None,
    check: str = "discretized",
) -> Array:
    """Coordinate-major ``(d, N), (d, N) -> (N,)``, for use inside other jitted code.

    ``mask`` (optional, ``(N,)`` bool): only these connections are checked, the
    others are reported blocked (False) without any work. ``check``: see
    :func:`motion_check`.
    """
    return motion_check(robot, check)(a_cm, b_cm, world, padding, mask)


STEER_CHUNK = 8192  # pairs per compiled call of steer_to_pairs (discretised check)
#: Pairs per compiled call of the certified check (:func:`steer_to_pairs` and
#: ``Env.steer_to(check="certified")`` alike): its program is large and costly to
#: compile, so every caller shares this one shape per (robot, map, padding); a call
#: checks a thousand motions, so the chunk's dispatch is a negligible share of it.
CERTIFIED_CHUNK = 1024
#: Pairs per compiled call of ``Env.steer_to(check="certified")`` on large batches: its
#: work queue's fixed cost per call (the sweep's two phases run until the call's slowest
#: motion is decided) is then shared by 16 times more motions than in a
#: :data:`CERTIFIED_CHUNK` call; the second (and last) compiled shape of the check.
CERTIFIED_PIECE = 16384
CHECK_CHUNK = 2048  # states per compiled call of valid_states / distances


@functools.partial(_kernel_jit, static_argnames=("robot", "padding", "check"))
def _steer_masked(
    robot, world: World, a: Array, b: Array, mask: Array, padding: float, check: str
) -> Array:
    return steer_to_cm(robot, world, a.T, b.T, padding, mask=mask, check=check)


def _float_rows(x, dim: int) -> np.ndarray:
    """``x`` as a C-contiguous float32 ``(N, dim)`` host array (in place where it can be)."""
    rows = host_rows(x)
    if rows is None:
        rows = np.ascontiguousarray(np.asarray(x, np.float32))
    return rows.reshape(-1, dim)


def _float_pairs(a, b, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_float_rows` of both ends of a batch of pairs, which must have the same rows."""
    a, b = _float_rows(a, dim), _float_rows(b, dim)
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    return a, b


def _fixed(chunk: int, arrays) -> RowPlan:
    """Pieces of exactly ``chunk`` rows, the rest padded to ``chunk`` (one compiled shape;
    unaligned pieces when aligning them would leave more than ``chunk`` edge rows)."""
    n = arrays[0].shape[0]
    plan = plan_rows(n, aligned_head(arrays), chunk, chunk, chunk)
    return plan if plan.bucket <= chunk else plan_rows(n, 0, chunk, chunk, chunk)


def _certified(arrays) -> RowPlan:
    """Pieces of :data:`CERTIFIED_PIECE`, then of :data:`CERTIFIED_CHUNK` rows, the rest
    padded to ``CERTIFIED_CHUNK``: two compiled shapes of the costly certified program."""
    n = arrays[0].shape[0]
    head = aligned_head(arrays) if n > CERTIFIED_CHUNK else 0
    plan = plan_rows(n, head, CERTIFIED_PIECE, CERTIFIED_CHUNK, CERTIFIED_CHUNK, two_sizes=True)
    if plan.bucket > CERTIFIED_CHUNK:  # the head rows would overflow the edge: unaligned pieces
        plan = plan_rows(n, 0, CERTIFIED_PIECE, CERTIFIED_CHUNK, CERTIFIED_CHUNK, two_sizes=True)
    return plan


def _flexible(arrays, robot=None) -> RowPlan:
    """Pieces of :data:`~ntq_jax.robots.rows.PIECE_MIN` to ``PIECE_MAX`` rows (or the
    robot's ``row_piece_max``, when it has one and it is smaller) and an edge padded by
    less than a quarter (a few compiled shapes per power of two)."""
    n = arrays[0].shape[0]
    top = min(rows.PIECE_MAX, getattr(robot, "row_piece_max", rows.PIECE_MAX))
    top = max(rows.PIECE_MIN, top)
    if n < rows.PIECE_MIN:
        return plan_rows(n, 0, top, rows.PIECE_MIN)
    return plan_rows(n, aligned_head(arrays), top, rows.PIECE_MIN, period=aligned_period(arrays[0]))


def steer_rows(
    robot,
    world: World,
    a: np.ndarray,
    b: np.ndarray,
    padding: float,
    check: str = "discretized",
    whole: tuple[Array, Array] | None = None,
) -> Array:
    """``steer_to`` of host ``(N, d)`` float32 pairs (:func:`~ntq_jax.robots.rows.host_rows`)
    as a JAX array, not waited for (see :func:`~ntq_jax.robots.rows.run_rows`).

    The discretised check runs in pieces of a few power-of-two sizes; the certified
    check in pieces of :data:`CERTIFIED_PIECE` and :data:`CERTIFIED_CHUNK` rows (its two
    compiled shapes; the second shared with :func:`steer_to_pairs`). Padded rows are masked out: they cost no checks.
    ``whole``: ``a`` and ``b`` as the JAX arrays they are views of, if they are
    (see :func:`~ntq_jax.robots.rows.run_rows`).
    """
    plan = _certified([a, b]) if check == "certified" else _flexible([a, b], robot)
    return run_rows(
        lambda x, y, m: _steer_masked(robot, world, x, y, m, padding, check), [a, b], plan, whole
    )


def valid_rows(
    robot, world: World, states: np.ndarray, padding: float, whole: tuple[Array] | None = None
) -> Array:
    """``is_valid`` of host ``(N, d)`` float32 states as a JAX array (as :func:`steer_rows`)."""
    return run_rows(
        lambda x, m: is_valid_batch(robot, world, x, padding),
        [states],
        _flexible([states], robot),
        whole,
    )


def distance_rows(
    robot, a: np.ndarray, b: np.ndarray, whole: tuple[Array, Array] | None = None
) -> Array:
    """The cost metric of host ``(N, d)`` float32 pairs as a JAX array (as :func:`steer_rows`)."""
    return run_rows(
        lambda x, y, m: distance_batch(robot, x, y), [a, b], _flexible([a, b], robot), whole
    )


def steer_to_pairs(
    robot, world: World, a, b, padding: float, chunk: int | None = None, check: str = "discretized"
) -> np.ndarray:
    """``steer_to`` over any number of ``(N, d)`` pairs in fixed-size compiled chunks.

    ``chunk``: pairs per compiled call; None = :data:`CERTIFIED_CHUNK` for the
    certified check, :data:`STEER_CHUNK` for the discretised one. The answers do
    not depend on it.

    Returns ``(N,)`` bool (host), True where the straight connection is
    collision-free by the motion check ``check`` (see :func:`motion_check`).
    """
    motion_check(robot, check)  # an unknown check fails here, before any work
    if chunk is None:
        chunk = CERTIFIED_CHUNK if check == "certified" else STEER_CHUNK
    a, b = _float_pairs(a, b, robot.dim)
    if a.shape[0] == 0:
        return np.zeros(0, bool)
    out = run_rows(
        lambda x, y, m: _steer_masked(robot, world, x, y, m, padding, check),
        [a, b],
        _fixed(chunk, [a, b]),
        host=True,
    )
    return out.astype(bool)


def valid_states(
    robot, world: World, states, padding: float, chunk: int = CHECK_CHUNK
) -> np.ndarray:
    """``is_valid`` over any number of ``(N, d)`` states in fixed-size compiled chunks."""
    states = _float_rows(states, robot.dim)
    if states.shape[0] == 0:
        return np.zeros(0, bool)
    out = run_rows(
        lambda x, m: is_valid_batch(robot, world, x, padding),
        [states],
        _fixed(chunk, [states]),
        host=True,
    )
    return out.astype(bool)


def distances(robot, a, b, chunk: int = CHECK_CHUNK) -> np.ndarray:
    """The cost metric over any number of ``(N, d)`` pairs (float32 kernel, host array)."""
    a, b = _float_pairs(a, b, robot.dim)
    if a.shape[0] == 0:
        return np.zeros(0, np.float32)
    return run_rows(
        lambda x, y, m: distance_batch(robot, x, y), [a, b], _fixed(chunk, [a, b]), host=True
    )
