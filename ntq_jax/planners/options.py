"""Checks of the planners' options: one TypeError / ValueError naming the planner and the option.

Every built-in planner validates its options with these helpers before doing
any work, so a bad value fails at once with a message such as
``astar: chunk_size must be an int in [1, 4,096], got 0`` instead of an
IndexError deep in a kernel. :func:`check_option_names` rejects an option the
planner does not know (a misspelt keyword), listing the ones it does.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from ntq_jax.validation import check_count, check_real
from ntq_jax.robots.certified import MOTION_CHECKS

__all__ = [
    "unsupported_robot",
    "bool_option",
    "check_option_names",
    "float_option",
    "int_option",
    "motion_check_option",
]


def int_option(planner: str, name: str, value: Any, minimum: int, maximum: int | None = None,
               *, none_ok: bool = False) -> int | None:
    """``value`` as an int in ``[minimum, maximum]`` (or None when ``none_ok``)."""
    if value is None and none_ok:
        return None
    return check_count(f"{planner}: {name}", value, minimum, maximum)


def float_option(planner: str, name: str, value: Any, *, minimum: float = 0.0,
                 inclusive: bool = False, maximum: float | None = None,
                 none_ok: bool = False) -> float | None:
    """``value`` as a finite float ``> minimum`` (``>=`` when ``inclusive``), ``<= maximum``."""
    if value is None and none_ok:
        return None
    return check_real(f"{planner}: {name}", value, minimum=minimum, inclusive=inclusive,
                      maximum=maximum)


def bool_option(planner: str, name: str, value: Any) -> bool:
    """``value`` as a bool: ``True``/``False`` (or NumPy bools) only, never ``"no"`` or ``2``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{planner}: {name} must be True or False, got {value!r} "
                        f"({type(value).__name__})")
    return bool(value)


def motion_check_option(planner: str, check: Any) -> str:
    """``check`` if it names a motion check (``MOTION_CHECKS``), else ValueError listing them."""
    if not isinstance(check, str) or check not in MOTION_CHECKS:
        raise ValueError(f"{planner}: check must be one of {', '.join(map(repr, MOTION_CHECKS))}, "
                         f"got {check!r}")
    return check


def check_option_names(planner: str, fn: Callable, options: Iterable[str],
                       extra: Iterable[str] = ()) -> None:
    """Raises TypeError for an option ``fn`` does not take (unless it takes ``**kwargs``).

    The parameters ``env``, ``queries``, ``padding`` and ``seed`` are arguments of
    :func:`ntq_jax.plan` itself, not options; ``extra`` adds the names a planner
    forwards through its ``**kwargs`` (then the check applies to it too).
    """
    params = inspect.signature(fn).parameters
    extra = tuple(extra)
    if not extra and any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    known = {n for n, p in params.items()
             if p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
             and not n.startswith("_")} - {"env", "queries", "padding", "seed"}
    known.update(extra)
    unknown = sorted(set(options) - known - {n for n in params if n.startswith("_")})
    if unknown:
        raise TypeError(f"{planner}: unknown option{'s' if len(unknown) > 1 else ''} "
                        f"{', '.join(map(repr, unknown))}; its options are "
                        f"{', '.join(sorted(known))}")


def unsupported_robot(planner: str, env) -> str | None:
    """Why the built-in ``planner`` cannot plan for ``env``'s robot (the fix named), or None."""
    if planner == "astar" and env.dim != 2:
        return (f"the grid A* planner needs a 2-D configuration space (point robot or 2-link "
                f"arm); {env.name} has dimension {env.dim}: use 'roadmap' or 'bitstar'")
    if planner == "visgraph" and env.robot.kind != "point":
        return (f"the 'visgraph' planner is for the point robot only; {env.name} has a "
                f"{env.robot.kind!r} robot: use 'roadmap' or 'bitstar' (or 'astar' for the "
                "2-link arm)")
    return None
