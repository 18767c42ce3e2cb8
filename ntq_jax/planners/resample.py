"""Resampling paths to a maximum waypoint spacing in the robot's metric.

Every segment ``(p_i, p_i+1)`` of cost ``c`` (the robot's ``distance``) is cut
into ``k = max(1, ceil(c / spacing))`` equal pieces by the robot's own
``interpolate`` (straight in position, shortest arc in a rigid body's angle),
so that

* every original waypoint is kept exactly (same float32 values), the new ones
  lie on the segments between them;
* consecutive waypoints are at most ``spacing`` apart (up to float32 rounding
  of the interpolation);
* the path's cost is unchanged (the metric is additive along an interpolated
  segment), up to that rounding.

This turns a shortcut path (a few corners) into one of BIT*-like density for
the data: includeData (Alg. 4) then records every intermediate step, and its
pruning drops the steps of the final straight run into the goal (they see the
goal), as in the paper's Fig. 1, instead of only the last one.
"""

from __future__ import annotations

import functools

import jax
import numpy as np

from ntq_jax.batching import map_chunks
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.robots.batch import CHECK_CHUNK, distances

__all__ = ["resample_paths", "segment_counts"]


@functools.partial(jax.jit, static_argnames=("robot",), compiler_options=KERNEL_COMPILER_OPTIONS)
def _interpolate_batch(robot, a, b, t):
    return jax.vmap(robot.interpolate)(a, b, t)


def segment_counts(robot, paths: np.ndarray, lengths: np.ndarray, spacing: float) -> np.ndarray:
    """``(B, L-1)`` int pieces per segment (0 past a path's end) for ``spacing``."""
    b, l, d = paths.shape
    seg = np.arange(max(l - 1, 0))[None, :] < (np.asarray(lengths)[:, None] - 1)
    rows, cols = np.nonzero(seg)
    cost = distances(robot, paths[rows, cols], paths[rows, cols + 1]).astype(np.float64)
    k = np.zeros(seg.shape, np.int64)
    k[rows, cols] = np.maximum(1, np.ceil(cost / float(spacing))).astype(np.int64)
    return k


def resample_paths(robot, paths, lengths, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Inserts waypoints so that consecutive ones are at most ``spacing`` apart.

    Args:
        robot: the robot (its ``distance`` and ``interpolate``).
        paths: ``(B, L, d)`` float32 waypoints, NaN-padded after ``lengths[b]``.
        lengths: ``(B,)`` waypoint counts (0 or 1: returned as they are).
        spacing: the largest distance between consecutive waypoints (> 0, robot metric).

    Returns:
        ``(paths (B, L', d) float32 NaN-padded, lengths (B,) int32)``; every input
        waypoint is kept exactly, in order.

    Raises:
        ValueError: ``spacing`` not a positive finite number, or malformed arrays.
    """
    spacing = float(spacing)
    if not np.isfinite(spacing) or spacing <= 0:
        raise ValueError(f"spacing must be a positive number, got {spacing}")
    p = np.asarray(paths, np.float32)
    n = np.asarray(lengths, np.int64).reshape(-1)
    if p.ndim != 3 or p.shape[2] != robot.dim or p.shape[0] != n.shape[0]:
        raise ValueError(
            f"paths must be (B, L, {robot.dim}) with lengths (B,), got {p.shape} and {n.shape}"
        )
    bsz, l, d = p.shape
    n = np.clip(n, 0, l)
    if bsz == 0:
        return p.copy(), n.astype(np.int32)
    k = segment_counts(robot, p, n, spacing)  # (B, L-1)
    out_len = np.where(n >= 2, k.sum(axis=1) + 1, n).astype(np.int64)
    width = max(2, int(out_len.max()))
    out = np.full((bsz, width, d), np.nan, np.float32)
    # segment (b, i) starts at output row start[b, i]; its original vertex goes there
    start = np.concatenate([np.zeros((bsz, 1), np.int64), np.cumsum(k, axis=1)], axis=1)
    keep = np.arange(l)[None, :] < n[:, None]
    rb, ri = np.nonzero(keep)
    out[rb, start[rb, ri]] = p[rb, ri]
    # the inserted waypoints: piece j = 1..k-1 of every segment, at t = j / k
    reps = np.maximum(k - 1, 0)
    sb, si = np.nonzero(reps)
    cnt = reps[sb, si]
    if cnt.size:
        seg_b, seg_i = np.repeat(sb, cnt), np.repeat(si, cnt)
        j = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt) + 1
        t = (j / k[seg_b, seg_i]).astype(np.float32)
        new = map_chunks(
            lambda a, b_, tt: _interpolate_batch(robot, a, b_, tt),
            p[seg_b, seg_i],
            p[seg_b, seg_i + 1],
            t,
            chunk=CHECK_CHUNK,
            empty=np.zeros((0, d), np.float32),
        )
        out[seg_b, start[seg_b, seg_i] + j] = new
    return out, out_len.astype(np.int32)
