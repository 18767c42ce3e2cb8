"""OMPL BIT* bridge: batched, parallel BIT* on the package's own geometry (host side).

The paper solves rigid-body and n-link-arm queries with OMPL's BIT* (3 s per
rigid-body query for data generation, 2 s at evaluation). :func:`plan_bitstar`
runs BIT* from the PyPI ``ompl`` package (2.x, nanobind bindings) on a batch of
queries in parallel worker processes and returns, per query, a waypoint path,
its cost in the robot's metric and a status code; an unsolvable or invalid
query is a status, never an exception::

    env = ntq_jax.make_env("rigid/0")
    queries, _ = env.sample_queries(jax.random.key(0), 8, p_nt=0.0)
    res = plan_bitstar(env, queries, time_budget=1.0)
    res.status      # (N,) int8: SOLVED 0, NO_PATH 1, INVALID 2, CRASHED 3, REJECTED 4
    res.paths[i]    # (L_i, d) float32, start first and goal last (exactly the query's)
    res.costs       # (N,) float64, sum of env.distance over the path's segments (inf unless solved)

Geometry: BIT*'s notion of a valid state and a valid edge is the package's.

* **States.** :class:`NumpyChecker` is a float64 NumPy/Python port of the exact
  kernels of :mod:`ntq_jax.geometry` (oriented rectangle, arm links and points
  against boxes and discs, with clearance ``padding``). The tests prove it
  equal to :meth:`ntq_jax.Env.is_valid` on random states (disagreements only at
  float32 tangency). A jitted JAX call per state costs ~0.2-0.6 ms from Python;
  the port ~2-8 us (``scripts/bench_bitstar.py``).
* **Edges.** A Python ``ompl.base.MotionValidator`` subclass checks an edge with
  the discretised ``steer_to`` of :mod:`ntq_jax.robots.base` (states at
  ``t = k / n``, ``n = ceil(distance / robot.resolution)``, endpoints included;
  straight line in position and shortest arc in angle for SE(2), straight line
  in joint space for the arm): a few states one by one in bisection order
  (endpoints, midpoint, quarters: most blocked edges stop there), the rest in
  one vectorised NumPy call. One Python callback per edge instead of one per
  intermediate state with OMPL's default discrete motion validator (see
  ``scripts/bench_bitstar.py``).
* **Objective.** Path length in the space's metric: for SE(2) OMPL's
  ``||dp|| + w |dtheta|`` with the SO(2) weight set to ``robot.angle_weight``
  (0.5 = OMPL's default, the robot's cost metric); Euclidean joint distance for
  the arm (joint bounds ``[-pi, pi]`` as the kernel applies them in float32, no wrap-around).
* **Check.** Every returned path is re-checked with the package's own jitted
  :meth:`Env.steer_to` on each segment at the planning padding (float32). A
  path that fails (only possible within float32 rounding of a tangency) gets
  status :data:`REJECTED` and keeps its path for inspection. The path is BIT*'s
  as is (no simplification, no interpolation).

Time budget: every query gets ``time_budget`` seconds of ``solve``. By default
BIT* keeps improving its solution for the whole budget and returns the best one
(as the paper did); ``stop_on_first=True`` returns at the first solution. Either
way BIT* returns at once when its solution is provably optimal (a feasible
straight connection: a 2-state path).

Parallelism: worker processes started with the ``spawn`` method (never fork:
the parent has JAX and its threads loaded). Each worker rebuilds the
environment from :meth:`Env.to_json` and receives chunks of queries. If a
worker dies (killed, segfault in native code), the query it was solving is
retried once in a fresh worker and marked :data:`CRASHED` if it kills that one
too; the worker's other unfinished queries are re-queued without penalty. As
with any ``spawn`` multiprocessing, a script calling :func:`plan_bitstar` at
import time needs the ``if __name__ == "__main__":`` guard.

Determinism: before each query the worker re-seeds OMPL's global seed generator
(``ompl.util.RNG.setSeed``) with a seed derived from ``seed`` and the query's
index, and builds a fresh planner, so the random samples do not depend on which
worker solves the query or in which order. With ``stop_on_first=True`` BIT*'s
first solution depends only on the samples, so results are reproducible
run-to-run (tested). With the full budget (default) the path depends on how
many batches BIT* processes before the wall-clock deadline, which depends on
machine load: not reproducible, only statistically so.

Logging: OMPL's own log level defaults to errors only (``ompl_log_level``). The
parent process never imports ``ompl``; workers leave with ``os._exit`` so
nanobind's "leaked instances" report at interpreter shutdown is never printed.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import importlib.util
import math
import multiprocessing as mp
import os
import sys
import time
import traceback
import warnings
from multiprocessing.connection import wait as _mp_wait
from typing import Any, Mapping, Sequence

import numpy as np

#: Per-query status codes of :class:`BitstarResult`.
SOLVED = 0    #: an exact solution, checked with ``env.steer_to``
NO_PATH = 1   #: no exact solution within the time budget (unsolvable or timed out)
INVALID = 2   #: start or goal invalid at the planning padding (checked before planning)
CRASHED = 3   #: the worker died on this query twice (or raised: see ``errors``)
REJECTED = 4  #: BIT* returned a path that fails ``env.steer_to`` (float32 tangency); path kept

STATUS_NAMES = {SOLVED: "solved", NO_PATH: "no_path", INVALID: "invalid", CRASHED: "crashed",
                REJECTED: "rejected"}

_LOG_LEVELS = ("debug", "info", "warn", "error", "none")

#: The arm's joint bound as the JAX kernel applies it: ``|q| <= float32(pi)``
#: (3.1415927410..., slightly above math.pi), so float32 states clipped to the
#: configuration bounds are valid in both.
PI32 = float(np.float32(np.pi))


# ---------------------------------------------------------------------------
# NumPy port of the geometry (float64)
# ---------------------------------------------------------------------------

def _wrap(a):
    """``wrap_angle`` of :mod:`ntq_jax.robots.base` (``[-pi, pi)``), for floats and arrays."""
    if isinstance(a, float):
        return (a + math.pi) % (2.0 * math.pi) - math.pi
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


class NumpyChecker:
    """Float64 NumPy/Python validity and ``steer_to`` for one environment and padding.

    Same semantics as the JAX kernels (:mod:`ntq_jax.geometry`, :mod:`ntq_jax.robots`):
    clearance means "distance to every obstacle ``> padding``", touching the
    workspace boundary is allowed, NaN/inf states are invalid. Two code paths:
    :meth:`is_valid` for one state (plain Python floats with short-circuit
    tests and exact-preserving bounding-box pre-filters: fast in a callback)
    and :meth:`is_valid_many` for ``(k, d)`` states (NumPy broadcasting over
    states and obstacles). Both are tested against :meth:`ntq_jax.Env.is_valid`.

    Args:
        robot: the environment's robot (``PointRobot``, ``RigidBody`` or ``NLinkArm``).
        bounds, boxes, discs: the world's arrays (``(2, 2)``, ``(B, 4)``, ``(C, 3)``).
        padding: clearance ``>= 0``.
    """

    _MARGIN = 1e-9  # pre-filters only skip obstacles farther than padding + this

    def __init__(self, robot, bounds, boxes, discs, padding: float):
        self.robot = robot
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
            self._cl = np.array([self.hl, -self.hl, -self.hl, self.hl])  # rect_corners' sl * hl
            self._cw = np.array([self.hw, self.hw, -self.hw, -self.hw])  # and sw * hw
            self._sx = np.array([-1.0, -1.0, 1.0, 1.0])  # box corner signs
            self._sy = np.array([-1.0, 1.0, -1.0, 1.0])
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
        pad = env.padding if padding is None else float(padding)
        w = env.world
        return cls(env.robot, np.asarray(w.bounds), np.asarray(w.boxes), np.asarray(w.discs), pad)

    # -- metric ----------------------------------------------------------------
    def distance(self, a, b) -> float:
        """The robot's cost metric between two states (float64)."""
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        if self.kind == "rigid_body":
            return float(math.hypot(b[0] - a[0], b[1] - a[1])
                         + self.angle_weight * abs(_wrap(float(b[2] - a[2]))))
        return float(np.sqrt(np.sum((b - a) ** 2)))

    def interpolate(self, a, b, t) -> np.ndarray:
        """States at fractions ``t`` ``(k,)`` of the steering curve ``a -> b``: ``(k, d)``."""
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        t = np.asarray(t, np.float64)[:, None]
        out = a + t * (b - a)
        if self.kind == "rigid_body":
            dth = _wrap(float(b[2] - a[2]))
            out[:, 2] = _wrap(a[2] + t[:, 0] * dth)
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
        if not (xmin <= x1 <= xmax and xmin <= x2 <= xmax and xmin <= x3 <= xmax
                and xmin <= x4 <= xmax and ymin <= y1 <= ymax and ymin <= y2 <= ymax
                and ymin <= y3 <= ymax and ymin <= y4 <= ymax):
            return False
        ac, as_ = abs(c), abs(s)
        ex = hl * ac + hw * as_  # half extents of the rectangle's axis-aligned bounding box
        ey = hl * as_ + hw * ac
        reach = p + self._MARGIN
        p2 = p * p
        for cx, cy, bw, bh in self._box_list:
            tx, ty = cx - x, cy - y
            atx, aty = abs(tx), abs(ty)
            if atx > bw + ex + reach or aty > bh + ey + reach:
                continue  # bounding boxes farther apart than the padding: no test can hit
            if (atx <= bw + ex and aty <= bh + ey
                    and abs(tx * c + ty * s) <= hl + bw * ac + bh * as_
                    and abs(-tx * s + ty * c) <= hw + bw * as_ + bh * ac):
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
        x, y = self.base
        if not self._in_bounds(x, y):
            return False
        phi = 0.0
        for k, length in enumerate(self.links):
            phi = phi + q[k]
            nx = x + length * math.cos(phi)
            ny = y + length * math.sin(phi)
            if not self._in_bounds(nx, ny) or not self.segment_free(x, y, nx, ny):
                return False
            x, y = nx, ny
        return True

    def segment_free(self, x0: float, y0: float, x1: float, y1: float) -> bool:
        """``geometry.segment_free(..., check_bounds=False)`` for one segment (exact)."""
        if not math.isfinite(x0 + y0 + x1 + y1):
            return False
        p = self.padding
        reach = p + self._MARGIN
        lox, hix = (x0, x1) if x0 <= x1 else (x1, x0)
        loy, hiy = (y0, y1) if y0 <= y1 else (y1, y0)
        dx, dy = x1 - x0, y1 - y0
        adx, ady = abs(dx), abs(dy)
        dd = dx * dx + dy * dy
        for cx, cy, hw, hh in self._box_list:
            if (lox > cx + hw + reach or hix < cx - hw - reach
                    or loy > cy + hh + reach or hiy < cy - hh - reach):
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
        if self.kind == "rigid_body":
            ok = self._rigid_many(q)
        elif self.kind == "nlink":
            ok = self._arm_many(q)
        else:
            ok = self._points_many(q[:, 0], q[:, 1])
        return ok & finite

    def _inb(self, x, y):
        return (x >= self.xmin) & (x <= self.xmax) & (y >= self.ymin) & (y <= self.ymax)

    def _points_many(self, x, y):
        ok = self._inb(x, y)
        p = self.padding
        bx, dc = self.boxes, self.discs
        if len(bx):
            X, Y = x[:, None], y[:, None]
            if p == 0.0:
                hit = (np.abs(X - bx[:, 0]) <= bx[:, 2]) & (np.abs(Y - bx[:, 1]) <= bx[:, 3])
            else:
                dx = np.maximum(np.abs(X - bx[:, 0]) - bx[:, 2], 0.0)
                dy = np.maximum(np.abs(Y - bx[:, 1]) - bx[:, 3], 0.0)
                hit = dx * dx + dy * dy <= p * p
            ok &= ~hit.any(axis=1)
        if len(dc):
            dx, dy = x[:, None] - dc[:, 0], y[:, None] - dc[:, 1]
            ok &= ~(dx * dx + dy * dy <= (dc[:, 2] + p) ** 2).any(axis=1)
        return ok

    def _rigid_many(self, q):
        x, y, th = q[:, 0], q[:, 1], q[:, 2]
        hl, hw, p = self.hl, self.hw, self.padding
        c, s = np.cos(th), np.sin(th)
        C, S = c[:, None], s[:, None]
        # corners (k, 4), in the order of geometry.rect_corners
        PX = x[:, None] + C * self._cl - S * self._cw
        PY = y[:, None] + S * self._cl + C * self._cw
        ok = ((PX >= self.xmin) & (PX <= self.xmax) & (PY >= self.ymin) & (PY <= self.ymax)).all(1)
        AC, AS = np.abs(C), np.abs(S)
        EX, EY = hl * AC + hw * AS, hl * AS + hw * AC
        bx = self.boxes
        if len(bx):
            cx, cy, bw, bh = bx[:, 0], bx[:, 1], bx[:, 2], bx[:, 3]
            ATX, ATY = np.abs(cx - x[:, None]), np.abs(cy - y[:, None])  # (k, B)
            reach = p + self._MARGIN
            ki, bi = np.nonzero((ATX <= bw + EX + reach) & (ATY <= bh + EY + reach))
            if len(ki):  # only (state, box) pairs whose bounding boxes are within the padding
                cx, cy, bw, bh = cx[bi], cy[bi], bw[bi], bh[bi]
                xk, yk, ck, sk, ac, as_ = x[ki], y[ki], c[ki], s[ki], AC[ki, 0], AS[ki, 0]
                tx, ty = cx - xk, cy - yk
                hit = ((np.abs(tx) <= bw + EX[ki, 0]) & (np.abs(ty) <= bh + EY[ki, 0])
                       & (np.abs(tx * ck + ty * sk) <= hl + bw * ac + bh * as_)
                       & (np.abs(-tx * sk + ty * ck) <= hw + bw * as_ + bh * ac))
                if p > 0.0:
                    p2 = p * p
                    dx = np.maximum(np.abs(PX[ki] - cx[:, None]) - bw[:, None], 0.0)
                    dy = np.maximum(np.abs(PY[ki] - cy[:, None]) - bh[:, None], 0.0)
                    hit |= (dx * dx + dy * dy <= p2).any(1)
                    rx = (cx[:, None] + self._sx * bw[:, None]) - xk[:, None]  # box corners (m, 4)
                    ry = (cy[:, None] + self._sy * bh[:, None]) - yk[:, None]
                    cc, ss = ck[:, None], sk[:, None]
                    du = np.maximum(np.abs(rx * cc + ry * ss) - hl, 0.0)
                    dv = np.maximum(np.abs(-rx * ss + ry * cc) - hw, 0.0)
                    hit |= (du * du + dv * dv <= p2).any(1)
                ok[ki[hit]] = False
        dc = self.discs
        if len(dc):
            rx, ry = dc[:, 0] - x[:, None], dc[:, 1] - y[:, None]
            du = np.maximum(np.abs(rx * C + ry * S) - hl, 0.0)
            dv = np.maximum(np.abs(-rx * S + ry * C) - hw, 0.0)
            ok &= ~(du * du + dv * dv <= (dc[:, 2] + p) ** 2).any(axis=1)
        return ok

    def _arm_many(self, q):
        ok = np.all(np.abs(q) <= PI32, axis=1)
        k = len(q)
        phi = np.cumsum(q, axis=1)  # (k, n) absolute link angles (left to right, as the JAX loop)
        xs = [np.full(k, self.base[0])]
        ys = [np.full(k, self.base[1])]
        for j, length in enumerate(self.links):
            xs.append(xs[-1] + length * np.cos(phi[:, j]))
            ys.append(ys[-1] + length * np.sin(phi[:, j]))
        X, Y = np.stack(xs, 1), np.stack(ys, 1)  # (k, n + 1)
        ok &= np.all(self._inb(X, Y), axis=1)
        free = _segments_free_many(X[:, :-1], Y[:, :-1], X[:, 1:], Y[:, 1:],
                                   self.boxes, self.discs, self.padding)
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
            return (self.point_valid(a[0], a[1]) and self.point_valid(b[0], b[1])
                    and self.segment_free(a[0], a[1], b[0], b[1]))
        rigid = self.kind == "rigid_body"
        if rigid:
            dth = _wrap(b[2] - a[2])
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
                if not one(x0 + t * dx, y0 + t * dy, _wrap(t0 + t * dth)):
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


def _segments_free_many(x0, y0, x1, y1, boxes, discs, p):
    """``geometry.segment_free(check_bounds=False)`` over arrays of segments (any shape).

    Only (segment, box) pairs whose bounding boxes are within the padding are tested.
    """
    shape = np.shape(x0)
    x0, y0, x1, y1 = (np.ravel(v) for v in (x0, y0, x1, y1))
    free = np.ones(x0.shape, bool)
    if len(boxes):
        reach = p + NumpyChecker._MARGIN
        lox, hix = np.minimum(x0, x1)[:, None], np.maximum(x0, x1)[:, None]
        loy, hiy = np.minimum(y0, y1)[:, None], np.maximum(y0, y1)[:, None]
        cx, cy, hw, hh = boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]
        si, bi = np.nonzero((lox <= cx + hw + reach) & (hix >= cx - hw - reach)
                            & (loy <= cy + hh + reach) & (hiy >= cy - hh - reach))
        if len(si):
            cx, cy, hw, hh = cx[bi], cy[bi], hw[bi], hh[bi]
            a0, b0, a1, b1 = x0[si], y0[si], x1[si], y1[si]
            dx, dy = a1 - a0, b1 - b0
            adx, ady = np.abs(dx), np.abs(dy)
            ux, uy = 0.5 * (a0 + a1) - cx, 0.5 * (b0 + b1) - cy
            ex, ey = np.abs(ux), np.abs(uy)
            cross = ux * dy - uy * dx
            h = hw * ady + hh * adx
            if p == 0.0:
                hit = (ex <= hw + 0.5 * adx) & (ey <= hh + 0.5 * ady) & (np.abs(cross) <= h)
            else:
                r2 = p * p
                gx, gy, gc = ex - 0.5 * adx, ey - 0.5 * ady, np.abs(cross) - h
                hit = (gx <= hw + p) & (gy <= hh) & (gc <= p * ady)
                hit |= (gx <= hw) & (gy <= hh + p) & (gc <= p * adx)
                for qx, qy in ((a0, b0), (a1, b1)):
                    ddx, ddy = np.abs(qx - cx) - hw, np.abs(qy - cy) - hh
                    hit |= ddx * ddx + ddy * ddy <= r2
                px = cx + np.where(cross * dy > 0.0, hw, -hw)
                py = cy + np.where(cross * dx > 0.0, -hh, hh)
                hit |= _seg_point_close_many(a0, b0, dx, dy, dx * dx + dy * dy, px, py, r2)
            free[si[hit]] = False
    if len(discs):
        X0, Y0, X1, Y1 = x0[:, None], y0[:, None], x1[:, None], y1[:, None]
        dx, dy = X1 - X0, Y1 - Y0
        cx, cy = discs[:, 0], discs[:, 1]
        r2 = (discs[:, 2] + p) ** 2
        hit = ((X0 - cx) ** 2 + (Y0 - cy) ** 2 <= r2) | ((X1 - cx) ** 2 + (Y1 - cy) ** 2 <= r2)
        hit |= _seg_point_close_many(X0, Y0, dx, dy, dx * dx + dy * dy, cx, cy, r2)
        free &= ~hit.any(axis=-1)
    return free.reshape(shape)


def _seg_point_close_many(x0, y0, dx, dy, dd, px, py, r2):
    wx, wy = px - x0, py - y0
    dot = wx * dx + wy * dy
    cross = wx * dy - wy * dx
    return (dot >= 0.0) & (dot <= dd) & (cross * cross <= r2 * dd) & (dd > 0.0)


# ---------------------------------------------------------------------------
# One OMPL problem (runs inside a worker; imports ompl lazily)
# ---------------------------------------------------------------------------

def _set_ompl_log_level(ou, level: str) -> None:
    names = {"debug": "LOG_DEBUG", "info": "LOG_INFO", "warn": "LOG_WARN", "error": "LOG_ERROR",
             "none": "LOG_NONE"}
    ou.setLogLevel(getattr(ou.LogLevel, names[level]))


class OmplProblem:
    """BIT* on one environment, padding and budget; :meth:`solve` plans one query.

    Usable in-process too (it imports ``ompl`` when constructed), e.g. to
    benchmark; :func:`plan_bitstar` runs it in worker processes.

    Args:
        checker: the :class:`NumpyChecker` of the environment at the planning padding.
        time_budget: seconds of ``solve`` per query.
        stop_on_first: return at BIT*'s first solution instead of using the whole budget.
        motion_validator: ``"python"`` (the package's steer_to, default) or
            ``"ompl"`` (OMPL's discrete motion validator calling the Python state
            callback at ``robot.resolution``; for comparisons only).
        log_level: OMPL's log level (``"error"``, ``"warn"``, ``"info"``, ...).
    """

    def __init__(self, checker: NumpyChecker, time_budget: float, stop_on_first: bool = False,
                 motion_validator: str = "python", log_level: str = "error"):
        import ompl.base as ob
        import ompl.geometric as og
        import ompl.util as ou

        self.ob, self.og, self.ou = ob, og, ou
        _set_ompl_log_level(ou, log_level)
        self._log_level = log_level
        self.checker = checker
        self.time_budget = float(time_budget)
        self.stop_on_first = bool(stop_on_first)
        if motion_validator not in ("python", "ompl"):
            raise ValueError("motion_validator must be 'python' or 'ompl', "
                             f"got {motion_validator!r}")
        self.motion_validator = motion_validator
        self.n_valid = 0   # Python state-validity callbacks (cumulative)
        self.n_motion = 0  # Python motion-validator callbacks (cumulative)
        kind, d = checker.kind, checker.dim
        if kind == "rigid_body":
            space = ob.SE2StateSpace()
            bnd = ob.RealVectorBounds(2)
            bnd.setLow(0, checker.xmin)
            bnd.setHigh(0, checker.xmax)
            bnd.setLow(1, checker.ymin)
            bnd.setHigh(1, checker.ymax)
            space.setBounds(bnd)
            space.setSubspaceWeight(1, checker.angle_weight)  # SO(2) component: the metric's weight

            def get(s):
                return (s.getX(), s.getY(), s.getYaw())

            def put(s, q):
                s.setX(float(q[0]))
                s.setY(float(q[1]))
                s.setYaw(float(_wrap(float(q[2]))))

            rigid_valid = checker.rigid_valid

            def valid(s):
                self.n_valid += 1
                return rigid_valid(s.getX(), s.getY(), s.getYaw())
        else:
            space = ob.RealVectorStateSpace(d)
            bnd = ob.RealVectorBounds(d)
            for i in range(d):
                if kind == "nlink":  # the kernel's float32 bound, so queries at +-pi are inside
                    bnd.setLow(i, -PI32)
                    bnd.setHigh(i, PI32)
                else:
                    bnd.setLow(i, float(checker.bounds[i, 0]))
                    bnd.setHigh(i, float(checker.bounds[i, 1]))
            space.setBounds(bnd)
            rng = range(d)

            def get(s):
                return tuple(s[i] for i in rng)

            def put(s, q):
                for i in rng:
                    s[i] = float(q[i])

            one = checker.is_valid

            def valid(s):
                self.n_valid += 1
                return one([s[i] for i in rng])

        self.space, self._get, self._put, self._valid = space, get, put, valid
        steer = checker.steer_to
        outer = self

        class _SteerToMotionValidator(ob.MotionValidator):
            """Edges checked with the package's discretised steer_to (endpoints included)."""

            def checkMotion(self, s1, s2):  # noqa: N802 (OMPL's name)
                outer.n_motion += 1
                return steer(get(s1), get(s2))

        self._mv_class = _SteerToMotionValidator
        if kind != "point" and motion_validator == "ompl":
            extent = space.getMaximumExtent()
            self._segment_fraction = checker.resolution / extent
        else:
            self._segment_fraction = None

    def solve(self, start, goal, seed: int | None = None) -> dict[str, Any]:
        """Plans one query. Returns a dict: ``status``, ``path`` ((L, d) float64 or None),
        ``planner_cost``, ``solve_time``, ``n_valid``/``n_motion`` (Python callbacks in this
        query) and ``n_edges`` (motions BIT* checked)."""
        ob, og, ou = self.ob, self.og, self.ou
        start = np.asarray(start, np.float64)
        goal = np.asarray(goal, np.float64)
        out = {"status": NO_PATH, "path": None, "planner_cost": math.inf, "solve_time": 0.0,
               "n_valid": 0, "n_motion": 0, "n_edges": 0}
        if not (self.checker.is_valid(start) and self.checker.is_valid(goal)):
            out["status"] = INVALID
            return out
        if seed is not None:
            # Re-seeding after RNGs exist makes OMPL log an error ("changing seed now will not
            # lead to deterministic sampling"): it does reseed the generator, and every RNG of
            # the fresh planner below draws its seed from it. Keep that message out of the logs.
            ou.setLogLevel(ou.LogLevel.LOG_NONE)
            ou.RNG.setSeed(int(seed))
            _set_ompl_log_level(ou, self._log_level)
        n_valid0, n_motion0 = self.n_valid, self.n_motion
        ss = og.SimpleSetup(self.space)
        ss.setStateValidityChecker(self._valid)
        si = ss.getSpaceInformation()
        if self._segment_fraction is not None:
            si.setStateValidityCheckingResolution(self._segment_fraction)
        mv = None
        if self.motion_validator == "python" or self.checker.kind == "point":
            mv = self._mv_class(si)
            si.setMotionValidator(mv)
        s, g = self.space.allocState(), self.space.allocState()
        self._put(s, start)
        self._put(g, goal)
        ss.setStartAndGoalStates(s, g)
        ss.setOptimizationObjective(ob.PathLengthOptimizationObjective(si))
        planner = og.BITstar(si)
        if self.stop_on_first:
            planner.setStopOnSolnImprovement(True)
        ss.setPlanner(planner)
        t0 = time.perf_counter()
        ss.solve(self.time_budget)
        out["solve_time"] = time.perf_counter() - t0
        out["n_valid"] = self.n_valid - n_valid0
        out["n_motion"] = self.n_motion - n_motion0
        # edges checked by BIT* (OMPL counts them only in its own motion validators)
        out["n_edges"] = out["n_motion"] if mv is not None else int(si.getCheckedMotionCount())
        if ss.haveExactSolutionPath():
            p = ss.getSolutionPath()
            path = np.array([self._get(p.getState(i)) for i in range(p.getStateCount())],
                            np.float64)
            path[0], path[-1] = start, goal  # exactly the query (OMPL wraps SE(2) yaw)
            out.update(status=SOLVED, path=path, planner_cost=float(p.length()))
        del mv, planner, ss
        return out


# ---------------------------------------------------------------------------
# Worker process
# ---------------------------------------------------------------------------

def _worker_main(conn, env_json, padding, time_budget, stop_on_first, log_level,
                 crash_on) -> None:  # pragma: no cover (runs in a child process)
    """Worker loop: ``("task", [(idx, start, goal, seed, attempt), ...])`` or ``("stop",)``."""
    code = 0
    try:
        from ntq_jax.envs import Env

        env = Env.from_json(env_json)
        checker = NumpyChecker.from_env(env, padding)
        problem = OmplProblem(checker, time_budget, stop_on_first, log_level=log_level)
        conn.send(("ready", os.getpid()))
        while True:
            msg = conn.recv()
            if msg[0] != "task":
                break
            for idx, start, goal, seed, attempt in msg[1]:
                conn.send(("start", idx))
                if crash_on.get(idx, 0) > attempt:  # test hook: simulate a native crash
                    os._exit(70)
                try:
                    r = problem.solve(start, goal, seed)
                except Exception:  # noqa: BLE001 (reported per query, never raised)
                    conn.send(("error", idx, traceback.format_exc()))
                    continue
                conn.send(("done", idx, r))
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        code = 1
    except Exception:  # noqa: BLE001
        try:
            conn.send(("fatal", traceback.format_exc()))
        except Exception:  # noqa: BLE001
            pass
        code = 1
    finally:
        try:
            conn.close()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            # Skip interpreter shutdown: nanobind would report OMPL's "leaked instances".
            os._exit(code)


# ---------------------------------------------------------------------------
# Batched entry point
# ---------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class BitstarResult:
    """Per-query results of :func:`plan_bitstar` (N queries).

    Attributes:
        paths: list of N ``(L_i, d)`` float32 arrays, start first and goal last
            (exactly the query's states); ``None`` unless a path was found
            (status :data:`SOLVED` or :data:`REJECTED`).
        costs: ``(N,)`` float64 sum of ``env.distance`` over the path's
            segments; ``inf`` unless :data:`SOLVED`.
        status: ``(N,)`` int8: :data:`SOLVED` 0, :data:`NO_PATH` 1 (no solution
            within the budget), :data:`INVALID` 2, :data:`CRASHED` 3,
            :data:`REJECTED` 4 (see the module docstring).
        planner_costs: ``(N,)`` float64 BIT*'s own path length (OMPL's metric
            in float64; equals ``costs`` up to float32 rounding).
        solve_times: ``(N,)`` float64 seconds spent in OMPL's ``solve`` (0 unless planned).
        seeds: ``(N,)`` uint32 OMPL seed used for each query.
        info: run statistics: ``workers`` (processes started), ``worker_deaths``,
            ``startup_time`` (slowest worker's seconds from spawn to ready), ``wall_time``,
            ``n_valid_calls``, ``n_motion_calls`` (Python callbacks, summed),
            ``errors`` (query index -> traceback of a Python error in a worker).
    """

    paths: list
    costs: np.ndarray
    status: np.ndarray
    planner_costs: np.ndarray
    solve_times: np.ndarray
    seeds: np.ndarray
    info: dict

    @property
    def solved(self) -> np.ndarray:
        return self.status == SOLVED


def query_seeds(seed: int, n: int) -> np.ndarray:
    """The OMPL seed of each query: ``(n,)`` uint32 in ``[1, 2^31 - 1]``, from ``(seed, index)``."""
    out = np.empty(n, np.uint32)
    for i in range(n):
        v = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, i]).generate_state(1)[0]
        out[i] = int(v) % 2147483646 + 1
    return out


class _Worker:
    def __init__(self, ctx, args):
        parent, child = ctx.Pipe(duplex=True)
        self.conn = parent
        self.proc = ctx.Process(target=_worker_main, args=(child,) + args, daemon=True,
                                name="ntq_jax-bitstar")
        self.proc.start()
        child.close()
        self.assigned: list[int] = []  # indices sent and not finished
        self.current: int | None = None  # started, not finished
        self.since = time.monotonic()   # start of the current query (or of the process)
        self.spawned = self.since
        self.ready = False
        self.alive = True

    def kill(self):
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(timeout=5)
        self.conn.close()
        self.alive = False


def plan_bitstar(env, queries, *, time_budget: float, padding: float | None = None,
                 workers: int = 0, seed: int = 0, stop_on_first: bool = False,
                 chunk_size: int | None = None, ompl_log_level: str = "error",
                 hang_timeout: float | None = None, startup_timeout: float = 300.0,
                 _crash_on: Mapping[int, int] | None = None) -> BitstarResult:
    """Solves a batch of queries with OMPL's BIT* in parallel worker processes.

    Args:
        env: an :class:`ntq_jax.Env` with a rigid-body, n-link-arm or point robot.
        queries: ``(N, 2, d)`` start and goal states.
        time_budget: seconds of BIT* per query (the paper: 3 s rigid-body data
            generation, 2 s evaluation; 2/4/6 s and 1/2/4 s for the 2/4/6-link arm).
        padding: clearance of the planning geometry (default: the environment's).
        workers: worker processes; ``0`` = ``os.cpu_count()`` (never more than N).
        seed: base seed; query ``i`` uses ``query_seeds(seed, N)[i]``.
        stop_on_first: stop at the first solution instead of using the whole budget.
        chunk_size: queries sent to a worker at a time (default: N / (4 workers), 1..8).
        ompl_log_level: OMPL's log level in the workers (``"error"`` by default;
            ``"warn"``, ``"info"``, ``"debug"``, ``"none"``).
        hang_timeout: a worker stuck on one query longer than this is killed and
            treated as crashed (default ``3 * time_budget + 30`` s).
        startup_timeout: seconds a new worker may take to import and get ready.
        _crash_on: test hook, ``{query index: attempts}``: the worker calls
            ``os._exit`` when it starts that query on attempt ``< attempts``
            (``1`` = crash once, then solved on retry; ``2`` = status CRASHED).

    Returns:
        A :class:`BitstarResult`. Never raises for an unsolvable, invalid or
        crashing query; raises ``ValueError`` for malformed arguments.
    """
    from ntq_jax.envs import Env

    if not isinstance(env, Env):
        raise TypeError(f"env must be an ntq_jax.Env, got {type(env).__name__}")
    if env.robot.kind not in ("rigid_body", "nlink", "point"):
        raise ValueError(f"plan_bitstar: unsupported robot kind {env.robot.kind!r}")
    d = env.dim
    q = np.asarray(queries, np.float32)
    if q.ndim != 3 or q.shape[1:] != (2, d):
        raise ValueError(f"queries must have shape (N, 2, {d}) for {env.name}, got {q.shape}")
    if not (isinstance(time_budget, (int, float)) and math.isfinite(time_budget)
            and time_budget > 0):
        raise ValueError(f"time_budget must be a number of seconds > 0, got {time_budget!r}")
    if ompl_log_level not in _LOG_LEVELS:
        raise ValueError(f"ompl_log_level must be one of {_LOG_LEVELS}, got {ompl_log_level!r}")
    if importlib.util.find_spec("ompl") is None:
        raise ImportError("plan_bitstar needs OMPL's Python bindings: pip install 'ompl>=2.0.1'")
    pad = env.resolve_padding(padding)
    n = q.shape[0]
    workers = int(workers) if workers else (os.cpu_count() or 1)
    if workers < 1:
        raise ValueError(f"workers must be >= 0 (0 = os.cpu_count()), got {workers}")
    hang_timeout = 3.0 * time_budget + 30.0 if hang_timeout is None else float(hang_timeout)
    crash_on = dict(_crash_on or {})

    t_wall = time.perf_counter()
    status = np.full(n, NO_PATH, np.int8)
    paths: list = [None] * n
    planner_costs = np.full(n, np.inf)
    solve_times = np.zeros(n)
    seeds = query_seeds(seed, n)
    info: dict[str, Any] = {"workers": 0, "worker_deaths": 0, "startup_time": 0.0,
                            "n_valid_calls": 0, "n_motion_calls": 0, "errors": {}}

    # Invalid queries are decided here, with the package's own kernel (OMPL only warns).
    ok = _chunked(lambda x: env.is_valid(x, padding=pad), q.reshape(2 * n, d)).astype(bool)
    ok = ok.reshape(n, 2).all(axis=1)
    status[~ok] = INVALID
    todo = collections.deque(int(i) for i in np.flatnonzero(ok))
    if todo:
        _run_workers(env, q, pad, time_budget, stop_on_first, ompl_log_level, crash_on, seeds,
                     todo, min(workers, len(todo)), chunk_size, hang_timeout, startup_timeout,
                     status, paths, planner_costs, solve_times, info)

    costs = np.full(n, np.inf)
    _check_paths(env, pad, q, status, paths, costs)
    info["wall_time"] = time.perf_counter() - t_wall
    return BitstarResult(paths, costs, status, planner_costs, solve_times, seeds, info)


def _run_workers(env, q, pad, time_budget, stop_on_first, log_level, crash_on, seeds, todo,
                 n_workers, chunk_size, hang_timeout, startup_timeout,
                 status, paths, planner_costs, solve_times, info) -> None:
    if chunk_size is None:
        chunk_size = max(1, min(8, len(todo) // (4 * n_workers)))
    chunk_size = max(1, int(chunk_size))
    ctx = mp.get_context("spawn")
    args = (env.to_json(), pad, float(time_budget), bool(stop_on_first), log_level, crash_on)
    attempts = collections.Counter()  # crashes charged to each query
    remaining = set(todo)
    pool: list[_Worker] = []
    max_deaths = 2 * len(todo) + n_workers  # every death charges >= 1 query, each at most twice

    def spawn():
        w = _Worker(ctx, args)
        pool.append(w)
        info["workers"] += 1
        return w

    def feed(w):
        if w.assigned or not todo:
            return
        chunk = [todo.popleft() for _ in range(min(chunk_size, len(todo)))]
        w.assigned = list(chunk)
        w.since = time.monotonic()
        try:
            w.conn.send(("task", [(i, q[i, 0].tolist(), q[i, 1].tolist(), int(seeds[i]),
                                   attempts[i]) for i in chunk]))
        except OSError:  # the worker just died: its sentinel reports it next
            pass

    def finish(i, st):
        status[i] = st
        remaining.discard(i)

    startup_failures = [0]  # consecutive workers that died before getting ready

    def died(w, why):
        info["worker_deaths"] += 1
        w.kill()
        pool.remove(w)
        if not w.ready:
            startup_failures[0] += 1
        blamed = [w.current] if w.current is not None else list(w.assigned)
        for i in blamed:
            attempts[i] += 1
            if attempts[i] >= 2:
                finish(i, CRASHED)
                info["errors"].setdefault(i, why)
        for i in reversed(w.assigned):  # back to the front of the queue, in order
            if i in remaining:
                todo.appendleft(i)

    try:
        for _ in range(n_workers):
            spawn()
        while remaining:
            if startup_failures[0] >= 3 or info["worker_deaths"] > max_deaths:
                why = info["errors"].get("worker", "workers died before getting ready")
                warnings.warn("plan_bitstar: BIT* workers cannot start; the remaining "
                              f"{len(remaining)} queries are marked CRASHED:\n{why}",
                              RuntimeWarning, stacklevel=3)
                for i in list(remaining):
                    finish(i, CRASHED)
                break
            # keep enough workers for the work left
            while len(pool) < min(n_workers, len(remaining)):
                spawn()
            now = time.monotonic()
            for w in list(pool):
                limit = startup_timeout if not w.ready else hang_timeout if w.assigned else math.inf
                if now - w.since > limit:
                    died(w, f"worker killed after {now - w.since:.0f} s without progress")
            conns = {w.conn: w for w in pool}
            sentinels = {w.proc.sentinel: w for w in pool}
            for r in _mp_wait(list(conns) + list(sentinels), timeout=1.0):
                w = conns.get(r) or sentinels.get(r)
                if w not in pool:
                    continue
                was_ready = w.ready
                try:
                    # drain everything the worker sent before reacting to its exit
                    while w.conn.poll():
                        _handle(w, w.conn.recv(), finish, paths, planner_costs, solve_times, info)
                except (EOFError, OSError):
                    pass
                if w.ready and not was_ready:
                    startup_failures[0] = 0
                if not w.proc.is_alive() or r in sentinels:
                    w.proc.join(timeout=0.1)
                    if w.proc.exitcode is not None or not w.proc.is_alive():
                        died(w, f"worker exited with code {w.proc.exitcode}")
            # every idle ready worker gets work (a death may have re-queued queries)
            for w in pool:
                w.assigned = [i for i in w.assigned if i in remaining]
            lost = remaining.difference(todo, *(w.assigned for w in pool))
            if lost:  # pragma: no cover (invariant: unfinished = queued or assigned)
                todo.extend(sorted(lost))
            for w in pool:
                if w.ready:
                    feed(w)
    finally:
        for w in pool:
            try:
                w.conn.send(("stop",))
            except (OSError, ValueError):
                pass
        deadline = time.monotonic() + 5.0
        for w in pool:
            w.proc.join(timeout=max(0.0, deadline - time.monotonic()))
            w.kill()


def _handle(w, msg, finish, paths, planner_costs, solve_times, info) -> None:
    kind = msg[0]
    if kind == "ready":
        w.ready = True
        w.since = time.monotonic()
        info["startup_time"] = max(info["startup_time"], w.since - w.spawned)
    elif kind == "start":
        w.current = msg[1]
        w.since = time.monotonic()
    elif kind == "done":
        i, r = msg[1], msg[2]
        w.current = None
        w.since = time.monotonic()
        if r["path"] is not None:
            paths[i] = r["path"]
        planner_costs[i] = r["planner_cost"]
        solve_times[i] = r["solve_time"]
        info["n_valid_calls"] += r["n_valid"]
        info["n_motion_calls"] += r["n_motion"]
        finish(i, r["status"])
    elif kind == "error":
        i = msg[1]
        w.current = None
        info["errors"][i] = msg[2]
        warnings.warn(f"plan_bitstar: query {i} raised in the worker (status CRASHED):\n{msg[2]}",
                      RuntimeWarning, stacklevel=4)
        finish(i, CRASHED)
    elif kind == "fatal":  # the worker could not start; it exits next
        info["errors"].setdefault("worker", msg[1])


#: Rows per call of the parent's jitted checks: every call has this shape, so each
#: environment and padding compiles ``is_valid``, ``steer_to`` and ``distance`` once.
CHECK_CHUNK = 256


def _chunked(fn, *arrays) -> np.ndarray:
    """``fn(*arrays)`` over rows in fixed-size chunks (the last one padded with row 0)."""
    m = arrays[0].shape[0]
    out = []
    for lo in range(0, m, CHECK_CHUNK):
        part = [x[lo:lo + CHECK_CHUNK] for x in arrays]
        k = part[0].shape[0]
        part = [np.concatenate([x, np.repeat(x[:1], CHECK_CHUNK - k, 0)]) for x in part]
        out.append(np.asarray(fn(*part))[:k])
    return np.concatenate(out) if out else np.zeros(0)


def _check_paths(env, pad, q, status, paths, costs) -> None:
    """Float32 paths with exact endpoints; segments checked with env.steer_to; costs."""
    idx = [i for i, p in enumerate(paths) if p is not None]
    if not idx:
        return
    for i in idx:
        p = np.asarray(paths[i], np.float32)
        p[0], p[-1] = q[i, 0], q[i, 1]
        paths[i] = p
    a = np.concatenate([paths[i][:-1] for i in idx])
    b = np.concatenate([paths[i][1:] for i in idx])
    ok = _chunked(lambda x, y: env.steer_to(x, y, padding=pad), a, b)
    dist = _chunked(env.distance, a, b).astype(np.float64)
    pos = 0
    for i in idx:
        k = paths[i].shape[0] - 1
        seg_ok, seg_d = ok[pos:pos + k], dist[pos:pos + k]
        pos += k
        if status[i] != SOLVED:
            continue
        if seg_ok.all():
            costs[i] = float(seg_d.sum())
        else:
            status[i] = REJECTED


__all__ = ["plan_bitstar", "BitstarResult", "NumpyChecker", "OmplProblem", "query_seeds",
           "SOLVED", "NO_PATH", "INVALID", "CRASHED", "REJECTED", "STATUS_NAMES"]
