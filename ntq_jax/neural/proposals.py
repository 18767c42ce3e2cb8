"""The ensemble planner's proposals inside the jitted steps (:mod:`ntq_jax.neural.steps`).

Wherever a step asks the PNet for a next state it goes through :func:`propose`: one PNet's
prediction, or, for an :class:`EnsemblePNet`, every member's prediction and the
:func:`choose` rule. :class:`MemberBlocks` runs several PNets side by side in one batch
(:func:`ntq_jax.neural.driver.plan_members`); :func:`is_key_stack`, :func:`fold_in` and
:func:`split2` take one PRNG key or a stack of keys (one per member).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.tree_util import Partial

from ntq_jax.neural.motions import steer as _steer

Array = jax.Array


@jax.tree_util.register_pytree_node_class
class EnsemblePNet:
    """Several PNets planning together (the ensemble planner; a pytree of its members).

    Each member is a ``pnet(key, current, goal)`` (e.g. a
    :class:`jax.tree_util.Partial`); at every step where the planner asks for a
    next state, every member predicts from the same ``(key, current, goal)``
    (each member's own dropout stream comes from its function, e.g.
    :func:`ntq_jax.models.member_pnets` folds in the member index, as in the
    members' own evaluation) and :func:`choose` picks one of the predictions.
    The members are called in a Python loop inside the jitted step: one
    compiled call predicts for every member and every query of a batch.
    """

    def __init__(self, members):
        self.members = tuple(members)

    def __len__(self) -> int:
        return len(self.members)

    def tree_flatten(self):
        return self.members, None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children)


@jax.tree_util.register_pytree_node_class
class MemberBlocks:
    """Several PNets planning side by side in one batch, each on its own block of rows.

    Called as ``pnet(key, current (M*W, d), goal (M*W, d))``: the rows are ``M``
    blocks of ``W`` (member-major), member ``m`` predicts for block ``m`` only
    (``M`` predictions of ``W`` rows: the members' work, not ``M`` times it), and
    the blocks are concatenated back. ``key`` is one key (every member gets it)
    or ``M`` keys, one per member (:func:`fold_in` folds a stack of keys row by
    row). Each block sees exactly what the member sees when it plans alone on
    the same rows with that key, so :func:`ntq_jax.neural.driver.plan_members`
    reproduces the members' own plans (a pytree of its members, like
    :class:`EnsemblePNet`).
    """

    def __init__(self, members):
        self.members = tuple(members)

    def __len__(self) -> int:
        return len(self.members)

    def __call__(self, key, current: Array, goal: Array) -> Array:
        m = len(self.members)
        w = current.shape[0] // m
        batched = is_key_stack(key)
        stacked = _stacked_partials(self.members)
        if stacked is not None:  # one function: vmapped over the members' bound arguments
            func, args = stacked
            keys = key if batched else jnp.broadcast_to(key, (m,) + key.shape)
            out = jax.vmap(lambda a, k, c, g: func(*a, k, c, g))(
                args, keys, current.reshape(m, w, -1), goal.reshape(m, w, -1)
            )
            return out.reshape(m * w, -1)
        return jnp.concatenate(
            [
                p(
                    key[i] if batched else key,
                    current[i * w : (i + 1) * w],
                    goal[i * w : (i + 1) * w],
                )
                for i, p in enumerate(self.members)
            ]
        )

    def tree_flatten(self):
        return self.members, None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children)


def _stacked_partials(members):
    """``(func, stacked args)`` when every member is a ``Partial`` of one function with
    arguments of one structure and shape (e.g. an ensemble's members), else None."""
    first = members[0]
    if not all(isinstance(p, Partial) and p.func is first.func and not p.keywords for p in members):
        return None
    trees = [jax.tree_util.tree_structure(p.args) for p in members]
    shapes = [[jnp.shape(x) for x in jax.tree_util.tree_leaves(p.args)] for p in members]
    if any(t != trees[0] for t in trees) or any(s != shapes[0] for s in shapes):
        return None
    return first.func, jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *[p.args for p in members])


def is_key_stack(key) -> bool:
    """True for a stack of PRNG keys (one per member), False for a single key (typed
    keys of shape ``()`` or raw ``uint32`` keys of shape ``(2,)``)."""
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    return key.ndim > (0 if typed else 1)


def fold_in(key, data) -> Array:
    """:func:`jax.random.fold_in` of one key, or of each key of a stack (:func:`is_key_stack`)."""
    if is_key_stack(key):
        return jax.vmap(jax.random.fold_in, in_axes=(0, None))(key, data)
    return jax.random.fold_in(key, data)


def split2(key) -> tuple[Array, Array]:
    """:func:`jax.random.split` into two, of one key or of each key of a stack."""
    if is_key_stack(key):
        ks = jax.vmap(jax.random.split)(key)
        return ks[:, 0], ks[:, 1]
    k0, k1 = jax.random.split(key)
    return k0, k1


def proposals_per_call(pnet) -> int:
    """PNet predictions per :func:`propose` call (the member count of an ensemble, else 1)."""
    return len(pnet) if isinstance(pnet, EnsemblePNet) else 1


def choose(
    robot,
    world,
    cands: Array,
    cur: Array,
    tgt: Array,
    live: Array,
    padding: float,
    steer: bool = True,
) -> Array:
    """The ensemble's rule: the index ``(N,)`` of the candidate to append, per row.

    ``cands (M, N, d)`` are the members' proposals from ``cur (N, d)`` towards
    ``tgt (N, d)`` (the goal of the coarse plan, or the other tree's end in a
    bidirectional connection and in neural replanning). With ``c`` a candidate,
    ``dist`` the robot's metric (``robot.distance``) and steerTo the planner's
    own (discretised) check at ``padding``, candidates are ranked by tier, then
    by a score, then by member index (the first member wins a tie):

    0. ``steerTo(c, tgt)`` and ``steerTo(cur, c)`` free (``cur -> c -> tgt`` is a
       free path): score ``dist(cur, c) + dist(c, tgt)``, the cheapest such path;
    1. ``steerTo(c, tgt)`` free only: same score;
    2. ``steerTo(cur, c)`` free only: score ``dist(c, tgt)``, the remaining
       cost-to-go (the candidate that reduces it most);
    3. the others: score ``dist(c, tgt)`` (the lowest cost-to-go).

    Without steerTo (``steer=False``, the paper's variant without the steering
    function) only the cost-to-go is used (every candidate in tier 3). A
    non-finite score counts as infinite. Rows not ``live`` are not checked
    (their choice is irrelevant). The rule is deterministic, so the ensemble
    planner stays deterministic given its key, and ``M`` identical candidates
    give candidate 0, the single member's prediction.
    """
    m, n, d = cands.shape
    flat = cands.reshape(m * n, d)
    tgt_m, cur_m = jnp.tile(tgt, (m, 1)), jnp.tile(cur, (m, 1))
    dist = jax.vmap(robot.distance)
    ctg = dist(flat, tgt_m).reshape(m, n)
    if steer:
        live_m = jnp.tile(live, m)
        to_tgt = _steer(robot, world, flat, tgt_m, padding, live_m).reshape(m, n)
        from_cur = _steer(robot, world, cur_m, flat, padding, live_m).reshape(m, n)
        tier = jnp.where(to_tgt, jnp.where(from_cur, 0, 1), jnp.where(from_cur, 2, 3))
        score = jnp.where(to_tgt, dist(cur_m, flat).reshape(m, n) + ctg, ctg)
    else:
        tier = jnp.zeros((m, n), jnp.int32)
        score = ctg
    score = jnp.where(jnp.isnan(score), jnp.inf, score)
    best = jnp.min(tier, axis=0)
    return jnp.argmin(jnp.where(tier == best[None], score, jnp.inf), axis=0)


def propose(
    robot, world, pnet, key, cur: Array, tgt: Array, live: Array, padding: float, steer: bool = True
) -> Array:
    """The next state ``(N, d)`` from ``cur`` towards ``tgt``: the PNet's prediction, or
    for an :class:`EnsemblePNet` every member's and the one :func:`choose` picks."""
    if not isinstance(pnet, EnsemblePNet):
        return pnet(key, cur, tgt)
    if len(pnet) == 1:
        return pnet.members[0](key, cur, tgt)
    cands = jnp.stack([p(key, cur, tgt) for p in pnet.members])
    idx = choose(robot, world, cands, cur, tgt, live, padding, steer)
    return jnp.take_along_axis(cands, idx[None, :, None], axis=0)[0]
