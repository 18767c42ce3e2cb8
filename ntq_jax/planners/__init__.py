"""Classical planners behind one entry point: :func:`plan` (a registry of planner functions).

Usage::

    import ntq_jax
    env = ntq_jax.make_env("point/3")
    res = ntq_jax.plan(env, queries)                         # grid A* + shortcutting
    res = ntq_jax.plan(env, queries, "visgraph", padding=0)  # exact point-robot optimum
    res = ntq_jax.plan(env, queries, "bitstar", time_budget=2.0, workers=2)
    res = ntq_jax.plan(env, queries, "roadmap", milestones=20_000)  # any robot, many queries
    res = ntq_jax.plan(panda, panda.query[None], "bitree", check="certified")  # one query a map

Every planner takes ``queries`` ``(K, 2, d)`` (start, goal) and returns a
:class:`PlanResult` with, per query, a NaN-padded path (start first and goal
last, exactly the query's float32 states), its waypoint count, its cost in the
``env.distance`` metric (float64 sum over segments) and a :class:`PlanStatus`:

* ``SOLVED``: a path was found and EVERY segment passed ``env.steer_to`` at the
  planning padding (:mod:`ntq_jax.planners.verify` checks every planner);
* ``NO_PATH``: the planner proved (on its own representation) there is no
  path, or the path it found failed the exact check;
* ``TIMEOUT``: the planner's budget ran out (BIT*'s time budget; A*'s
  open-list / path buffers);
* ``INVALID``: the start or the goal is not a valid state at the planning
  padding (or not finite).

An unsolvable query never raises. ``padding=None`` plans in the environment's
own (data-generation) geometry, ``padding=0`` in the evaluation geometry.

Planners
--------
``"astar"`` (2-D configuration spaces: the point robot and the 2-link arm)
    :func:`ntq_jax.planners.astar_planner.plan_astar`: the configuration box gridded at
    ``resolution`` (default 0.1), batched exact grid A* (jump point search),
    greedy shortcutting (``smooth=True``). Options: ``resolution``, ``smooth``,
    ``chunk_size``, ``smooth_chunk`` and any :func:`ntq_jax.planners.astar.astar`
    option (``open_capacity``, ``max_path_len``, ...).
``"visgraph"`` (point robot only)
    :func:`ntq_jax.planners.visgraph.plan_visgraph` (exact at padding 0 for
    boxes, see :mod:`ntq_jax.planners.visgraph`). Options: ``eps``,
    ``arc_step``, ``chunk_size``.
``"bitstar"`` (any robot; OMPL's BIT* in worker processes)
    :func:`ntq_jax.planners.ompl_bridge.plan_bitstar`. Options:
    ``time_budget`` (seconds per query, default 1.0), ``workers`` (0 = cores)
    and the other ``plan_bitstar`` options. BIT* is anytime: no solution within
    the budget is a TIMEOUT, not a proof that there is none (the bridge's own
    outcomes map to statuses in ``ompl_bridge.PLAN_STATUS``). On a 3-D serial arm
    (the Panda: no NumPy geometry for the workers) ``"bitstar"`` is
    ``"bitstar_jax"`` below (``workers`` and the other process options ignored).

``"roadmap"`` (any robot; many queries in one environment)
    :func:`ntq_jax.planners.roadmap.plan_roadmap`: a PRM* roadmap built once per
    environment and settings (cached in memory, and on disk with ``cache_dir``),
    A* per query (the robot's metric to the goal as heuristic), shortcutting.
    Options: ``milestones`` (default 20,000), ``k`` (default PRM*'s rule),
    ``grow_rounds``, ``roadmap_seed``, ``cache_dir``, ``attach``, ``edge_check``,
    ``end_rounds``; a 3-D serial arm (the Panda) has its own defaults
    (``roadmap.ARM_DEFAULTS``: 4,000 milestones, k 10, discretised edges with only
    the final segments checked by ``check``, e.g. certified).
``"bitree"`` (any robot; one query per map, e.g. MotionBenchMaker's problems)
    :func:`ntq_jax.planners.bitree.plan_bitree`: a batched bidirectional tree
    (RRT-Connect-like) and its shortcut in one compiled program per query, retried
    with the next key when the trees do not meet or the path fails ``check``.
    Options: ``batch``, ``step``, ``capacity``, ``iterations``, ``attempts``,
    ``path_cap``, ``split``.
``"rrtconnect"`` (point robot, n-link arm, serial arm; OMPL in this process)
    :func:`ntq_jax.planners.ompl_rrtconnect.plan_rrtconnect`: OMPL's RRT-Connect
    and path simplification on the package's JAX validity and discretised motion
    checks, one compiled call per callback: the in-CI peer for the Panda. Options:
    ``time_budget``, ``simplify``, ``range_``, ``ompl_log_level``.
``"bitstar_jax"`` (point robot, n-link arm, serial arm; OMPL in this process)
    :func:`ntq_jax.planners.ompl_rrtconnect.plan_bitstar_jax`: OMPL's BIT* (its
    default parameters, as the paper) on the same JAX checks, one query after
    another; what ``"bitstar"`` runs on the Panda. Each check is a compiled call
    (~60-270 us), so BIT* explores less in a budget than with a native checker (on
    the Panda at 6 s the checks take 19 % of it; ``info``: ``n_valid_per_query``,
    ``n_motion_per_query``). Options:
    ``time_budget`` (default 1.0), ``stop_on_first``, ``check``, ``ompl_log_level``.
``"vamp"`` (the Panda; needs ``vamp``, built from source)
    :func:`ntq_jax.planners.vamp_bridge.plan_vamp`: VAMP's RRT-Connect and
    simplification, its paths verified by the package. Options: ``simplify``,
    ``sampler``.

Register your own with :func:`register_planner`. Measurements: BENCHMARKS.md
("Classical planners").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ntq_jax.lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and the API docs
    from ntq_jax.planners.astar_planner import config_grid
    from ntq_jax.planners.registry import available_planners, plan, register_planner
    from ntq_jax.planners.verify import check_paths, finalize, valid_queries
    from ntq_jax.types import STATUS_NAMES, PlanResult, PlanStatus

#: Where each public name lives. They load on first use (PEP 562): a BIT* worker process
#: imports :mod:`ntq_jax.planners.ompl_worker` (NumPy and OMPL only) without loading JAX.
_EXPORTS = {
    "plan": "ntq_jax.planners.registry",
    "register_planner": "ntq_jax.planners.registry",
    "available_planners": "ntq_jax.planners.registry",
    "PlanResult": "ntq_jax.types",
    "PlanStatus": "ntq_jax.types",
    "STATUS_NAMES": "ntq_jax.types",
    "check_paths": "ntq_jax.planners.verify",
    "valid_queries": "ntq_jax.planners.verify",
    "finalize": "ntq_jax.planners.verify",
    "config_grid": "ntq_jax.planners.astar_planner",
}

__all__ = [
    "plan",
    "register_planner",
    "available_planners",
    "PlanResult",
    "PlanStatus",
    "STATUS_NAMES",
    "check_paths",
    "valid_queries",
    "finalize",
    "config_grid",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
