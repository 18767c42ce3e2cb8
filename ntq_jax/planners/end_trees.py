"""Small trees for the query ends a roadmap cannot reach: :func:`grow_end_trees`.

A query end in a pocket of the free space (the Panda's hand inside a shelf or a cage)
may reach none of its nearest milestones by a straight motion, although a short
crooked one leaves the pocket. For each such end a small tree grows from it, RRT-like
and batched over all such ends:

* each round, every end's tree draws ``samples`` targets uniformly in the configuration
  box and extends its node nearest to each (in the robot's metric, Euclidean here)
  towards it by at most ``step``: RRT's extension, whose Voronoi bias leads the tree
  out of a pocket where blind local steps stay inside; a new state becomes a node
  when the motion from its parent is free (in the travelled direction: away from a
  start, towards a goal);
* every new node tries its ``attach`` nearest milestones; the first new node (in draw
  order) that reaches one ends its end's growth: the end's *chain* is the tree path from
  the end to that node, and its edges to the roadmap are the node's free motions to (or
  from) those milestones, costed from the end.

All checks of a round go through one call of the package's batched ``steer_to``. An
end's random draws come from a generator seeded by the end's own float32 state and
``seed``, so an end's tree does not depend on the other ends of the batch (the roadmap
planner's promise that a query's path does not depend on its batch). An end that has
not reached the roadmap after ``rounds`` rounds stays unattached.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ntq_jax.planners.verify import motions_free
from ntq_jax.robots.batch import distances

__all__ = ["EndLink", "grow_end_trees"]


class EndLink(NamedTuple):
    """How a query end reaches the roadmap through its tree.

    ``chain (m, d)`` float32: the states from the end (first) to the node that reaches
    the roadmap (last); ``milestones (j,)`` int64 the milestones that node reaches (from
    the node for a start, to it for a goal); ``costs (j,)`` float64 the cost from the end
    along the chain to each milestone.
    """

    chain: np.ndarray
    milestones: np.ndarray
    costs: np.ndarray


def _end_rng(end: np.ndarray, seed: int) -> np.random.Generator:
    """The generator of one end: seeded by its float32 bits and ``seed``."""
    bits = np.ascontiguousarray(end, np.float32).view(np.uint32)
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, *map(int, bits)])


def grow_end_trees(
    robot,
    world,
    index,
    ends: np.ndarray,
    outgoing: bool,
    padding: float,
    check: str,
    *,
    rounds: int,
    samples: int,
    step: float,
    attach: int,
    seed: int = 0,
    targets: np.ndarray | None = None,
) -> list[EndLink | None]:
    """Grows a tree from each end until a node reaches the roadmap (see the module docstring).

    Args:
        robot, world: the geometry.
        index: the milestones' :class:`ntq_jax.planners.roadmap.MetricIndex`.
        ends: ``(E, d)`` float32 query ends (starts when ``outgoing``, else goals).
        outgoing: the ends are starts (motions leave them) or goals (motions reach them).
        padding: planning clearance.
        check: the motion check.
        rounds: growth rounds; ``samples``: extensions per end and round; ``step``:
            the longest extension (the robot's metric); ``attach``: milestones each new
            node tries.
        seed: mixed into every end's generator.
        targets: ``(N,)`` bool over the milestones, the ones worth reaching (None:
            all); a node that reaches only others does not end the growth (a
            milestone of a tiny roadmap component in the same pocket as the end).

    Returns:
        Per end, its :class:`EndLink`, or None when it did not reach the roadmap.
    """
    ends = np.asarray(ends, np.float32)
    num, d = ends.shape
    lo, hi = (np.asarray(v, np.float32) for v in robot.config_bounds(world))
    rngs = [_end_rng(e, seed) for e in ends]
    nodes = [[e] for e in ends]  # states
    parent = [[-1] for _ in ends]
    cost = [[0.0] for _ in ends]  # from the end
    out: list[EndLink | None] = [None] * num
    for _ in range(int(rounds)):
        live = [e for e in range(num) if out[e] is None]
        if not live:
            break
        owner, par, draw = _extend(nodes, live, rngs, lo, hi, samples, step)
        base = np.stack([nodes[e][p] for e, p in zip(owner, par)])
        a, b = (base, draw) if outgoing else (draw, base)
        free = motions_free(robot, world, a, b, padding, check=check)
        step_cost = distances(robot, base, draw).astype(np.float64)
        new = np.flatnonzero(free)
        new_id = np.empty(len(owner), np.int64)
        for j in new:  # append in draw order
            e = owner[j]
            new_id[j] = len(nodes[e])
            nodes[e].append(draw[j])
            parent[e].append(int(par[j]))
            cost[e].append(cost[e][par[j]] + step_cost[j])
        if not len(new):
            continue
        idx, _ = index.query(draw[new], attach)
        rows = np.repeat(np.arange(len(new)), idx.shape[1])
        ms = index.points[idx.reshape(-1)]
        p = draw[new][rows]
        a, b = (p, ms) if outgoing else (ms, p)
        reach = motions_free(robot, world, a, b, padding, check=check).reshape(idx.shape)
        if targets is not None:
            reach &= targets[idx]
        link_cost = distances(robot, a, b).astype(np.float64).reshape(idx.shape)
        for r in np.flatnonzero(reach.any(axis=1)):  # draw order: the first node wins
            j = new[r]
            e = owner[j]
            if out[e] is not None:
                continue
            chain, v = [], int(new_id[j])
            while v >= 0:
                chain.append(nodes[e][v])
                v = parent[e][v]
            hit = reach[r]
            out[e] = EndLink(
                np.asarray(chain[::-1], np.float32),
                idx[r][hit].astype(np.int64),
                cost[e][new_id[j]] + link_cost[r][hit],
            )
    return out


def _extend(
    nodes: list, live: list, rngs: list, lo: np.ndarray, hi: np.ndarray, samples: int, step: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One round's RRT extensions of the trees ``live``: ``(owner, parent, state)`` per
    draw, ``samples`` per tree, in draw order (a uniform target, the tree's nearest node
    moved towards it by at most ``step``, clipped to the box)."""
    d = lo.shape[0]
    owner, par, draw = [], [], []
    for e in live:
        target = lo + rngs[e].random((samples, d), np.float32) * (hi - lo)
        tree = np.asarray(nodes[e], np.float32)
        gap = target[:, None, :] - tree[None, :, :]
        pick = np.argmin(np.einsum("snd,snd->sn", gap, gap), axis=1)
        vec = target - tree[pick]
        norm = np.linalg.norm(vec, axis=1, keepdims=True)
        cand = tree[pick] + vec * np.minimum(1.0, step / np.maximum(norm, 1e-12))
        owner.append(np.full(samples, e))
        par.append(pick)
        draw.append(np.clip(cand, lo, hi).astype(np.float32))
    return np.concatenate(owner), np.concatenate(par), np.concatenate(draw)
