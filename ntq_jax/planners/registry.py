"""The planner registry behind :func:`ntq_jax.planners.plan`: names to planner functions.

The built-in planners (``"astar"``, ``"visgraph"``, ``"bitstar"``, ``"roadmap"``,
``"bitree"``, ``"rrtconnect"``, ``"bitstar_jax"``, ``"vamp"``) are
registered when this module is imported; :func:`register_planner` adds a user's own.
See :mod:`ntq_jax.planners` for each planner and its options.
"""

from __future__ import annotations

import functools
import inspect

import numpy as np

from ntq_jax.planners import (
    astar_planner,
    bitree,
    ompl_bridge,
    ompl_rrtconnect,
    roadmap,
    vamp_bridge,
    visgraph,
)
from ntq_jax.planners.options import check_option_names
from ntq_jax.types import PlannerFn, PlanResult
from ntq_jax.validation import check_count

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


def plan(
    env, queries, planner: str = "astar", *, padding: float | None = None, seed: int = 0, **options
) -> PlanResult:
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
        raise ValueError(
            f"unknown planner {planner!r}; available: {', '.join(available_planners())}"
        )
    seed = check_count("seed", seed)
    pad = env.resolve_padding(padding)
    try:
        q = np.asarray(queries, np.float32)
    except (TypeError, ValueError):
        raise TypeError(
            f"queries must be a numeric (K, 2, {env.dim}) array of (start, goal) "
            f"states for {env.name}, got {type(queries).__name__}"
        ) from None
    if q.ndim != 3 or q.shape[1:] != (2, env.dim):
        raise ValueError(f"queries must have shape (K, 2, {env.dim}) for {env.name}, got {q.shape}")
    fn = _REGISTRY[planner]
    check_option_names(planner, fn, options)
    return fn(env, q, padding=pad, seed=seed, **options)


@functools.wraps(ompl_bridge.plan_bitstar)
def _bitstar(env, queries, **options) -> PlanResult:
    """``"bitstar"``: :func:`ntq_jax.planners.ompl_bridge.plan_bitstar` (worker processes on
    the NumPy geometry), or for a 3-D serial arm, which has no NumPy geometry,
    :func:`ntq_jax.planners.ompl_rrtconnect.plan_bitstar_jax` (the same BIT*, in this
    process, on the package's JAX checks; the worker options ``workers``,
    ``chunk_size``, ``hang_timeout``, ``startup_timeout`` and ``keep_workers`` do not
    apply there and are ignored)."""
    if getattr(env.robot, "kind", None) != "serial_arm":
        return ompl_bridge.plan_bitstar(env, queries, **options)
    takes = inspect.signature(ompl_rrtconnect.plan_bitstar_jax).parameters
    return ompl_rrtconnect.plan_bitstar_jax(
        env, queries, **{k: v for k, v in options.items() if k in takes}
    )


register_planner("astar", astar_planner.plan_astar)
register_planner("visgraph", visgraph.plan_visgraph)
register_planner("bitstar", _bitstar)
register_planner("roadmap", roadmap.plan_roadmap)
register_planner("bitree", bitree.plan_bitree)
register_planner("rrtconnect", ompl_rrtconnect.plan_rrtconnect)
register_planner("bitstar_jax", ompl_rrtconnect.plan_bitstar_jax)
register_planner("vamp", vamp_bridge.plan_vamp)
