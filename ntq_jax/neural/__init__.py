"""The neural planner of the paper (Alg. 1, after MPNet), batched over queries (re-exports only).

* :mod:`~ntq_jax.neural.driver`: :func:`plan_batch` (one PNet, or several as the ensemble
  planner), :func:`plan_members` (every PNet on its own, all in one batch),
  :func:`plan_cascade` (the PNets as fallbacks), :func:`as_pnet`, :func:`padded_world`;
* :mod:`~ntq_jax.neural.options`: :class:`PlannerOptions` and :class:`NeuralPlanResult`;
* :mod:`~ntq_jax.neural.repair`: neural replanning on the host (repair windows, splices)
  and the per-query state of a batch;
* :mod:`~ntq_jax.neural.steps`: the jitted steps and their bounded cache of compiled programs;
* :mod:`~ntq_jax.neural.host_stages`: the checks on the host, through the shared batched
  programs, for robots whose checks are costly to compile (the 3-D arm);
* :mod:`~ntq_jax.neural.proposals`: the ensemble planner's proposals (:class:`EnsemblePNet`,
  :func:`choose`);
* :mod:`~ntq_jax.neural.motions`: the motion checks inside the jitted steps.
"""

from ntq_jax.neural.driver import as_pnet, padded_world, plan_batch, plan_cascade, plan_members
from ntq_jax.neural.options import NeuralPlanResult, PlannerOptions
from ntq_jax.neural.proposals import EnsemblePNet, choose

__all__ = [
    "plan_batch",
    "plan_members",
    "plan_cascade",
    "as_pnet",
    "padded_world",
    "PlannerOptions",
    "NeuralPlanResult",
    "EnsemblePNet",
    "choose",
]
