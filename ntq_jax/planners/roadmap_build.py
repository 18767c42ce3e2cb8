"""A checked probabilistic roadmap of one environment: :func:`build_roadmap` and its cache.

The build half of the ``"roadmap"`` planner (:mod:`ntq_jax.planners.roadmap` plans
queries on it): ``milestones`` valid states sampled at the planning padding, each
joined to its ``k`` nearest neighbours under the robot's metric (:class:`MetricIndex`:
a KD-tree on the embedding ``metric_weights * q`` with the periodic coordinates on a
circle, candidates re-ranked by the exact metric; ``k`` by default PRM*'s rule,
:func:`prm_star_k`), every edge checked with the package's batched motion check and
weighted by the metric. :func:`roadmap_for` returns an environment's roadmap for a
growth round, deterministic for ``roadmap_seed``, kept in memory per environment and,
with ``cache_dir``, on disk under a fingerprint of the map, robot, padding and settings.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np
from scipy.spatial import cKDTree

from ntq_jax import artifacts
from ntq_jax.geometry import World
from ntq_jax.planners.env_cache import EnvCache
from ntq_jax.planners.verify import motions_free
from ntq_jax.queries import sample_states
from ntq_jax.robots.batch import distances

__all__ = [
    "Roadmap",
    "MetricIndex",
    "prm_star_k",
    "undirected_pairs",
    "build_roadmap",
    "roadmap_for",
    "ALGORITHM_VERSION",
]

ALGORITHM_VERSION = 1  # bump when a roadmap built from the same settings changes


class Roadmap(NamedTuple):
    """A checked roadmap: ``milestones (N, d)`` float32; ``edges (E, 2)`` int32 pairs
    ``i < j`` whose connection ``m_i -> m_j`` passed ``steer_to``; ``costs (E,)``
    float64 their lengths in the robot's metric."""

    milestones: np.ndarray
    edges: np.ndarray
    costs: np.ndarray


class MetricIndex:
    """k nearest neighbours of ``points`` under a robot's metric.

    A KD-tree on ``metric_weights * (q - lo)`` with each periodic coordinate on a
    circle (the tree's periodic box) finds ``oversample * k`` candidates; the
    exact metric (``robot.distance``) picks the ``k`` nearest of them.
    """

    def __init__(self, robot, world: World, points: np.ndarray, oversample: int = 2):
        lo, hi = (np.asarray(v, np.float64) for v in robot.config_bounds(world))
        w = np.asarray(robot.metric_weights, np.float64)
        periodic = np.asarray(robot.periodic, bool)
        span = w * (hi - lo)
        # a non-periodic box larger than twice the span never wraps a distance
        self._box = np.where(periodic, span, 2.0 * span + 1.0)
        self._lo, self._w, self._robot, self._oversample = lo, w, robot, int(oversample)
        self.points = np.asarray(points, np.float32)
        self._tree = cKDTree(self._embed(self.points), boxsize=self._box)

    def _embed(self, x: np.ndarray) -> np.ndarray:
        return np.mod(self._w * (np.asarray(x, np.float64) - self._lo), self._box)

    def query(
        self, x: np.ndarray, k: int, exclude_self: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(idx (M, k) int64, dist (M, k) float64)``, nearest first, by the exact metric."""
        x = np.asarray(x, np.float32)
        n = len(self.points)
        k = min(k, n - int(exclude_self))
        m = min(n, self._oversample * k + int(exclude_self))
        _, idx = self._tree.query(self._embed(x), m)
        idx = idx.reshape(len(x), m)
        if exclude_self:  # drop the point itself (the nearest, or a duplicate at distance 0)
            rows = np.arange(len(x))[:, None]
            idx = np.where(idx == rows, idx[:, -1:], idx)[:, :m]
        a = np.repeat(x, m, axis=0)
        dist = distances(self._robot, a, self.points[idx.reshape(-1)]).astype(np.float64)
        dist = dist.reshape(len(x), m)
        order = np.argsort(dist, axis=1, kind="stable")[:, :k]
        return np.take_along_axis(idx, order, 1), np.take_along_axis(dist, order, 1)


def prm_star_k(n: int, d: int) -> int:
    """PRM*'s neighbour count ``ceil(e (1 + 1/d) log n)`` (at least 1)."""
    return max(1, math.ceil(math.e * (1.0 + 1.0 / d) * math.log(max(n, 2))))


def undirected_pairs(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """The distinct undirected edges ``{i, j}`` (``i != j``) among nodes ``0..n-1``, as
    ``(E, 2)`` int64 rows ``(min, max)`` in lexicographic order."""
    lo, hi = np.minimum(i, j).astype(np.int64), np.maximum(i, j).astype(np.int64)
    code = np.sort((lo * n + hi)[lo != hi])  # one int64 per edge: sorts as (lo, hi)
    code = code[np.r_[True, code[1:] != code[:-1]]] if code.size else code
    return np.stack([code // n, code % n], 1)


def build_roadmap(
    robot,
    world: World,
    padding: float,
    *,
    milestones: int,
    k: int,
    key: jax.Array,
    check: str = "discretized",
) -> Roadmap:
    """Samples ``milestones`` valid states and keeps the free edges to their ``k`` nearest."""
    states = sample_states(robot, world, key, int(milestones), padding)
    index = MetricIndex(robot, world, states)
    nbr, _ = index.query(states, k, exclude_self=True)
    pairs = undirected_pairs(
        np.repeat(np.arange(len(states)), nbr.shape[1]), nbr.reshape(-1), len(states)
    )
    a, b = states[pairs[:, 0]], states[pairs[:, 1]]
    free = motions_free(robot, world, a, b, padding, check=check)
    edges = pairs[free].astype(np.int32)
    costs = distances(robot, a[free], b[free]).astype(np.float64)
    return Roadmap(states, edges, costs)


_MEMORY = EnvCache(per_env=4)


def roadmap_for(
    env,
    padding: float,
    *,
    milestones: int,
    k: int,
    roadmap_seed: int,
    round_: int = 0,
    cache_dir: str | Path | None = None,
    check: str = "discretized",
) -> Roadmap:
    """The roadmap of ``env`` for these settings: from memory, from ``cache_dir``, or built.

    Round ``r`` uses ``milestones * 2**r`` milestones and its own sample.
    """
    n = int(milestones) * 2 ** int(round_)
    key = jax.random.fold_in(jax.random.key(int(roadmap_seed)), int(round_))
    robot, world = env.robot, env.world

    def build() -> dict:
        rm = build_roadmap(robot, world, padding, milestones=n, k=int(k), key=key, check=check)
        return rm._asdict()

    def load() -> Roadmap:
        if cache_dir is None:
            return Roadmap(**build())
        # the discretised check's fingerprint is the one from before ``check`` existed
        extra = () if check == "discretized" else (check,)
        fp = artifacts.fingerprint(
            ALGORITHM_VERSION,
            env.to_json(),
            float(padding),
            n,
            int(k),
            int(roadmap_seed),
            int(round_),
            *extra,
        )
        got = artifacts.compute_or_load(Path(cache_dir) / f"roadmap_{fp}.npz", fp, build)
        return Roadmap(*(np.asarray(got[f]) for f in Roadmap._fields))

    return _MEMORY.get(
        env,
        (
            float(padding),
            n,
            int(k),
            int(roadmap_seed),
            int(round_),
            None if cache_dir is None else str(cache_dir),
            check,
        ),
        load,
    )
