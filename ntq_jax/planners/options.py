"""Checks of the planners' options: one TypeError / ValueError naming the planner and the option.

Every built-in planner validates its options with these helpers before doing
any work, so a bad value fails at once with a message such as
``astar: chunk_size must be an int in [1, 4,096], got 0`` instead of an
IndexError deep in a kernel. :func:`check_option_names` rejects an option the
planner does not know (a misspelt keyword), listing the ones it does;
:func:`roadmap_memory_option` refuses a roadmap that could not fit in this
machine's available memory (``milestones=10**12`` ran 455 s, then blamed "free
space is too small").
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from ntq_jax.robots.certified import MOTION_CHECKS
from ntq_jax.validation import check_count, check_real

__all__ = [
    "unsupported_robot",
    "bool_option",
    "check_option_names",
    "float_option",
    "int_option",
    "motion_check_option",
    "available_memory",
    "roadmap_bytes",
    "roadmap_memory_option",
]


def int_option(
    planner: str,
    name: str,
    value: Any,
    minimum: int,
    maximum: int | None = None,
    *,
    none_ok: bool = False,
) -> int | None:
    """``value`` as an int in ``[minimum, maximum]`` (or None when ``none_ok``)."""
    if value is None and none_ok:
        return None
    return check_count(f"{planner}: {name}", value, minimum, maximum)


def float_option(
    planner: str,
    name: str,
    value: Any,
    *,
    minimum: float = 0.0,
    inclusive: bool = False,
    maximum: float | None = None,
    none_ok: bool = False,
) -> float | None:
    """``value`` as a finite float ``> minimum`` (``>=`` when ``inclusive``), ``<= maximum``."""
    if value is None and none_ok:
        return None
    return check_real(
        f"{planner}: {name}", value, minimum=minimum, inclusive=inclusive, maximum=maximum
    )


def bool_option(planner: str, name: str, value: Any) -> bool:
    """``value`` as a bool: ``True``/``False`` (or NumPy bools) only, never ``"no"`` or ``2``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(
            f"{planner}: {name} must be True or False, got {value!r} ({type(value).__name__})"
        )
    return bool(value)


def motion_check_option(planner: str, check: Any) -> str:
    """``check`` if it names a motion check (``MOTION_CHECKS``), else ValueError listing them."""
    if not isinstance(check, str) or check not in MOTION_CHECKS:
        raise ValueError(
            f"{planner}: check must be one of {', '.join(map(repr, MOTION_CHECKS))}, got {check!r}"
        )
    return check


def check_option_names(
    planner: str, fn: Callable, options: Iterable[str], extra: Iterable[str] = ()
) -> None:
    """Raises TypeError for an option ``fn`` does not take (unless it takes ``**kwargs``).

    The parameters ``env``, ``queries``, ``padding`` and ``seed`` are arguments of
    :func:`ntq_jax.plan` itself, not options; ``extra`` adds the names a planner
    forwards through its ``**kwargs`` (then the check applies to it too).
    """
    params = inspect.signature(fn).parameters
    extra = tuple(extra)
    if not extra and any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    known = {
        n
        for n, p in params.items()
        if p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
        and not n.startswith("_")
    } - {"env", "queries", "padding", "seed"}
    known.update(extra)
    unknown = sorted(set(options) - known - {n for n in params if n.startswith("_")})
    if unknown:
        raise TypeError(
            f"{planner}: unknown option{'s' if len(unknown) > 1 else ''} "
            f"{', '.join(map(repr, unknown))}; its options are "
            f"{', '.join(sorted(known))}"
        )


def unsupported_robot(planner: str, env) -> str | None:
    """Why the built-in ``planner`` cannot plan for ``env``'s robot (the fix named), or None."""
    if planner == "astar" and env.dim != 2:
        return (
            f"the grid A* planner needs a 2-D configuration space (point robot or 2-link "
            f"arm); {env.name} has dimension {env.dim}: use 'roadmap' or 'bitstar'"
        )
    if planner == "visgraph" and env.robot.kind != "point":
        return (
            f"the 'visgraph' planner is for the point robot only; {env.name} has a "
            f"{env.robot.kind!r} robot: use 'roadmap' or 'bitstar' (or 'astar' for the "
            "2-link arm)"
        )
    return None


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (psutil's ``available``; without
    psutil Linux's ``MemAvailable``, else ``os.sysconf``'s free pages), or None."""
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 - not installed or unsupported here: the fallbacks
        pass
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def roadmap_bytes(milestones: int, d: int, k: int, grow_rounds: int = 0) -> int:
    """A lower bound of the memory the roadmap planner holds at once while it builds its
    last growth round (``milestones * 2**grow_rounds`` states of dimension ``d``, ``k``
    neighbours each), the earlier rounds' roadmaps still cached.

    Counted while the edges are checked: the states (float32) and the KD-tree's float64
    copy with its int64 indices; the ``k`` int64 neighbours per state; at least ``n k / 2``
    distinct edges (each state has ``k`` of them, each shared by at most two) as int64
    pairs, both float32 end states, int32 edges and float64 costs. A cached round keeps
    its states, edges and costs. The kNN candidates, the checks' work and Python's own
    memory come on top, so a refusal is certain and a pass is no promise.
    """

    def build(n: int) -> int:
        kk = max(0, min(int(k), n - 1))
        edges = n * kk // 2
        return n * (4 * d + 8 * d + 8 + 8 * kk) + edges * (16 + 8 * d + 8 + 8)

    def kept(n: int) -> int:
        return n * 4 * d + n * min(int(k), n - 1) // 2 * (8 + 8)

    sizes = [int(milestones) * 2**r for r in range(int(grow_rounds) + 1)]
    return build(sizes[-1]) + sum(kept(n) for n in sizes[:-1])


def roadmap_memory_option(
    planner: str,
    milestones: int,
    d: int,
    k: int,
    grow_rounds: int = 0,
    available: int | None = None,
) -> None:
    """ValueError naming ``milestones``, the estimated bytes (:func:`roadmap_bytes`) and the
    largest count that fits, when the roadmap of its last growth round would not fit in
    ``available`` bytes (default :func:`available_memory`; None: not checked)."""
    available = available_memory() if available is None else available
    if not available:
        return
    need = roadmap_bytes(milestones, d, k, grow_rounds)
    if need <= available:
        return
    lo, hi = 1, int(milestones)  # the largest count that fits (need grows with milestones)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if roadmap_bytes(mid, d, k, grow_rounds) <= available else (lo, mid - 1)
    rounds = (
        f" after {grow_rounds} growth round{'s' * (grow_rounds > 1)} "
        f"({int(milestones) * 2**grow_rounds:,} states)"
        if grow_rounds
        else ""
    )
    fix = f"use milestones <= {lo:,}" if lo >= 2 else "use far fewer milestones"
    raise ValueError(
        f"{planner}: milestones {int(milestones):,} would need at least {need:,} bytes "
        f"({need / 1e9:.3g} GB) for its roadmap{rounds} ({d}-D states, k {k}), more than the "
        f"{available:,} bytes ({available / 1e9:.3g} GB) of memory available; {fix}"
        + (" or fewer grow_rounds" if grow_rounds else "")
    )
