"""Batched, jitted versions of the single-state robot kernels.

Inputs are row-major ``(N, d)`` arrays, as users hold them. Inside the compiled
function they are transposed to coordinate-major ``(d, N)`` and the one-state
kernels are vmapped over the minor axis, so XLA emits one fused elementwise loop
over contiguous rows (the layout the kernels are fast in).

:func:`steer_to_pairs`, :func:`valid_states` and :func:`distances` take host
arrays of any length and run them through one compiled program of a fixed
chunk size (the tail padded and masked): the batched entry points of every
stage above the kernels (includeData, path verification, snapping, ...).

The robot and the padding are static (hashable) arguments; the world is traced,
so a different map with the same obstacle counts reuses the compiled code. The
entry points compile with :data:`ntq_jax.geometry.KERNEL_COMPILER_OPTIONS`.
"""

from __future__ import annotations

import functools

import jax
import numpy as np

from ntq_jax.batching import map_chunks
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World

Array = jax.Array

_kernel_jit = functools.partial(jax.jit, compiler_options=KERNEL_COMPILER_OPTIONS)


@functools.partial(_kernel_jit, static_argnames=("robot", "padding"))
def is_valid_batch(robot, world: World, states: Array, padding: float) -> Array:
    """``(N, d) -> (N,)`` bool."""
    return jax.vmap(robot.is_valid, in_axes=(1, None, None))(states.T, world, padding)


@functools.partial(_kernel_jit, static_argnames=("robot", "padding"))
def steer_to_batch(robot, world: World, a: Array, b: Array, padding: float) -> Array:
    """``(N, d), (N, d) -> (N,)`` bool, True where the connection is collision-free."""
    return robot.steer_to_batch(a.T, b.T, world, padding)


@functools.partial(_kernel_jit, static_argnames=("robot",))
def distance_batch(robot, a: Array, b: Array) -> Array:
    """``(N, d), (N, d) -> (N,)`` cost-metric distances."""
    return jax.vmap(robot.distance, in_axes=(1, 1))(a.T, b.T)


def is_valid_cm(robot, world: World, states_cm: Array, padding: float) -> Array:
    """Coordinate-major ``(d, N) -> (N,)``, for use inside other jitted code."""
    return jax.vmap(robot.is_valid, in_axes=(1, None, None))(states_cm, world, padding)


def steer_to_cm(robot, world: World, a_cm: Array, b_cm: Array, padding: float,
                mask: Array | None = None) -> Array:
    """Coordinate-major ``(d, N), (d, N) -> (N,)``, for use inside other jitted code.

    ``mask`` (optional, ``(N,)`` bool): only these connections are checked, the
    others are reported blocked (False) without any work.
    """
    return robot.steer_to_batch(a_cm, b_cm, world, padding, mask)


STEER_CHUNK = 8192  # pairs per compiled call of steer_to_pairs
CHECK_CHUNK = 2048  # states per compiled call of valid_states / distances


@functools.partial(_kernel_jit, static_argnames=("robot", "padding"))
def _steer_masked(robot, world: World, a: Array, b: Array, mask: Array, padding: float) -> Array:
    return steer_to_cm(robot, world, a.T, b.T, padding, mask=mask)


def steer_to_pairs(robot, world: World, a, b, padding: float,
                   chunk: int = STEER_CHUNK) -> np.ndarray:
    """``steer_to`` over any number of ``(N, d)`` pairs in fixed-size compiled chunks.

    Returns ``(N,)`` bool (host), True where the straight connection is collision-free.
    """
    a = np.asarray(a, np.float32).reshape(-1, robot.dim)
    b = np.asarray(b, np.float32).reshape(-1, robot.dim)
    return map_chunks(lambda x, y, m: _steer_masked(robot, world, x, y, m, padding), a, b,
                      chunk=chunk, with_mask=True).astype(bool)


def valid_states(robot, world: World, states, padding: float,
                 chunk: int = CHECK_CHUNK) -> np.ndarray:
    """``is_valid`` over any number of ``(N, d)`` states in fixed-size compiled chunks."""
    states = np.asarray(states, np.float32).reshape(-1, robot.dim)
    return map_chunks(lambda x: is_valid_batch(robot, world, x, padding), states,
                      chunk=chunk).astype(bool)


def distances(robot, a, b, chunk: int = CHECK_CHUNK) -> np.ndarray:
    """The cost metric over any number of ``(N, d)`` pairs (float32 kernel, host array)."""
    a = np.asarray(a, np.float32).reshape(-1, robot.dim)
    b = np.asarray(b, np.float32).reshape(-1, robot.dim)
    return map_chunks(lambda x, y: distance_batch(robot, x, y), a, b, chunk=chunk,
                      empty=np.zeros(0, np.float32))
