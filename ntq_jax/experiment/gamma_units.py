"""gamma_nt measured in units: a unit's record, units pooled into one estimate, and the
family of worlds a scene name stands for.

A **unit** is one measurement of ``scripts/measure_gamma.py --json``: one environment,
one seed, the counts (``queries``, ``non_trivial``), the interval, the rates and the
settings (:func:`unit_record`). A measurement too long for one sitting (10^8 queries of
a Panda scene: hours of a core) is made of units, each written whole (atomically) as it
finishes, so a series stops and resumes at any unit (:func:`same_measurement` tells a
finished unit from one to measure).

:func:`pool` adds units up into one estimate: the counts summed, the Wilson interval of
the sum, and, over several environments (worlds), their mean with the interval of a
family of ``population`` worlds (:func:`ntq_jax.world_mean.world_mean`: the spread
between worlds counted for the worlds not measured). Worlds measured on one query
stream (units of different envs with the same seed, :func:`shared_streams`) have
correlated query errors, which the ``worlds`` interval allows for; a family's units
get one seed each (:func:`member_seed`), so their queries are independent.

A **family** is a name that stands for many worlds: ``panda/<scene>`` is the 100
problems of a MotionBenchMaker scene, each placing the scene differently
(:func:`family`); its gamma_nt is the mean over them, measured as one unit per
problem (:func:`unit_path` names their files beside the pooled one).
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

from ntq_jax.errors import UsageError
from ntq_jax.stats import wilson_interval, world_mean

__all__ = [
    "POOL_KEYS",
    "UNIT_KEYS",
    "family",
    "member_seed",
    "unit_path",
    "read_unit",
    "same_measurement",
    "unit_record",
    "pool",
    "shared_streams",
]

#: What the units of a pooled measurement must share.
POOL_KEYS = ("padding", "chunk", "resolution", "check")
#: What makes a unit the same measurement (:func:`same_measurement`).
UNIT_KEYS = ("env", "queries", "padding", "seed", "chunk")

_FAMILY = re.compile(r"panda/(\w+)")


def family(name: str) -> list[str] | None:
    """The environments a family name stands for, or None when ``name`` is one
    environment: ``panda/<scene>`` is ``panda/<scene>/1`` .. ``panda/<scene>/100``
    (MotionBenchMaker's problems of that scene; an unknown scene is a
    :class:`~ntq_jax.errors.UsageError` naming the scenes)."""
    m = _FAMILY.fullmatch(name)
    if m is None:
        return None
    from ntq_jax.scenes import mbm

    if m.group(1) not in mbm.SCENES:
        raise UsageError(
            f"unknown Panda scene {m.group(1)!r}: one of {', '.join(mbm.SCENES)} "
            "(panda/<scene> is its 100 problems; panda/<scene>/<number> one of them)"
        )
    return [f"{name}/{n}" for n in mbm.NUMBERS]


def member_seed(seed: int, index: int, members: int) -> int:
    """The seed of a family's member ``index`` (0-based, of ``members``) in the series of
    ``seed``: ``seed * members + index``, so every member has its own query stream and
    the series of different seeds share none (problem ``n`` of a Panda scene, series
    ``s``: ``100 s + n - 1``). A :class:`~ntq_jax.errors.UsageError` when it exceeds
    the 32-bit seeds."""
    out = seed * members + index
    if out > 2**32 - 1:
        raise UsageError(
            f"--seed {seed} is too large for a family of {members} (its members are seeded "
            f"{members} x seed + index, at most 2**32 - 1): use a seed below "
            f"{(2**32) // members}"
        )
    return out


def unit_path(pooled: str | os.PathLike, env: str) -> Path:
    """Where the unit of ``env`` (a member of a family) is written: beside the pooled
    file, in the folder of its name, ``problem_<last part of env>.json``
    (``series/cage.json``, ``panda/cage/7`` -> ``series/cage/problem_7.json``)."""
    pooled = Path(pooled)
    return pooled.parent / pooled.stem / f"problem_{env.rsplit('/', 1)[-1]}.json"


def read_unit(path: str | os.PathLike) -> dict | None:
    """The record in ``path``, or None when it is missing or not a JSON object."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def same_measurement(record: dict | None, **settings) -> bool:
    """Whether ``record`` is the measurement of ``settings`` (every key of
    :data:`UNIT_KEYS`: env, queries, padding, seed, chunk)."""
    return isinstance(record, dict) and all(record.get(k) == settings[k] for k in UNIT_KEYS)


def unit_record(env, est, *, padding, seed, chunk, cpu, ahead, rate, version, cpus) -> dict:
    """The record of one unit: ``est`` (a :class:`~ntq_jax.gamma.GammaEstimate`) on
    ``env`` with its settings, ``cpu`` seconds, the seconds ``ahead`` of the first chunk
    and the streaming ``rate`` after it (None where not measured)."""
    from ntq_jax.geometry import World3D

    lo, hi = est.ci95
    resolution = getattr(env.robot, "resolution", None)
    out = {
        "env": env.name,
        "padding": padding,
        "seed": seed,
        "queries": est.queries,
        "non_trivial": est.non_trivial,
        "gamma": est.gamma,
        "ci95": [lo, hi],
        "seconds": est.seconds,
        "queries_per_second": est.queries_per_second,
        "candidates": est.candidates,
        "candidates_per_second": est.candidates_per_second,
        "cpu_seconds": cpu,
        "first_chunk_seconds": ahead,
        "streaming_queries_per_second": rate,
        "chunk": chunk,
        "resolution": resolution,
        "check": "exact" if resolution is None else "discretized",
        "cpus": cpus,
        "version": version,
    }
    if isinstance(env.world, World3D):
        out["world"] = (
            "the world of this one problem (the problems of a scene place it "
            "differently, and their gamma_nt differ)"
        )
    return out


def pool(units: list[dict], population: int | None = None) -> dict:
    """One estimate over the queries of ``units`` (records of :func:`unit_record`).

    The counts are summed (the Wilson interval of the sum). With several environments,
    or a ``population``, ``worlds`` adds the mean over the environments measured (each
    environment's units summed into one world) and its interval for a family of
    ``population`` worlds (None: an unbounded family).

    Raises:
        UsageError: no units, a record without counts, units that differ in a
            :data:`POOL_KEYS` setting, two units of one env and seed, or a
            ``population`` below the number of environments.
    """
    if not units:
        raise UsageError("nothing to pool: no unit results")
    for u in units:
        if not {"env", "queries", "non_trivial", "seed", *POOL_KEYS} <= set(u):
            raise UsageError(f"{u.get('env', 'a unit')}: not a result of measure_gamma.py --json")
    for key in POOL_KEYS:
        values = {json.dumps(u[key]) for u in units}
        if len(values) > 1:
            raise UsageError(
                f"the units differ in {key} ({', '.join(sorted(values))}): pool "
                "measurements of one geometry"
            )
    seeds = [u["seed"] for u in units]
    envs = [u["env"] for u in units]
    if len(set(zip(envs, seeds))) < len(units):
        raise UsageError(
            "two units have the same env and seed (the same queries): give each "
            "unit of one env its own --seed"
        )
    names = sorted(set(envs), key=envs.index)
    if population is not None and population < len(names):
        raise UsageError(f"--population {population} is smaller than the {len(names)} envs pooled")
    queries = sum(u["queries"] for u in units)
    blocked = sum(u["non_trivial"] for u in units)
    lo, hi = wilson_interval(blocked, queries)
    out = {"env": envs[0] if len(names) == 1 else names}
    out.update({key: units[0][key] for key in POOL_KEYS})
    out.update(
        queries=queries,
        non_trivial=blocked,
        gamma=blocked / queries,
        ci95=[lo, hi],
        candidates=sum(u.get("candidates", 0) for u in units),
        units=len(units),
        seeds=sorted(seeds),
        cpu_seconds=sum(u.get("cpu_seconds") or 0.0 for u in units),
        seconds=sum(u.get("seconds") or 0.0 for u in units),
    )
    out["queries_per_second"] = queries / out["seconds"] if out["seconds"] else 0.0
    if "version" in units[0]:
        out["version"] = units[0]["version"]
    if len(names) > 1:
        out["world"] = (
            "the worlds of these environments, the same number of queries from each when "
            "their units are alike: gamma_nt is then their mean (the interval is "
            "conservative for that mean of fixed worlds; see worlds for the family's)"
        )
    elif "world" in units[0]:
        out["world"] = units[0]["world"]
    shared = shared_streams(units)
    if shared:
        out["world"] += (
            f"; {len(shared)} seeds are shared by several envs (one query stream checked "
            "in several worlds): their query errors are correlated, so ci95 (independent "
            "queries) is too narrow; worlds.ci95 allows for it"
        )
    if len(names) > 1 or population is not None:
        out["worlds"] = _worlds(units, names, population, bool(shared))
    return out


def shared_streams(units: list[dict]) -> list:
    """The seeds used by units of more than one env: those envs were measured on the same
    query stream (the same configurations, checked in each world)."""
    envs_of: dict = {}
    for u in units:
        envs_of.setdefault(json.dumps(u["seed"]), set()).add(u["env"])
    return sorted(json.loads(s) for s, e in envs_of.items() if len(e) > 1)


def _worlds(units: list[dict], names: list[str], population: int | None, shared: bool) -> dict:
    """The ``worlds`` entry of :func:`pool`: the mean over the envs and its interval."""
    hits = [sum(u["non_trivial"] for u in units if u["env"] == e) for e in names]
    counts = [sum(u["queries"] for u in units if u["env"] == e) for e in names]
    wm = world_mean(hits, counts, population=population, shared_queries=shared)
    return {
        "measured": wm.worlds,
        "population": wm.population,
        "mean": wm.mean,
        "spread": wm.spread,
        "ci95": None if wm.ci95 is None else list(wm.ci95),
        "df": wm.df if math.isfinite(wm.df) else None,
        "shared_queries": shared,
        "about": "the mean of gamma_nt over a family of worlds of which these were "
        "measured; its interval adds the spread between worlds (shrinking to the "
        "queries' alone as every world of the population is measured), "
        "ntq_jax.world_mean",
    }
