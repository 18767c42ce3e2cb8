"""How a batch of queries' ends join a roadmap: the checked edges the search starts and ends on.

Each start gets edges to the nearest milestones it reaches (start to milestone), each
goal edges from the nearest milestones that reach it (milestone to goal), and a query
its direct edge when the straight connection is free. Starts only have outgoing and
goals only incoming edges, so a query's edges (and so its path) depend on the query
alone, never on the rest of its batch.

:func:`attach_ends` tries the ``k`` nearest milestones at once or, lazily, the nearest
few first and more only for the ends that reached none; :func:`query_edges` adds the
direct edges and, for the ends that reach no milestone of a main component, small
trees (:mod:`ntq_jax.planners.end_trees`) whose chains lead them out of their pocket.
Used by :mod:`ntq_jax.planners.roadmap`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ntq_jax.planners.end_trees import grow_end_trees
from ntq_jax.planners.graph_search import QueryEdges
from ntq_jax.planners.verify import motions_free
from ntq_jax.robots.batch import distances

__all__ = [
    "Ends",
    "attach_ends",
    "query_edges",
    "main_components",
    "ATTACH_REACH",
    "END_SAMPLES",
    "END_STEP",
    "MAIN_COMPONENT",
]

#: Lazy attachment (``attach`` set): an end tries at most this many milestones (or ``k``).
ATTACH_REACH = 64
#: End trees (:mod:`ntq_jax.planners.end_trees`): extensions per end and round, and the
#: longest extension (radians for the arm).
END_SAMPLES = 16
END_STEP = 0.5
#: An end reaching only milestones of components smaller than this share of the roadmap
#: (isolated milestones in its own pocket) still grows a tree.
MAIN_COMPONENT = 0.01


def attach_ends(
    robot,
    world,
    index,
    points: np.ndarray,
    k: int,
    padding: float,
    outgoing: bool,
    check: str,
    first: int | None = None,
    reach: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges between ``points`` and the nearest milestones they see: ``(point row,
    milestone, cost)``; ``outgoing``: point -> milestone, else milestone -> point.

    ``first`` (None: the ``k`` nearest, all at once): each point tries its ``first``
    nearest milestones, and a point that reaches none of them the next ``2 first``,
    ``4 first``, ... up to ``reach`` (0: ``max(k, ATTACH_REACH)``) in all. A point's
    edges depend only on the point."""
    if first is None:
        idx, _ = index.query(points, k)
        rows = np.repeat(np.arange(len(points)), idx.shape[1])
        ms = index.points[idx.reshape(-1)]
        p = points[rows]
        a, b = (p, ms) if outgoing else (ms, p)
        free = motions_free(robot, world, a, b, padding, check=check)
        cost = distances(robot, a[free], b[free]).astype(np.float64)
        return rows[free], idx.reshape(-1)[free], cost
    total = min(reach or max(k, ATTACH_REACH), len(index.points))
    lo, step, todo = 0, max(1, int(first)), np.arange(len(points))
    got_rows, got_ms = [], []
    while lo < total and len(todo):
        hi = min(total, lo + step)
        idx = index.query(points[todo], hi)[0][:, lo:hi]
        rows = np.repeat(todo, idx.shape[1])
        ms = idx.reshape(-1)
        a, b = (points[rows], index.points[ms]) if outgoing else (index.points[ms], points[rows])
        free = motions_free(robot, world, a, b, padding, check=check)
        got_rows.append(rows[free])
        got_ms.append(ms[free])
        todo = np.setdiff1d(todo, rows[free])
        lo, step = hi, 2 * step
    rows, ms = np.concatenate(got_rows), np.concatenate(got_ms)
    order = np.lexsort((ms, rows))
    rows, ms = rows[order], ms[order]
    a, b = (points[rows], index.points[ms]) if outgoing else (index.points[ms], points[rows])
    return rows, ms, distances(robot, a, b).astype(np.float64)


class Ends(NamedTuple):
    """What :func:`query_edges` found for a batch of queries: their :class:`QueryEdges`
    and the chains of the ends joined through a tree (query row -> ``(m, d)`` states,
    the start first for a start, the goal last for a goal)."""

    edges: QueryEdges
    start_chains: dict
    goal_chains: dict


def query_edges(
    robot,
    world,
    rm,
    index,
    q: np.ndarray,
    k: int,
    padding: float,
    check: str,
    attach: int | None = None,
    end_rounds: int = 0,
    seed: int = 0,
    reach: int = 0,
    direct: bool = True,
) -> Ends:
    """The checked edges of the queries' ends: each start to the nearest ``k``
    milestones it reaches, the nearest ``k`` milestones that reach its goal to the
    goal (``attach``, ``reach``: lazily, see :func:`attach_ends`), and (``direct``) the start
    to its goal when that connection is free. With ``end_rounds``, an end that reaches
    no milestone grows a tree for that many rounds
    (:func:`ntq_jax.planners.end_trees.grow_end_trees`)."""
    s_row, s_m, s_c = attach_ends(
        robot, world, index, q[:, 0], k, padding, True, check, attach, reach
    )
    g_row, g_m, g_c = attach_ends(
        robot, world, index, q[:, 1], k, padding, False, check, attach, reach
    )
    chains: list[dict] = [{}, {}]
    if end_rounds:
        big = main_components(rm)
        grown = [[s_row, s_m, s_c], [g_row, g_m, g_c]]
        for side, outgoing in ((0, True), (1, False)):
            rows, ms = grown[side][:2]
            lone = np.setdiff1d(np.arange(len(q)), rows[big[ms]])
            if not len(lone):
                continue
            links = grow_end_trees(
                robot,
                world,
                index,
                q[lone, side],
                outgoing,
                padding,
                check,
                rounds=end_rounds,
                samples=END_SAMPLES,
                step=END_STEP,
                attach=attach or k,
                seed=seed,
                targets=big,
            )
            extra = [(i, link) for i, link in zip(lone, links) if link is not None]
            for i, link in extra:
                chains[side][int(i)] = link.chain if outgoing else link.chain[::-1]
            if extra:
                grown[side] = [
                    np.concatenate(
                        [grown[side][0]] + [np.full(len(l.milestones), i) for i, l in extra]
                    ),
                    np.concatenate([grown[side][1]] + [l.milestones for _, l in extra]),
                    np.concatenate([grown[side][2]] + [l.costs for _, l in extra]),
                ]
        (s_row, s_m, s_c), (g_row, g_m, g_c) = grown
    d_row = (
        np.flatnonzero(motions_free(robot, world, q[:, 0], q[:, 1], padding, check=check))
        if direct
        else np.zeros(0, np.int64)
    )
    d_c = distances(robot, q[d_row, 0], q[d_row, 1]).astype(np.float64)
    return Ends(
        QueryEdges.from_rows(len(q), s_row, s_m, s_c, g_row, g_m, g_c, d_row, d_c),
        chains[0],
        chains[1],
    )


def main_components(rm) -> np.ndarray:
    """``(N,)`` bool: the milestones in a component of the roadmap holding at least
    :data:`MAIN_COMPONENT` of the milestones (or in the largest one)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(rm.milestones)
    g = coo_matrix((np.ones(len(rm.edges)), (rm.edges[:, 0], rm.edges[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    size = np.bincount(label)
    return size[label] >= min(size.max(), MAIN_COMPONENT * n)
