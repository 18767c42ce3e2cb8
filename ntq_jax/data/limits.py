"""Bounds on a data run's size that are known before any work is done.

A resampling spacing (``planner.data_paths`` a number, :mod:`ntq_jax.planners.path_modes`)
puts a waypoint every ``spacing`` along each data path, and includeData makes a
training sample of each. :func:`check_spacing` refuses, before anything is
sampled or planned, a spacing that would put more than :data:`MAX_CROSSING_WAYPOINTS`
waypoints on one straight crossing of the map (its longest motion in the robot's
metric: the bounds' diagonal for the point robot, ``longest_motion`` for the others;
paths around obstacles are longer still). ``1e-9`` on a 20 x 20 point map would be
2.8e10 waypoints per crossing (the probe's 10.1 TiB allocation after planning);
the presets' spacings give 10 to 50.

:func:`check_roadmap` refuses a ``roadmap`` planner whose last growth round
(``milestones * 2**grow_rounds`` states) would not fit in half of this machine's
memory at :data:`ROADMAP_BYTES` per state and neighbour (``milestones: 1e12`` ran
455 s, then blamed "free space is too small").
"""

from __future__ import annotations

import math
import os

from ntq_jax.errors import ConfigError

__all__ = [
    "MAX_CROSSING_WAYPOINTS",
    "ROADMAP_BYTES",
    "crossing_length",
    "check_spacing",
    "memory_bytes",
    "check_roadmap",
]

#: the most waypoints a spacing may put on one straight crossing of the map
MAX_CROSSING_WAYPOINTS = 10_000


def crossing_length(env) -> float:
    """The longest straight motion across ``env`` in its robot's metric."""
    longest = getattr(env.robot, "longest_motion", None)
    if longest is not None:
        return float(longest(env.world))
    b = env.world.bounds.tolist() if hasattr(env.world.bounds, "tolist") else env.world.bounds
    return math.sqrt(sum((hi - lo) ** 2 for lo, hi in b))


def check_spacing(env, mode, env_name: str) -> None:
    """A :class:`ConfigError` when ``mode`` (``planner.data_paths`` of ``env_name``) is a
    spacing that would put more than :data:`MAX_CROSSING_WAYPOINTS` waypoints on one
    crossing of the map; other modes (``raw``, ``shortcut``, None) pass."""
    if isinstance(mode, bool) or not isinstance(mode, (int, float)) or not mode > 0:
        return
    length = crossing_length(env)
    n = length / float(mode)
    if n > MAX_CROSSING_WAYPOINTS:
        raise ConfigError(
            f"planner.data_paths {mode:g} for {env_name}: one straight crossing of the map "
            f"({length:.3g} in the robot's metric) would be {n:.3g} waypoints, each a "
            f"training sample (at most {MAX_CROSSING_WAYPOINTS:,}); use a spacing >= "
            f"{length / MAX_CROSSING_WAYPOINTS:.3g}, or shortcut/raw"
        )


#: bytes a roadmap takes per state and neighbour while it is built (its kNN candidates,
#: their checks and the kept edges with costs; generous, so that a refusal is certain)
ROADMAP_BYTES = 32


def memory_bytes() -> int | None:
    """This machine's physical memory in bytes (None when it cannot be told)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_roadmap(env, options: dict, env_name: str) -> None:
    """A :class:`ConfigError` when the roadmap planner's ``options`` (``milestones``, ``k``,
    ``grow_rounds``) would build a roadmap larger than half of this machine's memory."""
    mem, m = memory_bytes(), options.get("milestones")
    if not mem or not isinstance(m, int) or isinstance(m, bool):
        return
    n = m * 2 ** int(options.get("grow_rounds") or 0)
    d = env.dim
    k = options.get("k") or math.ceil(math.e * (1.0 + 1.0 / d) * math.log(max(n, 2)))
    need = n * (4 * d + ROADMAP_BYTES * int(k))
    if need > mem / 2:
        most = int(m * (mem / 2) / need)
        raise ConfigError(
            f"planner.milestones {m:,} for {env_name}: its roadmap ({n:,} states in its last "
            f"growth round, about {need / 1e9:.3g} GB) would not fit in this machine's memory "
            f"({mem / 1e9:.3g} GB); use at most {most:,} milestones (or fewer grow_rounds)"
        )
