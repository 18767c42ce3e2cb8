"""The package's validity and ``steer_to`` in float64 NumPy/Python, for BIT*'s callbacks.

BIT* calls back into Python for every state and every edge it checks; a
jitted JAX call per state is far too slow there, so :class:`NumpyChecker`
ports the exact kernels of :mod:`ntq_jax.geometry` and :mod:`ntq_jax.robots`
(oriented rectangle, arm links and points against boxes and discs, with
clearance ``padding``) to float64 Python floats (one state) and NumPy (many
states, :mod:`ntq_jax.planners.ompl_checker_batch`). Contract: the same answers
as ``Env.is_valid`` / ``Env.steer_to``, except within float32 rounding of a
tangency (tested in ``tests/test_ompl_bridge.py``). The planner's paths are
verified afterwards with the package's own kernels
(:func:`ntq_jax.planners.verify.finalize`). Pure NumPy: the BIT* workers import
it. Per-call costs: ``benchmarks/bench_bitstar.py`` and BENCHMARKS.md.
"""

from __future__ import annotations

import functools
import math
from typing import Sequence

import numpy as np

from ntq_jax.planners.ompl_checker_batch import MARGIN, points_free, rects_free, segments_free

__all__ = ["NumpyChecker", "PI32", "wrap_angle"]

#: The arm's joint bound as the JAX kernel applies it: ``|q| <= float32(pi)``
#: (3.1415927410..., slightly above math.pi), so float32 states clipped to the
#: configuration bounds are valid in both.
PI32 = float(np.float32(np.pi))


def wrap_angle(a):
    """``wrap_angle`` of :mod:`ntq_jax.robots.base` (``[-pi, pi)``), for floats and arrays."""
    if isinstance(a, float):
        return (a + math.pi) % (2.0 * math.pi) - math.pi
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


def arm_joints(base, links, angles, cos, sin):
    """Yields the arm's joint positions ``(x, y)``, base first, from its joint angles.

    Mirrors ``NLinkArm.joint_xy`` (robots/nlink.py) because BIT*'s callbacks cannot
    afford a JAX call. ``angles`` are floats with ``cos = math.cos`` or ``(k,)``
    arrays (one per joint) with ``cos = np.cos``; lazy, so a caller can stop early.
    """
    x, y = base
    yield x, y
    phi = 0.0
    for length, a in zip(links, angles):
        phi = phi + a
        x = x + length * cos(phi)
        y = y + length * sin(phi)
        yield x, y


class NumpyChecker:
    """Float64 validity and ``steer_to`` for one robot, world and padding.

    Same semantics as the JAX kernels: clearance means "distance to every
    obstacle ``> padding``", touching the workspace boundary is allowed, NaN/inf
    states are invalid. :meth:`is_valid` checks one state (plain Python floats,
    short-circuit tests and exact-preserving bounding-box pre-filters: fast in a
    callback); :meth:`is_valid_many` checks ``(k, d)`` states with NumPy
    broadcasting. Holds only floats and arrays, so it pickles to a worker.

    Args:
        robot: a ``PointRobot``, ``RigidBody`` or ``NLinkArm`` (read for its parameters).
        bounds, boxes, discs: the world's arrays (``(2, 2)``, ``(B, 4)``, ``(C, 3)``).
        padding: clearance ``>= 0``.
    """

    def __init__(self, robot, bounds, boxes, discs, padding: float):
        self.kind = robot.kind
        self.dim = int(robot.dim)
        self.padding = float(padding)
        b = np.asarray(bounds, np.float64).reshape(2, 2)
        self.bounds = b
        self.xmin, self.xmax, self.ymin, self.ymax = (float(v) for v in b.ravel())
        self.boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        self.discs = np.asarray(discs, np.float64).reshape(-1, 3)
        self._box_list = [tuple(float(v) for v in r) for r in self.boxes]
        self._disc_list = [tuple(float(v) for v in r) for r in self.discs]
        if self.kind == "rigid_body":
            self.hl, self.hw = 0.5 * float(robot.length), 0.5 * float(robot.width)
            self.angle_weight = float(robot.angle_weight)
            self.resolution = float(robot.resolution)
        elif self.kind == "nlink":
            self.links = tuple(float(v) for v in robot.link_lengths)
            self.base = tuple(float(v) for v in robot.base)
            self.resolution = float(robot.resolution)
        elif self.kind == "point":
            self.resolution = None  # steer_to is exact (continuous)
        else:
            raise ValueError(f"NumpyChecker: unsupported robot kind {self.kind!r}")

    @classmethod
    def from_env(cls, env, padding: float | None = None) -> "NumpyChecker":
        """The checker of ``env`` at ``padding`` (default: the environment's)."""
        w = env.world
        return cls(
            env.robot,
            np.asarray(w.bounds),
            np.asarray(w.boxes),
            np.asarray(w.discs),
            env.resolve_padding(padding),
        )

    # -- metric ----------------------------------------------------------------
    def distance(self, a, b) -> float:
        """The robot's cost metric between two states (float64)."""
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        if self.kind == "rigid_body":
            return float(
                math.hypot(b[0] - a[0], b[1] - a[1])
                + self.angle_weight * abs(wrap_angle(float(b[2] - a[2])))
            )
        return float(np.sqrt(np.sum((b - a) ** 2)))

    def interpolate(self, a, b, t) -> np.ndarray:
        """States at fractions ``t`` ``(k,)`` of the steering curve ``a -> b``: ``(k, d)``."""
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        t = np.asarray(t, np.float64)[:, None]
        out = a + t * (b - a)
        if self.kind == "rigid_body":
            dth = wrap_angle(float(b[2] - a[2]))
            out[:, 2] = wrap_angle(a[2] + t[:, 0] * dth)
        return out

    # -- single state ----------------------------------------------------------------
    def is_valid(self, q) -> bool:
        """One state ``(d,)`` (any sequence of numbers) -> bool."""
        if self.kind == "rigid_body":
            return self.rigid_valid(float(q[0]), float(q[1]), float(q[2]))
        if self.kind == "nlink":
            return self.arm_valid([float(v) for v in q])
        return self.point_valid(float(q[0]), float(q[1]))

    def _in_bounds(self, x, y) -> bool:
        return self.xmin <= x <= self.xmax and self.ymin <= y <= self.ymax

    def point_valid(self, x: float, y: float) -> bool:
        if not math.isfinite(x + y) or not self._in_bounds(x, y):
            return False
        p = self.padding
        p2 = p * p
        for cx, cy, hw, hh in self._box_list:
            if p == 0.0:
                if abs(x - cx) <= hw and abs(y - cy) <= hh:
                    return False
            else:
                dx = max(abs(x - cx) - hw, 0.0)
                dy = max(abs(y - cy) - hh, 0.0)
                if dx * dx + dy * dy <= p2:
                    return False
        for cx, cy, r in self._disc_list:
            dx, dy = x - cx, y - cy
            rr = r + p
            if dx * dx + dy * dy <= rr * rr:
                return False
        return True

    def rigid_valid(self, x: float, y: float, th: float) -> bool:
        """``geometry.rect_free`` for one pose (same formulas, float64, short-circuit)."""
        if not math.isfinite(x + y + th):
            return False
        hl, hw, p = self.hl, self.hw, self.padding
        c, s = math.cos(th), math.sin(th)
        a, b, e, f = hl * c, hw * s, hl * s, hw * c
        # corners (sl, sw) = (1, 1), (-1, 1), (-1, -1), (1, -1) of geometry.rect_corners
        x1, x2, x3, x4 = x + a - b, x - a - b, x - a + b, x + a + b
        y1, y2, y3, y4 = y + e + f, y - e + f, y - e - f, y + e - f
        xmin, xmax, ymin, ymax = self.xmin, self.xmax, self.ymin, self.ymax
        if not (
            xmin <= x1 <= xmax
            and xmin <= x2 <= xmax
            and xmin <= x3 <= xmax
            and xmin <= x4 <= xmax
            and ymin <= y1 <= ymax
            and ymin <= y2 <= ymax
            and ymin <= y3 <= ymax
            and ymin <= y4 <= ymax
        ):
            return False
        ac, as_ = abs(c), abs(s)
        ex = hl * ac + hw * as_  # half extents of the rectangle's axis-aligned bounding box
        ey = hl * as_ + hw * ac
        reach = p + MARGIN
        p2 = p * p
        for cx, cy, bw, bh in self._box_list:
            tx, ty = cx - x, cy - y
            atx, aty = abs(tx), abs(ty)
            if atx > bw + ex + reach or aty > bh + ey + reach:
                continue  # bounding boxes farther apart than the padding: no test can hit
            if (
                atx <= bw + ex
                and aty <= bh + ey
                and abs(tx * c + ty * s) <= hl + bw * ac + bh * as_
                and abs(-tx * s + ty * c) <= hw + bw * as_ + bh * ac
            ):
                return False
            if p == 0.0:
                continue
            for px, py in ((x1, y1), (x2, y2), (x3, y3), (x4, y4)):
                dx = abs(px - cx) - bw
                dy = abs(py - cy) - bh
                dx = dx if dx > 0.0 else 0.0
                dy = dy if dy > 0.0 else 0.0
                if dx * dx + dy * dy <= p2:
                    return False
            for qx in (cx - bw, cx + bw):
                for qy in (cy - bh, cy + bh):
                    rx, ry = qx - x, qy - y
                    du = abs(rx * c + ry * s) - hl
                    dv = abs(-rx * s + ry * c) - hw
                    du = du if du > 0.0 else 0.0
                    dv = dv if dv > 0.0 else 0.0
                    if du * du + dv * dv <= p2:
                        return False
        for cx, cy, r in self._disc_list:
            rx, ry = cx - x, cy - y
            rr = r + p
            du = max(abs(rx * c + ry * s) - hl, 0.0)
            dv = max(abs(-rx * s + ry * c) - hw, 0.0)
            if du * du + dv * dv <= rr * rr:
                return False
        return True

    def arm_valid(self, q: Sequence[float]) -> bool:
        """``NLinkArm.is_valid`` for one joint vector."""
        for v in q:
            if not (math.isfinite(v) and abs(v) <= PI32):
                return False
        joints = arm_joints(self.base, self.links, q, math.cos, math.sin)
        x, y = next(joints)
        if not self._in_bounds(x, y):
            return False
        for nx, ny in joints:
            if not self._in_bounds(nx, ny) or not self.segment_free(x, y, nx, ny):
                return False
            x, y = nx, ny
        return True

    def segment_free(self, x0: float, y0: float, x1: float, y1: float) -> bool:
        """``geometry.segment_free(..., check_bounds=False)`` for one segment (exact)."""
        if not math.isfinite(x0 + y0 + x1 + y1):
            return False
        p = self.padding
        reach = p + MARGIN
        lox, hix = (x0, x1) if x0 <= x1 else (x1, x0)
        loy, hiy = (y0, y1) if y0 <= y1 else (y1, y0)
        dx, dy = x1 - x0, y1 - y0
        adx, ady = abs(dx), abs(dy)
        dd = dx * dx + dy * dy
        for cx, cy, hw, hh in self._box_list:
            if (
                lox > cx + hw + reach
                or hix < cx - hw - reach
                or loy > cy + hh + reach
                or hiy < cy - hh - reach
            ):
                continue
            ux, uy = 0.5 * (x0 + x1) - cx, 0.5 * (y0 + y1) - cy
            ex, ey = abs(ux), abs(uy)
            cross = ux * dy - uy * dx
            h = hw * ady + hh * adx
            if p == 0.0:
                if ex <= hw + 0.5 * adx and ey <= hh + 0.5 * ady and abs(cross) <= h:
                    return False
                continue
            r2 = p * p
            gx, gy, gc = ex - 0.5 * adx, ey - 0.5 * ady, abs(cross) - h
            if gx <= hw + p and gy <= hh and gc <= p * ady:
                return False
            if gx <= hw and gy <= hh + p and gc <= p * adx:
                return False
            for qx, qy in ((x0, y0), (x1, y1)):
                ddx, ddy = abs(qx - cx) - hw, abs(qy - cy) - hh
                if ddx * ddx + ddy * ddy <= r2:
                    return False
            px = cx + (hw if cross * dy > 0.0 else -hw)
            py = cy + (-hh if cross * dx > 0.0 else hh)
            if _seg_point_close(x0, y0, dx, dy, dd, px, py, r2):
                return False
        for cx, cy, r in self._disc_list:
            rr = r + p
            r2 = rr * rr
            if (x0 - cx) ** 2 + (y0 - cy) ** 2 <= r2 or (x1 - cx) ** 2 + (y1 - cy) ** 2 <= r2:
                return False
            if _seg_point_close(x0, y0, dx, dy, dd, cx, cy, r2):
                return False
        return True

    # -- many states (NumPy) ---------------------------------------------------------
    def is_valid_many(self, states) -> np.ndarray:
        """``(k, d)`` states -> ``(k,)`` bool, vectorised over states and obstacles."""
        q = np.asarray(states, np.float64)
        if q.ndim != 2 or q.shape[1] != self.dim:
            raise ValueError(f"states must have shape (k, {self.dim}), got {q.shape}")
        finite = np.all(np.isfinite(q), axis=1)
        q = np.where(finite[:, None], q, 0.0)
        world = (self.bounds, self.boxes, self.discs, self.padding)
        if self.kind == "rigid_body":
            ok = rects_free(q[:, 0], q[:, 1], q[:, 2], self.hl, self.hw, *world)
        elif self.kind == "nlink":
            ok = self._arm_many(q)
        else:
            ok = points_free(q[:, 0], q[:, 1], *world)
        return ok & finite

    def _arm_many(self, q):
        ok = np.all(np.abs(q) <= PI32, axis=1)
        k = len(q)
        joints = list(arm_joints(self.base, self.links, q.T, np.cos, np.sin))
        X = np.stack([np.broadcast_to(x, (k,)) for x, _ in joints], 1)  # (k, n + 1)
        Y = np.stack([np.broadcast_to(y, (k,)) for _, y in joints], 1)
        ok &= np.all(
            (X >= self.xmin) & (X <= self.xmax) & (Y >= self.ymin) & (Y <= self.ymax), axis=1
        )
        free = segments_free(
            X[:, :-1], Y[:, :-1], X[:, 1:], Y[:, 1:], self.boxes, self.discs, self.padding
        )
        return ok & np.all(free, axis=1)

    # -- edges -------------------------------------------------------------------------
    #: ``steer_to`` first checks this many states one by one in bisection order (endpoints,
    #: midpoint, quarters, ...), so most blocked edges are rejected early and cheaply ...
    PROBE = 5
    #: ... then the rest one by one up to this many states per edge, else in one NumPy call.
    SCALAR_MAX = 16

    def steer_to(self, a, b) -> bool:
        """The package's ``steer_to`` for one pair of states (float64).

        Point robot: exact segment test. Rigid body and arm: every state at
        ``t = k / n``, ``k = 0..n``, ``n = max(ceil(distance / resolution), 1)``
        is valid (``robots.base.discretized_steer_to``); the order in which the
        states are checked does not change the result.
        """
        a = [float(v) for v in a]
        b = [float(v) for v in b]
        if self.kind == "point":
            return (
                self.point_valid(a[0], a[1])
                and self.point_valid(b[0], b[1])
                and self.segment_free(a[0], a[1], b[0], b[1])
            )
        rigid = self.kind == "rigid_body"
        if rigid:
            dth = wrap_angle(b[2] - a[2])
            dist = math.hypot(b[0] - a[0], b[1] - a[1]) + self.angle_weight * abs(dth)
        else:
            dist = math.sqrt(sum((v - u) ** 2 for u, v in zip(a, b)))
        if not math.isfinite(dist):
            return False
        n = max(math.ceil(dist / self.resolution), 1)
        probe = _bisection_order(n, self.PROBE if n + 1 > self.SCALAR_MAX else n + 1)
        if rigid:
            x0, y0, t0 = a
            dx, dy = b[0] - x0, b[1] - y0
            one = self.rigid_valid
            for k in probe:
                t = k / n
                if not one(x0 + t * dx, y0 + t * dy, wrap_angle(t0 + t * dth)):
                    return False
        else:
            one = self.arm_valid if self.kind == "nlink" else self.is_valid
            diff = [v - u for u, v in zip(a, b)]
            for k in probe:
                t = k / n
                if not one([u + t * w for u, w in zip(a, diff)]):
                    return False
        if len(probe) == n + 1:
            return True
        rest = np.ones(n + 1, bool)
        rest[list(probe)] = False
        t = np.flatnonzero(rest) / n
        return bool(np.all(self.is_valid_many(self.interpolate(a, b, t))))


@functools.lru_cache(maxsize=4096)
def _bisection_order(n: int, m: int) -> tuple[int, ...]:
    """The first ``m`` of ``0..n`` in bisection order: ``0, n, n/2, n/4, 3n/4, ...``."""
    out, seen = [], set()

    def add(k):
        if k not in seen and len(out) < m:
            seen.add(k)
            out.append(k)

    add(0)
    add(n)
    den = 2
    while len(out) < m and den <= 2 * n:
        for j in range(1, den, 2):
            add(round(j * n / den))
        den *= 2
    for k in range(n + 1):  # whatever rounding skipped
        add(k)
    return tuple(out)


def _seg_point_close(x0, y0, dx, dy, dd, px, py, r2) -> bool:
    """``geometry._seg_point_interior_close`` for floats."""
    wx, wy = px - x0, py - y0
    dot = wx * dx + wy * dy
    cross = wx * dy - wy * dx
    return dd > 0.0 and 0.0 <= dot <= dd and cross * cross <= r2 * dd
