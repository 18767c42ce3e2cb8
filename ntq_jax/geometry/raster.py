"""Rasterisation of a world onto a grid, and conversions between cells and workspace points."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.geometry.shapes import point_free
from ntq_jax.geometry.world import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.validation import check_positive

Array = jax.Array


# ---------------------------------------------------------------------------
# Rasterisation
# ---------------------------------------------------------------------------


def rasterize(world: World, resolution: float, padding: float = 0.0) -> np.ndarray:
    """Occupancy grid of the workspace: cell ``[i, j]`` covers ``y`` row ``i``, ``x`` column ``j``.

    A cell is occupied when its centre is in collision (``point_free`` is False)
    at the given padding. Returns a NumPy bool array of shape ``(H, W)`` with
    ``W = round((xmax - xmin) / resolution)``; cell ``(i, j)`` has centre
    ``(xmin + (j + 0.5) * resolution, ymin + (i + 0.5) * resolution)``.
    """
    resolution = check_positive("resolution", resolution)
    b = np.asarray(world.bounds, dtype=np.float64)
    w = int(round((b[0, 1] - b[0, 0]) / resolution))
    h = int(round((b[1, 1] - b[1, 0]) / resolution))
    xs = b[0, 0] + (np.arange(w) + 0.5) * resolution
    ys = b[1, 0] + (np.arange(h) + 0.5) * resolution
    gx, gy = np.meshgrid(xs, ys)
    pts = jnp.asarray(np.stack([gx.ravel(), gy.ravel()]), jnp.float32)
    free = _points_free_cm(pts, world, float(padding))
    return ~np.asarray(free).reshape(h, w)


def cell_centers(world: World, resolution: float, cells: np.ndarray) -> np.ndarray:
    """Maps integer cells ``(..., 2)`` as ``(row, col)`` to workspace points ``(..., 2)`` as ``(x, y)``."""
    b = np.asarray(world.bounds, dtype=np.float64)
    cells = np.asarray(cells)
    x = b[0, 0] + (cells[..., 1] + 0.5) * resolution
    y = b[1, 0] + (cells[..., 0] + 0.5) * resolution
    return np.stack([x, y], axis=-1)


def point_to_cell(world: World, resolution: float, points: np.ndarray) -> np.ndarray:
    """Maps workspace points ``(..., 2)`` to integer cells ``(..., 2)`` as ``(row, col)``."""
    b = np.asarray(world.bounds, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    col = np.floor((p[..., 0] - b[0, 0]) / resolution).astype(np.int32)
    row = np.floor((p[..., 1] - b[1, 0]) / resolution).astype(np.int32)
    return np.stack([row, col], axis=-1)


@functools.partial(jax.jit, static_argnames=("padding",), compiler_options=KERNEL_COMPILER_OPTIONS)
def _points_free_cm(pts: Array, world: World, padding: float) -> Array:
    return jax.vmap(point_free, in_axes=(1, None, None))(pts, world, padding)
