"""Classical planners behind one entry point: :func:`plan` (a registry of planner functions).

Usage::

    import ntq_jax
    env = ntq_jax.make_env("point/3")
    res = ntq_jax.plan(env, queries)                         # grid A* + shortcutting
    res = ntq_jax.plan(env, queries, "visgraph", padding=0)  # exact point-robot optimum
    res = ntq_jax.plan(env, queries, "bitstar", time_budget=2.0, workers=2)
    res = ntq_jax.plan(env, queries, "roadmap", milestones=20_000)  # any robot, many queries

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
    :func:`ntq_jax.planners.astar.plan_astar`: the configuration box gridded at
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
    outcomes map to statuses in ``ompl_bridge.PLAN_STATUS``).

``"roadmap"`` (any robot; many queries in one environment)
    :func:`ntq_jax.planners.roadmap.plan_roadmap`: a PRM* roadmap built once per
    environment and settings (cached in memory, and on disk with ``cache_dir``),
    A* per query (the robot's metric to the goal as heuristic), shortcutting.
    Options: ``milestones`` (default 20,000), ``k`` (default PRM*'s rule),
    ``grow_rounds``, ``roadmap_seed``, ``cache_dir``.

Register your own with :func:`register_planner`. Measurements: BENCHMARKS.md
("Classical planners").
"""

from __future__ import annotations

import numpy as np

from ntq_jax.planners import astar, ompl_bridge, roadmap, visgraph
from ntq_jax.planners.astar import config_grid
from ntq_jax.planners.options import check_option_names
from ntq_jax.planners.verify import check_paths, finalize, valid_queries
from ntq_jax.validation import check_count
from ntq_jax.types import STATUS_NAMES, PlannerFn, PlanResult, PlanStatus

_REGISTRY: dict[str, PlannerFn] = {}


def register_planner(name: str, fn: PlannerFn) -> None:
    """Registers (or replaces) a planner usable as ``plan(env, queries, name)``.

    Args:
        name: the planner's name.
        fn: ``fn(env, queries (K, 2, d) float32, *, padding: float, seed: int,
            **options) -> PlanResult``; ``padding`` is already resolved to a number.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"planner name must be a non-empty string, got {name!r}")
    if not callable(fn):
        raise TypeError(f"planner {name!r} must be callable, got {type(fn).__name__}")
    _REGISTRY[name] = fn


def available_planners() -> tuple[str, ...]:
    """Names of the registered planners, sorted."""
    return tuple(sorted(_REGISTRY))


def plan(env, queries, planner: str = "astar", *, padding: float | None = None, seed: int = 0,
         **options) -> PlanResult:
    """Plans a batch of queries with a registered planner.

    Args:
        env: an :class:`ntq_jax.Env`.
        queries: ``(K, 2, d)`` array of (start, goal) states.
        planner: ``"astar"``, ``"visgraph"``, ``"bitstar"`` or a registered name.
        padding: planning clearance; ``None`` = the environment's padding (the
            data-generation geometry), ``0`` = the evaluation geometry.
        seed: seed for randomised planners.
        **options: planner options (see the module docstring).

    Returns:
        A :class:`PlanResult`.

    Raises:
        ValueError: unknown planner (the message lists the available ones), bad
            query shape, or a planner that does not support the robot.
        TypeError, ValueError: an option the planner does not take (the message
            lists those it does), or one of the wrong type or out of range (the
            message names it); a non-integer or negative ``seed``.
    """
    if not isinstance(planner, str) or planner not in _REGISTRY:
        raise ValueError(f"unknown planner {planner!r}; available: {', '.join(available_planners())}")
    seed = check_count("seed", seed)
    pad = env.resolve_padding(padding)
    try:
        q = np.asarray(queries, np.float32)
    except (TypeError, ValueError):
        raise TypeError(f"queries must be a numeric (K, 2, {env.dim}) array of (start, goal) "
                        f"states for {env.name}, got {type(queries).__name__}") from None
    if q.ndim != 3 or q.shape[1:] != (2, env.dim):
        raise ValueError(f"queries must have shape (K, 2, {env.dim}) for {env.name}, got {q.shape}")
    fn = _REGISTRY[planner]
    check_option_names(planner, fn, options)
    return fn(env, q, padding=pad, seed=seed, **options)


register_planner("astar", astar.plan_astar)
register_planner("visgraph", visgraph.plan_visgraph)
register_planner("bitstar", ompl_bridge.plan_bitstar)
register_planner("roadmap", roadmap.plan_roadmap)

__all__ = ["plan", "register_planner", "available_planners", "PlanResult", "PlanStatus",
           "STATUS_NAMES", "check_paths", "valid_queries", "finalize", "config_grid"]
