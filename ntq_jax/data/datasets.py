"""One dataset's contents and metadata: the arrays includeData makes of its queries' paths,
its statistics, the warnings they raise, and the metadata its ``meta.json`` shares.

The pieces :func:`ntq_jax.data.generate.generate_datasets` assembles D0..D3 from:
:func:`resolve_prune` (a dataset's pruning probability, Alg. 4), :func:`dataset_arrays`
(the training samples of a pool's planned paths), :func:`dataset_stats` and
:func:`dataset_warnings` (what a reader of ``meta.json`` needs to trust it), and
:func:`common_meta` / :func:`sharing` (the metadata every dataset of a run shares).
"""

from __future__ import annotations

import warnings

import numpy as np

from ntq_jax import queries as Q
from ntq_jax.data.format import (
    FORMAT,
    FORMAT_VERSION,
)
from ntq_jax.data.include import include_data, prune_probability
from ntq_jax.data.options import DataOptions
from ntq_jax.data.pools import (
    Pools,
)
from ntq_jax.planners.jobs import PoolPlan
from ntq_jax.stats import wilson_interval
from ntq_jax.types import PlanResult
from ntq_jax.version import __version__

__all__ = [
    "resolve_prune",
    "dataset_arrays",
    "dataset_stats",
    "dataset_warnings",
    "sharing",
    "common_meta",
]

#: ``meta.json``'s names of the query kinds (:data:`ntq_jax.queries.UNIFORM`, ...).
QUERY_KINDS = {"0": "uniform", "1": "non-trivial", "2": "non-trivial sampler exhausted (trivial)"}


def resolve_prune(spec, g_data: dict, env_name: str, name: str) -> float:
    """The drop probability of a free sample for ``spec.prune`` (``gamma``: ``g_data``'s estimate)."""
    if spec.prune == "keep_last":  # Alg. 4's pruning; include_data keeps the last steps
        return 1.0
    if isinstance(spec.prune, str):  # "gamma"
        g = g_data.get("gamma")
        if g is None:
            raise ValueError(
                f"{env_name} {name}: prune: gamma needs the map's gamma_nt at the data padding, "
                f"but it could not be estimated ({g_data.get('error', 'no estimate')}); give "
                "the dataset a pruning probability instead"
            )
        return prune_probability(min(max(float(g), 0.0), 1.0))
    return prune_probability(spec.prune)


def dataset_arrays(
    env,
    pools: Pools,
    planned: PlanResult,
    idx: np.ndarray,
    prune: bool | float,
    prune_padding: float,
    rng: np.random.Generator | None = None,
    keep_last: bool = False,
) -> dict[str, np.ndarray]:
    """The arrays of the dataset made of pool rows ``idx`` (:data:`ARRAY_SPECS`).

    ``prune``, ``rng``, ``keep_last``: :func:`ntq_jax.data.include.include_data`'s.
    """
    solved = planned.solved[idx]
    sel = idx[solved]
    lens = planned.lengths[sel].astype(np.int32)
    lmax = int(lens.max()) if len(lens) else 0
    paths = (
        np.ascontiguousarray(planned.paths[sel, :lmax])
        if len(sel)
        else np.zeros((0, 0, env.dim), np.float32)
    )
    inputs, targets, pidx = include_data(
        env, paths, lens, prune=prune, padding=prune_padding, rng=rng, keep_last=keep_last
    )
    return {
        "inputs": inputs,
        "targets": targets,
        "path_index": pidx,
        "paths": paths.astype(np.float32),
        "path_lengths": lens,
        "queries": pools.queries[idx].astype(np.float32),
        "query_kind": pools.kind[idx].astype(np.int8),
        "solved": solved.astype(np.bool_),
    }


def dataset_stats(
    arrays: dict,
    idx: np.ndarray,
    planned: PoolPlan,
    blocked: np.ndarray,
    prune: bool,
    g_data: dict,
    g_eval: dict,
) -> dict:
    """The ``stats`` of a dataset's ``meta.json``."""
    k, kind, solved = len(idx), arrays["query_kind"], arrays["solved"]
    lens, samples = arrays["path_lengths"], len(arrays["inputs"])
    sel = idx[solved]
    segments = int(np.maximum(lens - 1, 0).sum())
    nblk = int(blocked[idx].sum())
    return {
        "queries": k,
        "uniform": int((kind == Q.UNIFORM).sum()),
        "non_trivial": int((kind == Q.NON_TRIVIAL).sum()),
        "nt_exhausted": int((kind == Q.NT_EXHAUSTED).sum()),
        "solved": int(solved.sum()),
        "unsolved": int(k - solved.sum()),
        "rejected_paths": int(planned.rejected[idx].sum()),
        "paths": int(len(sel)),
        "segments": segments,
        "samples": samples,
        "pruned": segments - samples if prune else 0,
        "fraction_pruned": (segments - samples) / segments if prune and segments else 0.0,
        "mean_waypoints": float(lens.mean()) if len(lens) else 0.0,
        "max_waypoints": int(lens.max()) if len(lens) else 0,
        "blocked_fraction": nblk / k,
        "blocked_fraction_ci95": list(wilson_interval(nblk, k)) if k else [0.0, 1.0],
        "mean_cost": float(planned.result.costs[sel].mean()) if len(sel) else None,
        "gamma_nt": g_data["gamma"],
        "gamma_nt_eval": g_eval["gamma"],
    }


def dataset_warnings(env_name: str, name: str, stats: dict, prune: bool, n_max: int) -> list[str]:
    """The ``warnings`` of a dataset's ``meta.json``; an empty dataset is also warned about."""
    out = []
    if stats["samples"] == 0:
        why = (
            "(pruning removed every segment: no waypoint of any path is blocked from its goal, "
            "e.g. a map without obstacles)"
            if prune and stats["segments"]
            else "(no query was solved)"
            if not stats["paths"]
            else "(empty)"
        )
        out.append(
            f"{env_name} {name}: the dataset has no samples {why}; an empty, valid "
            "dataset was written"
        )
        warnings.warn(out[-1], RuntimeWarning, stacklevel=3)
    if stats["nt_exhausted"]:
        out.append(
            f"{env_name} {name}: {stats['nt_exhausted']} non-trivial draw(s) found no "
            f"blocked query in n_max={n_max} attempts and are trivial (query_kind 2)"
        )
    return out


def sharing(run, j: int) -> dict:
    """Dataset ``j``'s pool prefixes and the earlier datasets with the same queries (``run``:
    the :class:`ntq_jax.data.generate.RunSpec`)."""
    b = run.bits[j]
    return {
        "uniform_pool": [0, int((~b).sum())],
        "nontrivial_pool": [0, int(b.sum())],
        "same_queries_as": [run.names[i] for i in range(j) if np.array_equal(run.bits[i], b)],
    }


def common_meta(env, opts: DataOptions, run, g_data: dict, g_eval: dict) -> dict:
    """The ``meta.json`` entries every dataset of the run shares (``run``: the
    :class:`ntq_jax.data.generate.RunSpec`)."""
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "env": env.name,
        "env_name": run.env_name,
        "env_slug": run.slug,
        "seed": opts.seed,
        "k_train": run.k,
        "padding": run.padding,
        "prune_padding": run.prune_padding,
        "planner": {
            "name": run.planner_name,
            "options": run.options,
            **({} if run.data_paths is None else {"data_paths": run.data_paths}),
            # where the recorded paths come from (the planner above plans the rest)
            **({} if run.record is None else {"paths_from": run.record}),
        },
        "sampling": {"n_max": opts.n_max},
        "gamma_nt": g_data,
        "gamma_nt_eval": g_eval,
        "package_version": __version__,
        "config_hash": opts.recorded_hash(),
        "fingerprint": run.fingerprint,
        "query_kind_values": QUERY_KINDS,
    }
