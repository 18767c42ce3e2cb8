"""The vectorised NumPy baseline of the point robot's ``steer_to``: pure NumPy, no package
import, so that benchmarks can load it beside any commit's package
(``bench_steer_commits.py`` runs it in child processes of other checkouts)."""

from __future__ import annotations

import numpy as np


def numpy_steer(a: np.ndarray, b: np.ndarray, boxes, bounds, padding: float) -> np.ndarray:
    """Exact vectorised NumPy segment-vs-boxes test, ``(N, 2), (N, 2) -> (N,)`` (True = free).

    Separating axes for the segment against the box grown by the padding along x
    and along y, plus the endpoint-to-corner and nearest-corner-to-segment
    distances (the same mathematics as ``ntq_jax.geometry.segment_hits_box``).
    """
    x0, y0, x1, y1 = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    free = np.isfinite(x0 + y0 + x1 + y1)
    for x, y in ((x0, y0), (x1, y1)):
        free &= (
            (x >= bounds[0][0]) & (x <= bounds[0][1]) & (y >= bounds[1][0]) & (y <= bounds[1][1])
        )
    dx, dy = x1 - x0, y1 - y0
    adx, ady = np.abs(dx), np.abs(dy)
    dd = dx * dx + dy * dy
    r, r2 = np.float32(padding), np.float32(padding * padding)
    for cx, cy, hw, hh in np.asarray(boxes, np.float32):
        ux, uy = 0.5 * (x0 + x1) - cx, 0.5 * (y0 + y1) - cy
        gx, gy = np.abs(ux) - 0.5 * adx, np.abs(uy) - 0.5 * ady
        cross = ux * dy - uy * dx
        gc = np.abs(cross) - (hw * ady + hh * adx)
        hit = (gx <= hw + r) & (gy <= hh) & (gc <= r * ady)
        hit |= (gx <= hw) & (gy <= hh + r) & (gc <= r * adx)
        if padding > 0:
            for px, py in ((x0, y0), (x1, y1)):
                ex, ey = np.abs(px - cx) - hw, np.abs(py - cy) - hh
                hit |= ex * ex + ey * ey <= r2
            kx = cx + np.where(cross * dy > 0, hw, -hw)
            ky = cy + np.where(cross * dx > 0, -hh, hh)
            wx, wy = kx - x0, ky - y0
            dot, crs = wx * dx + wy * dy, wx * dy - wy * dx
            hit |= (dot >= 0) & (dot <= dd) & (crs * crs <= r2 * dd) & (dd > 0)
        free &= ~hit
    return free
