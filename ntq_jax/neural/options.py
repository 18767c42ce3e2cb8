"""The neural planner's contract: its options (:class:`PlannerOptions`) and its per-query results
(:class:`NeuralPlanResult`).

:mod:`ntq_jax.neural.driver` takes the one and returns the other.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ntq_jax.robots.certified import MOTION_CHECKS

__all__ = ["PlannerOptions", "NeuralPlanResult", "DELTA_NORMS", "ALGORITHM_VERSION", "STAGE_FIELDS"]

DELTA_NORMS = ("robot", "l2")
ALGORITHM_VERSION = 4  # bump when planning results change (saved evaluations are then redone)


#: The values of ``PlannerOptions.nosteer_check`` (see there).
NOSTEER_CHECKS = (True, False, "states", "replan")


#: The fields the coarse plan reads once the ends' validity is given (``"coarse_plan"``).
_COARSE_PLAN_FIELDS = (
    "n_plan",
    "steer",
    "delta",
    "delta_norm",
    "nosteer_check",
    "replan_rounds",
    "replan_steps",
    "bidirectional",
    "plan_padding",
)

#: The :class:`PlannerOptions` fields each compiled stage of the neural planner reads
#: (:mod:`ntq_jax.neural.steps`; a test traces each stage and checks it reads no other).
STAGE_FIELDS = {
    "coarse": _COARSE_PLAN_FIELDS + ("eval_padding",),
    "coarse_plan": _COARSE_PLAN_FIELDS,
    "valid": ("eval_padding",),
    "connect": ("replan_steps", "plan_padding"),
    "check": ("steer", "nosteer_check", "contract", "plan_padding", "eval_padding", "eval_check"),
}


@dataclasses.dataclass(frozen=True)
class PlannerOptions:
    """Static settings of the neural planner (hashable: part of the compile key).

    Attributes:
        n_plan: PNet iterations of the coarse plan (``N_plan`` of Alg. 1).
        steer: use ``steerTo`` (Alg. 1); False is the paper's variant without it.
        delta: goal tolerance of the variant without steerTo, in the robot's cost metric
            (``robot.distance``: Euclidean for the point robot and the arm's joints;
            ``||dp|| + angle_weight * |dtheta|`` on the shortest arc for the rigid body).
        delta_norm: the goal test's distance without steerTo: ``"robot"`` (the robot's
            metric, above) or ``"l2"`` (``||pi_end - x_g||_2`` on the raw state
            vector, angles not wrapped: the paper's text, Sec. V).
        nosteer_check: without steerTo, a reached path counts as a success only if
            every segment passes the feasibility check (True); False is the paper's
            "only executing the lines 8 and 9" (success once the goal test passes);
            ``"states"``: only if every state of the path is valid (the segments
            between them not checked); ``"replan"``: Alg. 1 with only the test of
            line 4 replaced by the goal test: a path that reaches it gets the goal
            appended (so the goal is in the path, line 10), then lines 11-14 run as
            with steerTo (contraction, every segment checked, neural replanning,
            whose connections use the planner's steerTo).
        replan_rounds: neural replanning rounds (0 disables replanning).
        replan_steps: PNet predictions per repaired segment.
        bidirectional: MPNet's bidirectional coarse plan instead of Alg. 1's forward one.
        contract: lazy states contraction after the coarse plan and after each repair.
        plan_padding: clearance of the planner's own steerTo calls.
        eval_padding: clearance of the feasibility check (0 = the evaluation geometry).
        eval_check: the motion check of the feasibility check (and so of success and
            of which segments replanning repairs): ``"certified"`` (every
            configuration proven clear; :mod:`ntq_jax.robots.certified`) or
            ``"discretized"`` (states ``resolution`` apart, the paper's check). The
            planner's own steerTo calls use the discretised check, as in the paper.
    """

    n_plan: int = 50
    steer: bool = True
    delta: float = 1.0
    delta_norm: str = "robot"
    nosteer_check: bool | str = True
    replan_rounds: int = 5
    replan_steps: int = 20
    bidirectional: bool = False
    contract: bool = True
    plan_padding: float = 0.0
    eval_padding: float = 0.0
    eval_check: str = "certified"

    def __post_init__(self):
        if self.eval_check not in MOTION_CHECKS:
            raise ValueError(f"eval_check must be one of {MOTION_CHECKS}, got {self.eval_check!r}")
        if self.delta_norm not in DELTA_NORMS:
            raise ValueError(f"delta_norm must be one of {DELTA_NORMS}, got {self.delta_norm!r}")
        if self.nosteer_check not in NOSTEER_CHECKS:
            raise ValueError(
                f"nosteer_check must be True, False, 'states' or 'replan', got "
                f"{self.nosteer_check!r}"
            )
        if self.n_plan < 1:
            raise ValueError(f"n_plan must be >= 1, got {self.n_plan}")
        if not (self.delta > 0 and math.isfinite(self.delta)):
            raise ValueError(f"delta must be > 0, got {self.delta}")
        if self.replan_rounds < 0 or self.replan_steps < 1:
            raise ValueError(
                "replan_rounds must be >= 0 and replan_steps >= 1, got "
                f"{self.replan_rounds}, {self.replan_steps}"
            )
        for name in ("plan_padding", "eval_padding"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")

    @property
    def repairs(self) -> bool:
        """Whether Alg. 1's lines 10-14 run as with steerTo: the goal appended once reached,
        contraction and neural replanning (with steerTo, or ``nosteer_check="replan"``)."""
        return self.steer or self.nosteer_check == "replan"

    @property
    def max_len(self) -> int:
        """Rows of the path buffer: coarse plan plus what replanning can add."""
        rounds = self.replan_rounds if self.repairs else 0
        return self.n_plan + 2 + rounds * self.replan_steps

    def for_stage(self, stage: str) -> "PlannerOptions":
        """These options reduced to the fields the planner's stage ``stage`` reads
        (:data:`STAGE_FIELDS`), the others at their defaults. The stage computes the same
        with either; its compile key holds the reduced options, so option sets that differ
        only where a stage does not look share its compiled program."""
        return type(self)(**{f: getattr(self, f) for f in STAGE_FIELDS[stage]})


@dataclasses.dataclass(frozen=True)
class NeuralPlanResult:
    """Per-query results of :func:`plan_batch` (N queries, host NumPy arrays).

    Attributes:
        paths: ``(N, L, d)`` float32 states, start first; NaN after ``lengths[i]`` rows.
            Failed queries keep their last (coarse or partly repaired) path for inspection.
        lengths: ``(N,)`` int32 number of states.
        success: ``(N,)`` bool: reached the goal and collision-free on the evaluation geometry.
        costs: ``(N,)`` float64 path cost (the robot's metric); ``inf`` unless success.
        cause: ``(N,)`` int8 :class:`ntq_jax.types.PlanCause` values.
        pnet_calls: ``(N,)`` int32 PNet predictions spent on the query (the ensemble
            planner counts every member's).
        replans: ``(N,)`` int32 replanning rounds the query went through.
        seconds: wall time of the batch (compiled calls only); ``compile_seconds``:
            time spent compiling for this call (0 when the compiled code was reused).
        member: ``(N,)`` int8, for :func:`plan_cascade` only: the PNet whose path is kept.
    """

    paths: np.ndarray
    lengths: np.ndarray
    success: np.ndarray
    costs: np.ndarray
    cause: np.ndarray
    pnet_calls: np.ndarray
    replans: np.ndarray
    seconds: float = 0.0
    compile_seconds: float = 0.0
    member: np.ndarray | None = None

    def path(self, i: int) -> np.ndarray:
        """Query ``i``'s path ``(lengths[i], d)``."""
        return self.paths[i, : self.lengths[i]]
