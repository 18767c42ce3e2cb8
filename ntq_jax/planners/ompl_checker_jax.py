"""The package's own JAX kernels as OMPL's callbacks: :class:`JaxChecker`, one state or motion a call.

OMPL asks for one state or one motion at a time. :class:`NumpyChecker`
(:mod:`ntq_jax.planners.ompl_checker`) re-implements the planar kernels in plain
Python for that; a robot whose kernels exist only in JAX (the 3-D serial arm: forward
kinematics, 59 spheres against cuboids and capsules, self-collision) is checked here by
the very kernels every other planner uses, one compiled call per callback:

* :meth:`JaxChecker.is_valid`: ``robot.is_valid`` at the planning padding;
* :meth:`JaxChecker.steer_to`: ``robot.steer_to``, the discretised check (states
  ``resolution`` apart, endpoints included; the point robot's exact test), the same
  answers as the batched ``Env.steer_to``, in the travelled direction.

Each is one compiled program per robot, padding and obstacle counts (the world is an
argument, so every problem of a MotionBenchMaker scene shares it), called on a
``(d,)`` float32 array (~50 us and ~70 us of CPU per call for the Panda), so a
planner in the same process (:func:`ntq_jax.planners.ompl_rrtconnect.plan_rrtconnect`,
:func:`~ntq_jax.planners.ompl_rrtconnect.plan_bitstar_jax`) sees exactly the package's
geometry. Not picklable: JAX programs stay in their process.
"""

from __future__ import annotations

import functools
import math

import jax
import numpy as np

from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS

__all__ = ["JaxChecker"]


@functools.partial(
    jax.jit, static_argnames=("robot", "padding"), compiler_options=KERNEL_COMPILER_OPTIONS
)
def _valid_one(robot, world, q, padding):
    return robot.is_valid(q, world, padding)


@functools.partial(
    jax.jit, static_argnames=("robot", "padding"), compiler_options=KERNEL_COMPILER_OPTIONS
)
def _steer_one(robot, world, a, b, padding):
    return robot.steer_to(a, b, world, padding)


class JaxChecker:
    """Validity and discretised ``steer_to`` of one environment and padding, a state a call.

    The interface :class:`ntq_jax.planners.ompl_worker.OmplProblem` reads: ``kind``,
    ``dim``, ``bounds`` (``(d, 2)``: the configuration box, the serial arm's joint
    limits), ``resolution``, :meth:`is_valid`, :meth:`steer_to` and :meth:`distance`;
    :meth:`compile` compiles both programs ahead of a timed solve.

    Args:
        env: the environment (a robot with a real-vector configuration space: the
            point robot, the n-link arm or the serial arm).
        padding: the planning clearance (None: the environment's).
    """

    def __init__(self, env, padding: float | None = None):
        robot, world = env.robot, env.world
        if robot.kind == "rigid_body":
            raise ValueError(
                "JaxChecker: the rigid body's SE(2) space is not supported; "
                "use the 'bitstar' planner (NumpyChecker) for it"
            )
        self.kind = robot.kind
        self.dim = int(robot.dim)
        self.padding = float(env.resolve_padding(padding))
        lo, hi = (np.asarray(v, np.float64) for v in robot.config_bounds(world))
        self.bounds = np.stack([lo, hi], axis=1)
        self.resolution = getattr(robot, "resolution", None)
        self._robot, self._world = robot, world
        self.n_valid = 0
        self.n_motion = 0

    def compile(self, q) -> None:
        """Compiles both programs (a state and a motion at ``q``) without counting the
        calls, so that no planner's time budget pays for the compilation."""
        q = np.asarray(q, np.float32)
        bool(_valid_one(self._robot, self._world, q, self.padding))
        bool(_steer_one(self._robot, self._world, q, q, self.padding))

    def is_valid(self, q) -> bool:
        """Whether state ``q`` (``d`` numbers) is valid at the padding."""
        self.n_valid += 1
        return bool(_valid_one(self._robot, self._world, np.asarray(q, np.float32), self.padding))

    def steer_to(self, a, b) -> bool:
        """Whether the straight motion ``a -> b`` passes the discretised check."""
        self.n_motion += 1
        return bool(
            _steer_one(
                self._robot,
                self._world,
                np.asarray(a, np.float32),
                np.asarray(b, np.float32),
                self.padding,
            )
        )

    def distance(self, a, b) -> float:
        """The Euclidean distance of two states (the cost metric of these robots)."""
        return math.dist(a, b)
