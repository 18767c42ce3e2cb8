"""PNet (MPNet's planning network) and a stacked ensemble of PNets.

A :class:`PNet` maps ``(current, goal)`` to the next state on a path. It is
MPNet's MLP: ``Linear -> PReLU`` for every hidden width, dropout after the
first ``dropout_layers`` hidden layers, and a linear output layer.

**Normalisation.** States enter and leave the network in ``[-1, 1]``: every
coordinate ``q_k`` is mapped by the robot's configuration bounds
``(lo_k, hi_k)`` (``env.robot.config_bounds``) to ``2 (q_k - lo_k) / (hi_k -
lo_k) - 1``; the network's output is mapped back the same way. The public
functions (:meth:`PNet.__call__`, :func:`predictor`) take and return states in
the robot's own coordinates (radians for angles); the training loss is
computed in normalised units so that every coordinate weighs the same.

**Angles.** A coordinate is *periodic* when it is an angle whose two bounds
are the same orientation (the rigid body's ``theta`` in ``[-pi, pi)``). The
n-link arm's joint angles are *not* periodic: the paper limits them to
``[-pi, pi]`` without wrap-around, so they are treated like positions. For a
periodic coordinate

* the loss uses the shortest arc: the normalised error ``e`` is wrapped to
  ``[-1, 1)`` (``e -> (e + 1) mod 2 - 1``; a full turn is 2 normalised units),
  so predicting ``pi - 0.01`` for a target of ``-pi + 0.01`` costs 0.02 rad,
  not ``2 pi - 0.02``;
* the prediction is wrapped into ``[lo, hi)`` (``[-pi, pi)``), so the network
  may output any real and the planner always gets a canonical angle;
* the input is the normalised angle as is (the cut at ``+-pi`` is a
  discontinuity of the input only; the data never cross it within a row
  because the robot's interpolation takes the shortest arc).

Non-periodic outputs are not clipped (MPNet does not clip; the planner's
validity check rejects states outside the bounds).

**Ensembles.** :class:`Ensemble` holds ``M`` PNets of one architecture as one
``nnx.GraphDef`` plus one ``nnx.State`` whose every array has a leading member
axis (``nnx.split`` of each member, stacked). Computation over members uses
``jax.vmap`` over that axis; :func:`member` merges one member back into a
:class:`PNet`.

**Dropout at planning time.** MPNet plans stochastically: dropout stays active
when predicting. Every random choice comes from an explicit PRNG key
(``key`` arguments), never from hidden module state, so :func:`predictor`
returns a pure, jittable function.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx
from jax.tree_util import Partial

from ntq_jax import prng
from ntq_jax.errors import check_config as _check


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    """PNet (MPNet's MLP).

    Attributes:
        hidden: hidden layer widths.
        dropout: dropout rate after the first ``dropout_layers`` hidden layers.
        dropout_layers: how many hidden layers are followed by dropout.
    """

    hidden: tuple[int, ...] = (256, 256, 128, 64)
    dropout: float = 0.5
    dropout_layers: int = 2

    def validate(self, p: str):
        _check(
            len(self.hidden) >= 1 and all(h >= 1 for h in self.hidden),
            f"{p}.hidden",
            f"must be a non-empty list of positive widths, got {list(self.hidden)}",
        )
        _check(0.0 <= self.dropout < 1.0, f"{p}.dropout", f"must be in [0, 1), got {self.dropout}")
        _check(
            0 <= self.dropout_layers <= len(self.hidden),
            f"{p}.dropout_layers",
            f"must be in [0, {len(self.hidden)}], got {self.dropout_layers}",
        )


Array = jax.Array

PRELU_INIT = 0.25  # torch.nn.PReLU's default, as MPNet uses it


@dataclasses.dataclass(frozen=True)
class ModelSpec:
    """Everything needed to rebuild a PNet's graph (JSON-serialisable, hashable).

    Attributes:
        dim: state dimension ``d`` (input ``2 d``, output ``d``).
        hidden: hidden layer widths.
        dropout: dropout rate.
        dropout_layers: how many leading hidden layers are followed by dropout.
        lo, hi: configuration bounds per coordinate (normalisation to ``[-1, 1]``).
        periodic: per coordinate, whether it is an angle with wrap-around.
    """

    dim: int
    hidden: tuple[int, ...]
    dropout: float
    dropout_layers: int
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    periodic: tuple[bool, ...]

    def __post_init__(self):
        if not (len(self.lo) == len(self.hi) == len(self.periodic) == self.dim):
            raise ValueError(f"ModelSpec: lo, hi and periodic must have length dim={self.dim}")
        if any(not h > l for l, h in zip(self.lo, self.hi)):
            raise ValueError(f"ModelSpec: every bound must have hi > lo, got {self.lo}, {self.hi}")
        if not 0 <= self.dropout_layers <= len(self.hidden):
            raise ValueError(f"ModelSpec: dropout_layers must be in [0, {len(self.hidden)}]")

    def to_json(self) -> dict:
        return {
            "dim": self.dim,
            "hidden": list(self.hidden),
            "dropout": self.dropout,
            "dropout_layers": self.dropout_layers,
            "lo": list(self.lo),
            "hi": list(self.hi),
            "periodic": list(self.periodic),
        }

    @staticmethod
    def from_json(d: dict) -> "ModelSpec":
        return ModelSpec(
            dim=int(d["dim"]),
            hidden=tuple(int(h) for h in d["hidden"]),
            dropout=float(d["dropout"]),
            dropout_layers=int(d["dropout_layers"]),
            lo=tuple(float(v) for v in d["lo"]),
            hi=tuple(float(v) for v in d["hi"]),
            periodic=tuple(bool(v) for v in d["periodic"]),
        )

    @staticmethod
    def from_env(env, model_cfg) -> "ModelSpec":
        """The spec of a PNet for ``env``'s robot with the widths of ``model_cfg``.

        Args:
            env: an :class:`ntq_jax.Env` (its robot's ``config_bounds`` and kind are used).
            model_cfg: a :class:`ntq_jax.models.ModelConfig`.
        """
        lo, hi = env.robot.config_bounds(env.world)
        lo = tuple(float(v) for v in np.asarray(lo))
        hi = tuple(float(v) for v in np.asarray(hi))
        return ModelSpec(
            dim=int(env.dim),
            hidden=tuple(model_cfg.hidden),
            dropout=float(model_cfg.dropout),
            dropout_layers=int(model_cfg.dropout_layers),
            lo=lo,
            hi=hi,
            periodic=periodic_dims(env.robot),
        )


def periodic_dims(robot) -> tuple[bool, ...]:
    """Which coordinates of ``robot``'s state wrap around (the robot's own ``periodic``;
    see the module docstring)."""
    return tuple(bool(v) for v in robot.periodic)


class PNet(nnx.Module):
    """MPNet's planning network.

    Args:
        spec: the architecture and normalisation (:class:`ModelSpec`).
        rngs: initialisation keys (``nnx.Rngs``); dropout keys are given per call.
    """

    def __init__(self, spec: ModelSpec, *, rngs: nnx.Rngs):
        self.spec = spec  # static (hashable dataclass): part of the graph definition
        widths = (2 * spec.dim,) + tuple(spec.hidden)
        self.layers = nnx.List([nnx.Linear(a, b, rngs=rngs) for a, b in zip(widths, widths[1:])])
        self.acts = nnx.List([nnx.PReLU(PRELU_INIT) for _ in spec.hidden])
        self.out = nnx.Linear(widths[-1], spec.dim, rngs=rngs)

    # -- normalisation --------------------------------------------------------
    def normalize(self, q: Array) -> Array:
        """Robot coordinates ``(..., d)`` -> ``[-1, 1]``."""
        lo, hi = jnp.asarray(self.spec.lo, jnp.float32), jnp.asarray(self.spec.hi, jnp.float32)
        return 2.0 * (q - lo) / (hi - lo) - 1.0

    def denormalize(self, y: Array) -> Array:
        """``[-1, 1]`` -> robot coordinates, periodic coordinates wrapped into ``[lo, hi)``."""
        lo, hi = jnp.asarray(self.spec.lo, jnp.float32), jnp.asarray(self.spec.hi, jnp.float32)
        q = lo + 0.5 * (y + 1.0) * (hi - lo)
        per = jnp.asarray(self.spec.periodic)
        return jnp.where(per, lo + jnp.mod(q - lo, hi - lo), q)

    # -- network --------------------------------------------------------------
    def net(self, x: Array, key: Array | None, deterministic: bool = False) -> Array:
        """The MLP on normalised input ``(..., 2 d)`` -> normalised output ``(..., d)``.

        Args:
            x: normalised ``(current, goal)``.
            key: dropout key; ignored when ``deterministic`` or the rate is 0.
            deterministic: True switches dropout off (validation).

        Dropout is inverted dropout as ``nnx.Dropout``/``torch.nn.Dropout`` (keep with
        probability ``1 - rate``, scale kept units by ``1 / (1 - rate)``); the masks of
        all dropout layers come from ONE ``prng.uniform_array(key, (..., sum of their
        widths))`` draw (one PRNG call site compiles much faster than one per layer;
        vmapped over the ensemble's members, threefry draws took about half of a
        training step, see BENCHMARKS.md).
        """
        spec = self.spec
        off = deterministic or spec.dropout == 0.0 or spec.dropout_layers == 0
        if not off and key is None:
            raise ValueError("PNet: dropout is active, pass a PRNG key (or deterministic=True)")
        u, offset = None, 0
        if not off:
            u = prng.uniform_array(key, x.shape[:-1] + (sum(spec.hidden[: spec.dropout_layers]),))
        for i, (lin, act) in enumerate(zip(self.layers, self.acts)):
            x = act(lin(x))
            if not off and i < spec.dropout_layers:
                w = spec.hidden[i]
                keep = u[..., offset : offset + w] >= spec.dropout
                x = jnp.where(keep, x / (1.0 - spec.dropout), 0.0)
                offset += w
        return self.out(x)

    def __call__(
        self, current: Array, goal: Array, *, key: Array | None = None, deterministic: bool = False
    ) -> Array:
        """Next state ``(..., d)`` in robot coordinates from ``current`` and ``goal`` ``(..., d)``."""
        x = jnp.concatenate([self.normalize(current), self.normalize(goal)], axis=-1)
        return self.denormalize(self.net(x, key, deterministic))

    def loss(
        self,
        inputs: Array,
        targets: Array,
        mask: Array,
        key: Array | None,
        deterministic: bool = False,
    ) -> Array:
        """Masked mean squared error in normalised units (shortest arc on periodic coordinates).

        Args:
            inputs: ``(B, 2 d)`` rows ``(current, goal)`` in robot coordinates.
            targets: ``(B, d)`` next states in robot coordinates.
            mask: ``(B,)`` weights (1 = a real row, 0 = padding).
            key: dropout key.
            deterministic: dropout off.

        Returns:
            Scalar: ``sum_b mask_b * mean_k e_bk^2 / max(sum_b mask_b, 1)``.
        """
        d = self.spec.dim
        x = jnp.concatenate([self.normalize(inputs[..., :d]), self.normalize(inputs[..., d:])], -1)
        err = self.net(x, key, deterministic) - self.normalize(targets)
        err = wrap_normalized_error(err, self.spec.periodic)
        per_row = jnp.mean(err * err, axis=-1)
        mask = mask.astype(per_row.dtype)
        return jnp.sum(per_row * mask) / jnp.maximum(jnp.sum(mask), 1.0)


def wrap_normalized_error(err: Array, periodic: Sequence[bool]) -> Array:
    """Shortest-arc error on periodic coordinates (a full turn = 2 normalised units)."""
    if not any(periodic):
        return err
    return jnp.where(jnp.asarray(periodic), jnp.mod(err + 1.0, 2.0) - 1.0, err)


# ---------------------------------------------------------------------------
# Ensembles
# ---------------------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Ensemble:
    """``M`` PNets of one architecture, stacked on a leading member axis.

    A pytree: ``params`` is the data, ``graphdef`` and ``spec`` are static.

    Attributes:
        graphdef: the shared ``nnx.GraphDef`` of a :class:`PNet`.
        params: ``nnx.State`` of ``nnx.Param`` arrays, each with leading axis ``M``.
        spec: the :class:`ModelSpec`.
    """

    graphdef: Any = dataclasses.field(metadata=dict(static=True))
    params: Any
    spec: ModelSpec = dataclasses.field(metadata=dict(static=True))

    @property
    def num_members(self) -> int:
        return int(jax.tree.leaves(self.params)[0].shape[0])


def stack_states(states: Sequence[Any]) -> Any:
    """Stacks per-member pytrees of identical structure on a new leading axis."""
    return jax.tree.map(lambda *xs: jnp.stack(xs), *states)


def unstack_state(state: Any, m: int) -> Any:
    """Member ``m``'s slice of a stacked pytree."""
    return jax.tree.map(lambda x: x[m], state)


def init_pnet(spec: ModelSpec, key: Array) -> PNet:
    """One freshly initialised PNet (weights from ``key``, as member ``i`` of
    :func:`init_ensemble` gets from ``member_key(seed, i)``)."""
    graphdef, init = _graph_and_init(spec)
    return nnx.merge(graphdef, unstack_state(init(jnp.stack([key])), 0))


def member_key(seed_or_key, member_id: int) -> Array:
    """The initialisation key of member ``member_id``: ``fold_in(key(seed), member_id)``.

    Keyed by the member's id (not by ``M``), so a member trained alone gets the
    same weights as inside an ensemble.
    """
    key = jax.random.key(seed_or_key) if isinstance(seed_or_key, (int, np.integer)) else seed_or_key
    return jax.random.fold_in(key, member_id)


LECUN_TRUNC = 0.87962566103423978  # std of a standard normal truncated to [-2, 2]


@functools.lru_cache(maxsize=32)
def _graph_and_init(spec: ModelSpec):
    """The (cached) graph definition of ``spec`` and a jitted ``keys (M,) -> stacked params``.

    The initialisation is ``nnx.Linear``'s default distribution (LeCun normal,
    truncated at 2 std, on kernels; zero biases) and PReLU slopes of 0.25, but all
    kernels of a member come from one ``truncated_normal`` draw: one PRNG call
    site instead of one per layer, which compiles several times faster on CPU.
    """
    graphdef, abstract = nnx.split(
        nnx.eval_shape(lambda: PNet(spec, rngs=nnx.Rngs(params=jax.random.key(0)))), nnx.Param
    )
    paths_leaves, treedef = jax.tree_util.tree_flatten_with_path(abstract)
    names = [
        next(k.key for k in reversed(p) if isinstance(k, jax.tree_util.DictKey))
        for p, _ in paths_leaves
    ]
    shapes = [leaf.shape for _, leaf in paths_leaves]
    total = sum(int(np.prod(sh)) for n, sh in zip(names, shapes) if n == "kernel")

    def init_one(key):
        z = jax.random.truncated_normal(key, -2.0, 2.0, (total,), jnp.float32)
        leaves, off = [], 0
        for n, sh in zip(names, shapes):
            if n == "kernel":
                size = int(np.prod(sh))
                std = (1.0 / sh[0]) ** 0.5 / LECUN_TRUNC
                leaves.append(z[off : off + size].reshape(sh) * std)
                off += size
            elif n == "negative_slope":
                leaves.append(jnp.full(sh, PRELU_INIT, jnp.float32))
            else:
                leaves.append(jnp.zeros(sh, jnp.float32))
        return jax.tree_util.tree_unflatten(treedef, leaves)

    return graphdef, jax.jit(jax.vmap(init_one))


def init_ensemble(
    spec: ModelSpec, seed_or_key, num_members: int = 4, member_ids: Sequence[int] | None = None
) -> Ensemble:
    """An ensemble of freshly initialised PNets.

    Args:
        spec: architecture and normalisation.
        seed_or_key: an int seed or a PRNG key.
        num_members: ``M`` (ignored when ``member_ids`` is given).
        member_ids: ids of the members (default ``0..M-1``); member ``i`` is
            initialised from :func:`member_key` ``(seed_or_key, i)``, whatever ``M``.
    """
    ids = list(range(num_members)) if member_ids is None else list(member_ids)
    if not ids:
        raise ValueError("init_ensemble: at least one member")
    graphdef, init = _graph_and_init(spec)
    keys = jnp.stack([member_key(seed_or_key, i) for i in ids])
    return Ensemble(graphdef=graphdef, params=init(keys), spec=spec)


def member(ens: Ensemble, m: int) -> PNet:
    """Member ``m`` as a standalone :class:`PNet` module."""
    return nnx.merge(ens.graphdef, unstack_state(ens.params, m))


def apply_member(
    graphdef, params, key: Array | None, current: Array, goal: Array, deterministic: bool = False
) -> Array:
    """Pure forward pass of one member given its ``params`` (no member axis)."""
    return nnx.merge(graphdef, params)(current, goal, key=key, deterministic=deterministic)


def predictor(
    ens: Ensemble, member: int | None = None, *, deterministic: bool = False
) -> Callable[[Array, Array, Array], Array]:
    """A pure, jittable next-state function in the robot's own coordinates.

    Dropout is active (MPNet plans stochastically) and driven by the explicit key.
    Member ``m`` always uses the key ``fold_in(key, m)``, so
    ``predictor(ens, m)(key, c, g) == predictor(ens)(key, c, g)[m]``.

    Args:
        ens: an :class:`Ensemble` (e.g. from :func:`ntq_jax.training.load_ensemble`).
        member: a member index, or None for all members.
        deterministic: switch dropout off (for diagnostics only).

    Returns:
        ``fn(key, current (N, d), goal (N, d))`` returning ``(N, d)`` for one member,
        or ``(M, N, d)`` for ``member=None``.
    """
    graphdef, params = ens.graphdef, ens.params
    num = ens.num_members

    def one(p, k, current, goal):
        return apply_member(graphdef, p, k, current, goal, deterministic)

    if member is not None:
        if not 0 <= member < num:
            raise ValueError(f"predictor: member must be in [0, {num}), got {member}")
        p_m = unstack_state(params, member)

        def fn(key, current, goal):
            return one(p_m, jax.random.fold_in(key, member), current, goal)

        return fn

    def fn_all(key, current, goal):
        keys = jax.vmap(lambda m: jax.random.fold_in(key, m))(jnp.arange(num))
        return jax.vmap(one, in_axes=(0, 0, None, None))(params, keys, current, goal)

    return fn_all


@functools.lru_cache(maxsize=8)
def _member_apply(graphdef) -> Callable:
    """One apply function per graphdef, so ensembles of one architecture share a compilation."""

    def fn(params, m, key, current, goal):
        return apply_member(graphdef, params, jax.random.fold_in(key, m), current, goal)

    return fn


def member_pnets(ens) -> list[Partial]:
    """One planner-ready PNet per member: ``Partial(apply, params_m, m)``.

    Same semantics as :func:`ntq_jax.models.predictor` ``(ens, m)`` (dropout on,
    key ``fold_in(key, m)``), but the members share one apply function, so the
    neural planner compiles once for the whole ensemble.
    """
    try:
        fn = _member_apply(ens.graphdef)
    except TypeError:  # unhashable graphdef: no sharing across ensembles
        fn = _member_apply.__wrapped__(ens.graphdef)
    return [
        Partial(fn, unstack_state(ens.params, m), jnp.uint32(m)) for m in range(ens.num_members)
    ]
