"""ntq_jax: non-trivial query sampling for efficient learning to plan, in JAX.

Public API (stable):

* :func:`make_env` -> :class:`Env` with ``is_valid``, ``steer_to``,
  ``sample_queries``, ``gamma_nt``, ``to_json`` (each geometry method takes
  ``padding=``: default the environment's, ``0`` for the evaluation geometry).
* :func:`plan` ``(env, queries, planner="astar" | "visgraph" | "bitstar" | "roadmap", **options)``
  -> :class:`PlanResult` (paths, lengths, costs, :class:`PlanStatus` per query);
  :func:`register_planner`; :class:`PlanCause` (the neural planner's outcomes).
* :func:`plan_batch` ``(env, pnet, queries, key, PlannerOptions(...))`` ->
  :class:`NeuralPlanResult`: the neural planner of the paper (Alg. 1) with a PNet
  ``pnet(key, current, goal) -> next``, or a list of PNets (the ensemble planner);
  :func:`plan_members` (every PNet on its own, all in one batch) and
  :func:`plan_cascade` (the PNets as fallbacks).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ntq_jax.lazy import lazy_exports
from ntq_jax.version import __version__

if TYPE_CHECKING:  # the names below, for type checkers and the API docs
    from ntq_jax.envs import Env, EnvError, make_env
    from ntq_jax.gamma import GammaEstimate
    from ntq_jax.geometry import World
    from ntq_jax.neural import (
        NeuralPlanResult,
        PlannerOptions,
        plan_batch,
        plan_cascade,
        plan_members,
    )
    from ntq_jax.planners import PlanResult, plan, register_planner
    from ntq_jax.presets import PAPER_GAMMA, PRESETS
    from ntq_jax.queries import NON_TRIVIAL, NT_EXHAUSTED, UNIFORM, FreeSpaceTooSmall
    from ntq_jax.types import PlanCause, PlanStatus

#: Where each public name lives. They load on first use (PEP 562), so a process that
#: imports only a JAX-free module of the package (the BIT* workers) never loads JAX.
_EXPORTS = {
    "Env": "ntq_jax.envs",
    "EnvError": "ntq_jax.envs",
    "make_env": "ntq_jax.envs",
    "World": "ntq_jax.geometry",
    "PlanResult": "ntq_jax.planners",
    "plan": "ntq_jax.planners",
    "register_planner": "ntq_jax.planners",
    "plan_batch": "ntq_jax.neural",
    "plan_members": "ntq_jax.neural",
    "plan_cascade": "ntq_jax.neural",
    "PlannerOptions": "ntq_jax.neural",
    "NeuralPlanResult": "ntq_jax.neural",
    "PRESETS": "ntq_jax.presets",
    "PAPER_GAMMA": "ntq_jax.presets",
    "GammaEstimate": "ntq_jax.gamma",
    "FreeSpaceTooSmall": "ntq_jax.queries",
    "UNIFORM": "ntq_jax.queries",
    "NON_TRIVIAL": "ntq_jax.queries",
    "NT_EXHAUSTED": "ntq_jax.queries",
    "PlanStatus": "ntq_jax.types",
    "PlanCause": "ntq_jax.types",
}

__all__ = [
    "Env",
    "EnvError",
    "make_env",
    "World",
    "PRESETS",
    "PAPER_GAMMA",
    "GammaEstimate",
    "FreeSpaceTooSmall",
    "UNIFORM",
    "NON_TRIVIAL",
    "NT_EXHAUSTED",
    "plan",
    "PlanResult",
    "PlanStatus",
    "PlanCause",
    "register_planner",
    "plan_batch",
    "plan_members",
    "plan_cascade",
    "PlannerOptions",
    "NeuralPlanResult",
    "__version__",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
