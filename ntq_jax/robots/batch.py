"""Batched, jitted versions of the single-state robot kernels.

Inputs are row-major ``(N, d)`` arrays, as users hold them. Inside the compiled
function they are transposed to coordinate-major ``(d, N)`` and the one-state
kernels are vmapped over the minor axis, so XLA emits one fused elementwise loop
over contiguous rows (the layout the kernels are fast in).

The robot and the padding are static (hashable) arguments; the world is traced,
so a different map with the same obstacle counts reuses the compiled code. The
entry points compile with :data:`ntq_jax.geometry.KERNEL_COMPILER_OPTIONS`.
"""

from __future__ import annotations

import functools

import jax

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
