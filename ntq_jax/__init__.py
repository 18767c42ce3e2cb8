"""ntq_jax: non-trivial query sampling for efficient learning to plan, in JAX.

Public API (stable):

* :func:`make_env` -> :class:`Env` with ``is_valid``, ``steer_to``,
  ``sample_queries``, ``gamma_nt``, ``to_json`` (each geometry method takes
  ``padding=``: default the environment's, ``0`` for the evaluation geometry).
* :func:`plan` ``(env, queries, planner="astar" | "visgraph" | "bitstar" | "roadmap", **options)``
  -> :class:`PlanResult` (paths, lengths, costs, :class:`PlanStatus` per query);
  :func:`register_planner`; :class:`PlanCause` (the neural planner's outcomes).
"""

from ntq_jax.envs import Env, EnvError, make_env
from ntq_jax.geometry import World
from ntq_jax.planners import PlanResult, plan, register_planner
from ntq_jax.presets import PAPER_GAMMA, PRESETS
from ntq_jax.queries import NON_TRIVIAL, NT_EXHAUSTED, UNIFORM, FreeSpaceTooSmall, GammaEstimate
from ntq_jax.types import PlanCause, PlanStatus
from ntq_jax.version import __version__

__all__ = ["Env", "EnvError", "make_env", "World", "PRESETS", "PAPER_GAMMA", "GammaEstimate",
           "FreeSpaceTooSmall", "UNIFORM", "NON_TRIVIAL", "NT_EXHAUSTED", "plan", "PlanResult",
           "PlanStatus", "PlanCause", "register_planner", "__version__"]
