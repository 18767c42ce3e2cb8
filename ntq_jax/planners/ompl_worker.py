"""One OMPL BIT* problem and the worker process that solves queries with it.

:class:`OmplProblem` runs BIT* (PyPI ``ompl`` 2.x, nanobind bindings) on one
:class:`~ntq_jax.planners.ompl_checker.NumpyChecker` (robot, world, padding)
and budget; :meth:`OmplProblem.solve` plans one query and reports a
:class:`BridgeOutcome`. BIT*'s notion of a valid state and a valid edge is the
package's: states through the checker, edges through a Python
``MotionValidator`` running the checker's discretised ``steer_to`` (one
callback per edge). The objective is path length in the robot's metric (SE(2)
with the SO(2) weight set to ``robot.angle_weight``; Euclidean joint distance
for the arm, joint bounds ``[-pi, pi]`` as the kernel applies them in float32).

:func:`worker_main` is the loop of one worker process of
:mod:`ntq_jax.planners.ompl_bridge`: it receives the pickled checker (no
environment is rebuilt) and leaves with ``os._exit`` so nanobind's "leaked
instances" report at interpreter shutdown is never printed. This module and the
checker import only NumPy (and ``ompl`` when a problem is built), and the packages'
``__init__`` modules load their names lazily, so a worker never loads JAX.
"""

from __future__ import annotations

import enum
import math
import os
import sys
import time
import traceback
from typing import Any

import numpy as np

from ntq_jax.planners.ompl_checker import PI32, NumpyChecker, wrap_angle

__all__ = ["BridgeOutcome", "OmplProblem", "worker_main", "LOG_LEVELS"]


class BridgeOutcome(enum.IntEnum):
    """The bridge's own per-query outcome (``info["bitstar_status"]``, int8).

    :func:`ntq_jax.planners.ompl_bridge.plan_bitstar` maps it to
    :class:`ntq_jax.types.PlanStatus` in one table.
    """

    EXACT = 0  #: BIT* found an exact solution
    NOT_FOUND = 1  #: no exact solution within the time budget (unsolvable or timed out)
    BAD_QUERY = 2  #: start or goal invalid at the planning padding (checked before planning)
    CRASHED = 3  #: the worker died on this query twice (or raised: see ``info["errors"]``)
    REJECTED = 4  #: BIT*'s path failed the package's ``steer_to`` (float32 tangency)


_OMPL_LOG_LEVELS = {
    "debug": "LOG_DEBUG",
    "info": "LOG_INFO",
    "warn": "LOG_WARN",
    "error": "LOG_ERROR",
    "none": "LOG_NONE",
}
LOG_LEVELS = tuple(_OMPL_LOG_LEVELS)


def _set_ompl_log_level(ou, level: str) -> None:
    ou.setLogLevel(getattr(ou.LogLevel, _OMPL_LOG_LEVELS[level]))


class OmplProblem:
    """BIT* (or RRT-Connect) on one environment, padding and budget; :meth:`solve` plans one query.

    Usable in-process too (it imports ``ompl`` when constructed), e.g. to
    benchmark; :func:`ntq_jax.planners.ompl_bridge.plan_bitstar` runs it in
    worker processes, :func:`ntq_jax.planners.ompl_rrtconnect.plan_rrtconnect` and
    :func:`~ntq_jax.planners.ompl_rrtconnect.plan_bitstar_jax` in their own process
    with the package's JAX kernels.

    Args:
        checker: the :class:`NumpyChecker` of the environment at the planning padding,
            or a :class:`~ntq_jax.planners.ompl_checker_jax.JaxChecker` (a robot with a
            real-vector space: ``checker.bounds`` ``(d, 2)`` is the box).
        time_budget: seconds of ``solve`` per query. BIT* keeps improving its
            solution for the whole budget unless ``stop_on_first``; either way it
            returns at once when its solution is provably optimal (a 2-state path).
        stop_on_first: return at BIT*'s first solution instead of using the whole budget.
        motion_validator: ``"python"`` (the package's steer_to, default) or
            ``"ompl"`` (OMPL's discrete motion validator calling the Python state
            callback at ``robot.resolution``; for comparisons only).
        log_level: OMPL's log level (``"error"``, ``"warn"``, ``"info"``, ...).
        planner: ``"bitstar"`` (default) or ``"rrtconnect"`` (OMPL's RRT-Connect: it
            returns at its first solution).
        simplify: simplify a found path with OMPL's ``PathSimplifier.simplifyMax``
            (vertex reduction, shortcuts, B-spline smoothing; every new motion checked
            by the same motion validator) before it is returned.
        range_: RRT-Connect's longest extension (None: OMPL's default, a fifth of
            the space's extent).
    """

    def __init__(
        self,
        checker: NumpyChecker,
        time_budget: float,
        stop_on_first: bool = False,
        motion_validator: str = "python",
        log_level: str = "error",
        planner: str = "bitstar",
        simplify: bool = False,
        range_: float | None = None,
    ):
        import ompl.base as ob
        import ompl.geometric as og
        import ompl.util as ou

        if motion_validator not in ("python", "ompl"):
            raise ValueError(
                f"motion_validator must be 'python' or 'ompl', got {motion_validator!r}"
            )
        if planner not in ("bitstar", "rrtconnect"):
            raise ValueError(f"planner must be 'bitstar' or 'rrtconnect', got {planner!r}")
        self.planner, self.simplify, self.range = planner, bool(simplify), range_
        self.ob, self.og, self.ou = ob, og, ou
        _set_ompl_log_level(ou, log_level)
        self._log_level = log_level
        self.checker = checker
        self.time_budget = float(time_budget)
        self.stop_on_first = bool(stop_on_first)
        self.motion_validator = motion_validator
        self.n_valid = 0  # Python state-validity callbacks (cumulative)
        self.n_motion = 0  # Python motion-validator callbacks (cumulative)
        if checker.kind == "rigid_body":
            self.space, self._get, self._put, self._valid = self._se2_space()
        else:
            self.space, self._get, self._put, self._valid = self._real_vector_space()
        self._mv_class = self._steer_to_motion_validator()
        if checker.kind != "point" and motion_validator == "ompl":
            self._segment_fraction = checker.resolution / self.space.getMaximumExtent()
        else:
            self._segment_fraction = None

    def _se2_space(self):
        """SE(2) on the workspace bounds, the SO(2) component weighted as the robot's metric."""
        ob, checker = self.ob, self.checker
        space = ob.SE2StateSpace()
        bnd = ob.RealVectorBounds(2)
        bnd.setLow(0, checker.xmin)
        bnd.setHigh(0, checker.xmax)
        bnd.setLow(1, checker.ymin)
        bnd.setHigh(1, checker.ymax)
        space.setBounds(bnd)
        space.setSubspaceWeight(1, checker.angle_weight)

        def get(s):
            return (s.getX(), s.getY(), s.getYaw())

        def put(s, q):
            s.setX(float(q[0]))
            s.setY(float(q[1]))
            s.setYaw(float(wrap_angle(float(q[2]))))

        rigid_valid = checker.rigid_valid

        def valid(s):
            self.n_valid += 1
            return rigid_valid(s.getX(), s.getY(), s.getYaw())

        return space, get, put, valid

    def _real_vector_space(self):
        """R^d: the arm's joints in ``[-PI32, PI32]``, or the point robot's workspace."""
        ob, checker = self.ob, self.checker
        d = checker.dim
        space = ob.RealVectorStateSpace(d)
        bnd = ob.RealVectorBounds(d)
        for i in range(d):
            if checker.kind == "nlink":  # the kernel's float32 bound, so queries at +-pi are inside
                bnd.setLow(i, -PI32)
                bnd.setHigh(i, PI32)
            elif checker.kind == "serial_arm":  # the joint limits, as float32 (the kernel's)
                bnd.setLow(i, float(np.float32(checker.bounds[i, 0])))
                bnd.setHigh(i, float(np.float32(checker.bounds[i, 1])))
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

        return space, get, put, valid

    def _steer_to_motion_validator(self):
        """An ``ob.MotionValidator`` subclass checking each edge with the checker's steer_to."""
        steer, get, outer = self.checker.steer_to, self._get, self

        class _SteerToMotionValidator(self.ob.MotionValidator):
            """Edges checked with the package's discretised steer_to (endpoints included)."""

            def checkMotion(self, s1, s2):  # noqa: N802 (OMPL's name)
                outer.n_motion += 1
                return steer(get(s1), get(s2))

        return _SteerToMotionValidator

    def solve(self, start, goal, seed: int | None = None) -> dict[str, Any]:
        """Plans one query. Returns a dict: ``outcome`` (a :class:`BridgeOutcome` value),
        ``path`` ((L, d) float64, exactly ``start`` first and ``goal`` last, or None),
        ``planner_cost`` (the planner's own path length, after simplification when
        ``simplify``), ``solve_time``, ``simplify_time``, ``n_valid``/``n_motion``
        (Python callbacks in this query) and ``n_edges`` (motions the planner checked)."""
        start = np.asarray(start, np.float64)
        goal = np.asarray(goal, np.float64)
        out = {
            "outcome": int(BridgeOutcome.NOT_FOUND),
            "path": None,
            "planner_cost": math.inf,
            "solve_time": 0.0,
            "simplify_time": 0.0,
            "n_valid": 0,
            "n_motion": 0,
            "n_edges": 0,
        }
        if not (self.checker.is_valid(start) and self.checker.is_valid(goal)):
            out["outcome"] = int(BridgeOutcome.BAD_QUERY)
            return out
        if seed is not None:
            self._reseed(int(seed))
        n_valid0, n_motion0 = self.n_valid, self.n_motion
        ss, si, mv, keep = self._setup(start, goal)
        t0 = time.perf_counter()
        ss.solve(self.time_budget)
        out["solve_time"] = time.perf_counter() - t0
        if self.simplify and ss.haveExactSolutionPath():
            t1 = time.perf_counter()
            self.og.PathSimplifier(si).simplifyMax(ss.getSolutionPath())
            out["simplify_time"] = time.perf_counter() - t1
        out["n_valid"] = self.n_valid - n_valid0
        out["n_motion"] = self.n_motion - n_motion0
        # edges checked by BIT* (OMPL counts them only in its own motion validators)
        out["n_edges"] = out["n_motion"] if mv is not None else int(si.getCheckedMotionCount())
        if ss.haveExactSolutionPath():
            p = ss.getSolutionPath()
            path = np.array(
                [self._get(p.getState(i)) for i in range(p.getStateCount())], np.float64
            )
            path[0], path[-1] = start, goal  # exactly the query (OMPL wraps SE(2) yaw)
            out.update(outcome=int(BridgeOutcome.EXACT), path=path, planner_cost=float(p.length()))
        del mv, keep, ss
        return out

    def _reseed(self, seed: int) -> None:
        """Re-seeds OMPL's global seed generator; every RNG of the next planner draws from it."""
        ou = self.ou
        # Re-seeding after RNGs exist makes OMPL log an error ("changing seed now will not
        # lead to deterministic sampling"): it does reseed the generator. Keep it out of the logs.
        ou.setLogLevel(ou.LogLevel.LOG_NONE)
        ou.RNG.setSeed(seed)
        _set_ompl_log_level(ou, self._log_level)

    def _setup(self, start: np.ndarray, goal: np.ndarray):
        """A fresh ``SimpleSetup`` with BIT* for one query: ``(ss, space information, motion
        validator or None, (planner, start, goal))``; the caller keeps them all alive while
        it solves."""
        ob, og = self.ob, self.og
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
        if self.planner == "rrtconnect":
            planner = og.RRTConnect(si)
            if self.range is not None:
                planner.setRange(float(self.range))
        else:
            planner = og.BITstar(si)
            if self.stop_on_first:
                planner.setStopOnSolnImprovement(True)
        ss.setPlanner(planner)
        return ss, si, mv, (planner, s, g)


def worker_main(
    conn,
    checker: NumpyChecker,
    time_budget: float,
    stop_on_first: bool,
    log_level: str,
    crash_on: dict,
) -> None:  # pragma: no cover (child process)
    """Worker loop: ``("task", [(idx, start, goal, seed, attempt), ...])`` or ``("stop",)``.

    Sends ``("ready", pid)`` once, then per query ``("start", idx)`` and
    ``("done", idx, solve() dict)`` or ``("error", idx, traceback)``;
    ``("fatal", traceback)`` if it cannot start. ``crash_on`` is a test hook
    (``{idx: attempts}``: ``os._exit`` when starting ``idx`` on an attempt below it).
    """
    code = 0
    try:
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
