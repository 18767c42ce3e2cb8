"""Vectorised float64 NumPy obstacle tests: many states or segments against every obstacle.

The batch half of :class:`ntq_jax.planners.ompl_checker.NumpyChecker` (its
``is_valid_many`` and the tail of its ``steer_to``). Each function is the
NumPy broadcast of one kernel of :mod:`ntq_jax.geometry` (same formulas, in
float64): clearance means "distance to every obstacle ``> padding``".
Obstacles are ``boxes (B, 4)`` rows ``[cx, cy, half_w, half_h]`` and ``discs
(C, 3)`` rows ``[cx, cy, r]``. Only (state, obstacle) pairs whose bounding
boxes are within the padding (plus :data:`MARGIN`) are tested in full. Pure
NumPy: the BIT* workers import it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MARGIN", "points_free", "rects_free", "segments_free"]

#: Bounding-box pre-filters only skip obstacles farther than ``padding + MARGIN``.
MARGIN = 1e-9

_SL = np.array([1.0, -1.0, -1.0, 1.0])  # rectangle corner signs along the length and
_SW = np.array([1.0, 1.0, -1.0, -1.0])  # the width, in the order of geometry.rect_corners
_SX = np.array([-1.0, -1.0, 1.0, 1.0])  # box corner signs
_SY = np.array([-1.0, 1.0, -1.0, 1.0])


def in_bounds(x, y, bounds) -> np.ndarray:
    """Elementwise ``x, y`` inside ``bounds (2, 2)`` (the boundary included)."""
    return (x >= bounds[0, 0]) & (x <= bounds[0, 1]) & (y >= bounds[1, 0]) & (y <= bounds[1, 1])


def points_free(x, y, bounds, boxes, discs, p: float) -> np.ndarray:
    """``geometry.point_free`` for ``(k,)`` points -> ``(k,)`` bool."""
    ok = in_bounds(x, y, bounds)
    if len(boxes):
        X, Y = x[:, None], y[:, None]
        if p == 0.0:
            hit = (np.abs(X - boxes[:, 0]) <= boxes[:, 2]) & (
                np.abs(Y - boxes[:, 1]) <= boxes[:, 3]
            )
        else:
            dx = np.maximum(np.abs(X - boxes[:, 0]) - boxes[:, 2], 0.0)
            dy = np.maximum(np.abs(Y - boxes[:, 1]) - boxes[:, 3], 0.0)
            hit = dx * dx + dy * dy <= p * p
        ok &= ~hit.any(axis=1)
    if len(discs):
        dx, dy = x[:, None] - discs[:, 0], y[:, None] - discs[:, 1]
        ok &= ~(dx * dx + dy * dy <= (discs[:, 2] + p) ** 2).any(axis=1)
    return ok


def rects_free(x, y, th, hl: float, hw: float, bounds, boxes, discs, p: float) -> np.ndarray:
    """``geometry.rect_free`` for ``(k,)`` poses of a ``2 hl x 2 hw`` rectangle -> ``(k,)`` bool."""
    c, s = np.cos(th), np.sin(th)
    C, S = c[:, None], s[:, None]
    cl, cw = hl * _SL, hw * _SW
    PX = x[:, None] + C * cl - S * cw  # corners (k, 4)
    PY = y[:, None] + S * cl + C * cw
    ok = in_bounds(PX, PY, bounds).all(1)
    AC, AS = np.abs(C), np.abs(S)
    EX, EY = hl * AC + hw * AS, hl * AS + hw * AC  # half extents of the axis-aligned bounding box
    if len(boxes):
        cx, cy, bw, bh = boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]
        ATX, ATY = np.abs(cx - x[:, None]), np.abs(cy - y[:, None])  # (k, B)
        reach = p + MARGIN
        ki, bi = np.nonzero((ATX <= bw + EX + reach) & (ATY <= bh + EY + reach))
        if len(ki):
            cx, cy, bw, bh = cx[bi], cy[bi], bw[bi], bh[bi]
            xk, yk, ck, sk, ac, as_ = x[ki], y[ki], c[ki], s[ki], AC[ki, 0], AS[ki, 0]
            tx, ty = cx - xk, cy - yk
            hit = (
                (np.abs(tx) <= bw + EX[ki, 0])
                & (np.abs(ty) <= bh + EY[ki, 0])
                & (np.abs(tx * ck + ty * sk) <= hl + bw * ac + bh * as_)
                & (np.abs(-tx * sk + ty * ck) <= hw + bw * as_ + bh * ac)
            )
            if p > 0.0:
                p2 = p * p
                dx = np.maximum(np.abs(PX[ki] - cx[:, None]) - bw[:, None], 0.0)
                dy = np.maximum(np.abs(PY[ki] - cy[:, None]) - bh[:, None], 0.0)
                hit |= (dx * dx + dy * dy <= p2).any(1)
                rx = (cx[:, None] + _SX * bw[:, None]) - xk[:, None]  # box corners (m, 4)
                ry = (cy[:, None] + _SY * bh[:, None]) - yk[:, None]
                cc, ss = ck[:, None], sk[:, None]
                du = np.maximum(np.abs(rx * cc + ry * ss) - hl, 0.0)
                dv = np.maximum(np.abs(-rx * ss + ry * cc) - hw, 0.0)
                hit |= (du * du + dv * dv <= p2).any(1)
            ok[ki[hit]] = False
    if len(discs):
        rx, ry = discs[:, 0] - x[:, None], discs[:, 1] - y[:, None]
        du = np.maximum(np.abs(rx * C + ry * S) - hl, 0.0)
        dv = np.maximum(np.abs(-rx * S + ry * C) - hw, 0.0)
        ok &= ~(du * du + dv * dv <= (discs[:, 2] + p) ** 2).any(axis=1)
    return ok


def segments_free(x0, y0, x1, y1, boxes, discs, p: float) -> np.ndarray:
    """``geometry.segment_free(check_bounds=False)`` over arrays of segments (any shape)."""
    shape = np.shape(x0)
    x0, y0, x1, y1 = (np.ravel(v) for v in (x0, y0, x1, y1))
    free = np.ones(x0.shape, bool)
    if len(boxes):
        reach = p + MARGIN
        lox, hix = np.minimum(x0, x1)[:, None], np.maximum(x0, x1)[:, None]
        loy, hiy = np.minimum(y0, y1)[:, None], np.maximum(y0, y1)[:, None]
        cx, cy, hw, hh = boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]
        si, bi = np.nonzero(
            (lox <= cx + hw + reach)
            & (hix >= cx - hw - reach)
            & (loy <= cy + hh + reach)
            & (hiy >= cy - hh - reach)
        )
        if len(si):
            free[si[_segment_box_hits(x0[si], y0[si], x1[si], y1[si], boxes[bi], p)]] = False
    if len(discs):
        X0, Y0, X1, Y1 = x0[:, None], y0[:, None], x1[:, None], y1[:, None]
        dx, dy = X1 - X0, Y1 - Y0
        cx, cy = discs[:, 0], discs[:, 1]
        r2 = (discs[:, 2] + p) ** 2
        hit = ((X0 - cx) ** 2 + (Y0 - cy) ** 2 <= r2) | ((X1 - cx) ** 2 + (Y1 - cy) ** 2 <= r2)
        hit |= _seg_point_close(X0, Y0, dx, dy, dx * dx + dy * dy, cx, cy, r2)
        free &= ~hit.any(axis=-1)
    return free.reshape(shape)


def _segment_box_hits(a0, b0, a1, b1, boxes, p: float) -> np.ndarray:
    """``(m,)`` segments against their ``(m, 4)`` boxes, pairwise: True where within ``p``."""
    cx, cy, hw, hh = boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]
    dx, dy = a1 - a0, b1 - b0
    adx, ady = np.abs(dx), np.abs(dy)
    ux, uy = 0.5 * (a0 + a1) - cx, 0.5 * (b0 + b1) - cy
    ex, ey = np.abs(ux), np.abs(uy)
    cross = ux * dy - uy * dx
    h = hw * ady + hh * adx
    if p == 0.0:
        return (ex <= hw + 0.5 * adx) & (ey <= hh + 0.5 * ady) & (np.abs(cross) <= h)
    r2 = p * p
    gx, gy, gc = ex - 0.5 * adx, ey - 0.5 * ady, np.abs(cross) - h
    hit = (gx <= hw + p) & (gy <= hh) & (gc <= p * ady)
    hit |= (gx <= hw) & (gy <= hh + p) & (gc <= p * adx)
    for qx, qy in ((a0, b0), (a1, b1)):
        ddx, ddy = np.abs(qx - cx) - hw, np.abs(qy - cy) - hh
        hit |= ddx * ddx + ddy * ddy <= r2
    px = cx + np.where(cross * dy > 0.0, hw, -hw)
    py = cy + np.where(cross * dx > 0.0, -hh, hh)
    hit |= _seg_point_close(a0, b0, dx, dy, dx * dx + dy * dy, px, py, r2)
    return hit


def _seg_point_close(x0, y0, dx, dy, dd, px, py, r2):
    """``geometry._seg_point_interior_close`` elementwise."""
    wx, wy = px - x0, py - y0
    dot = wx * dx + wy * dy
    cross = wx * dy - wy * dx
    return (dot >= 0.0) & (dot <= dd) & (cross * cross <= r2 * dd) & (dd > 0.0)
