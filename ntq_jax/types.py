"""The shared contracts: planning statuses, the one planning result, the planner protocol.

Every planner of the package (grid A*, visibility graph, OMPL BIT*, a user's
own through :func:`ntq_jax.register_planner`) returns a :class:`PlanResult`
whose ``status`` holds :class:`PlanStatus` values; each backend maps its own
codes to these once, in its adapter. The neural planner reports a
:class:`PlanCause` per query instead (it judges success on the evaluation
geometry, after replanning). Nothing else in the package defines a status code.
"""

from __future__ import annotations

import enum
from typing import Any, NamedTuple, Protocol

import numpy as np

__all__ = [
    "PlanStatus",
    "PlanCause",
    "STATUS_NAMES",
    "CAUSE_NAMES",
    "QUERY_KINDS",
    "PlanResult",
    "PlannerFn",
]


class PlanStatus(enum.IntEnum):
    """Per-query outcome of a classical planner (stored as int8)."""

    SOLVED = 0  #: a path was found and every segment passed ``steer_to`` at the planning padding
    NO_PATH = (
        1  #: no path (proved on the planner's representation, or the found path failed the check)
    )
    TIMEOUT = 2  #: the planner's budget ran out (BIT*'s time budget, A*'s buffers)
    INVALID = 3  #: start or goal is not a valid state at the planning padding (or not finite)


class PlanCause(enum.IntEnum):
    """Per-query outcome of the neural planner (stored as int8 in saved evaluations)."""

    SUCCESS = 0  #: reached the goal, collision-free on the evaluation geometry
    NO_PATH = 1  #: goal not reached within ``n_plan`` steps (Alg. 1's empty path)
    INFEASIBLE = 2  #: reached but still in collision after replanning
    INVALID_QUERY = 3  #: start or goal invalid on the evaluation geometry, or not finite


#: Outcomes from a success to the farthest failure: a combination of several planners'
#: attempts on a query keeps the attempt of lowest rank (an infeasible path is closer to a
#: success than no path, which is closer than an invalid query).
CAUSE_RANK = {
    PlanCause.SUCCESS: 0,
    PlanCause.INFEASIBLE: 1,
    PlanCause.NO_PATH: 2,
    PlanCause.INVALID_QUERY: 3,
}

#: :class:`PlanStatus` -> its lower-case name (``"solved"``, ``"no_path"``, ...).
STATUS_NAMES = {s: s.name.lower() for s in PlanStatus}
CAUSE_NAMES = {c: c.name.lower() for c in PlanCause}

#: The task (the paper's table: point robot, rigid body, n-link arm) of each robot kind.
TASK_OF_ROBOT = {"point": "point", "rigid_body": "rigid", "nlink": "nlink"}

#: The two test-query sets of an evaluation, in table order (names in its saved files).
QUERY_KINDS = ("uniform", "nontrivial")


class PlanResult(NamedTuple):
    """Per-query planning results (K queries), the same for every planner.

    Attributes:
        paths: ``(K, L, d)`` float32 waypoints, start first and goal last (exactly
            the query's states), NaN-padded after ``lengths[i]``.
        lengths: ``(K,)`` int32 number of waypoints (0 unless solved).
        costs: ``(K,)`` float64 path cost in the robot's metric, inf unless solved.
        status: ``(K,)`` int8 :class:`PlanStatus` values.
        info: planner-specific statistics (times, counts).
    """

    paths: np.ndarray
    lengths: np.ndarray
    costs: np.ndarray
    status: np.ndarray
    info: dict

    @property
    def solved(self) -> np.ndarray:
        """``(K,)`` bool, status == SOLVED."""
        return self.status == PlanStatus.SOLVED

    def path(self, i: int) -> np.ndarray | None:
        """Query ``i``'s path ``(lengths[i], d)``, or None unless solved."""
        return self.paths[i, : self.lengths[i]] if self.status[i] == PlanStatus.SOLVED else None


class PlannerFn(Protocol):
    """A classical planner as the registry calls it.

    ``queries`` is ``(K, 2, d)`` float32 (start, goal); ``padding`` is already
    resolved to a number (the planning clearance); ``seed`` seeds randomised
    planners. An unsolvable query is a status, never an exception.
    """

    def __call__(
        self, env: Any, queries: np.ndarray, *, padding: float, seed: int, **options: Any
    ) -> PlanResult: ...
