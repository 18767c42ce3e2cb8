"""The pure training step of the ensemble and its compiled multi-step chunk.

:class:`TrainState` stacks every member's parameters and optax state on a
leading member axis. :func:`member_step` is one member's optimisation step (a
no-op when the member is inactive, i.e. has finished its epochs);
:func:`make_train_chunk` jit-compiles ``steps`` of them (``lax.scan`` of
``jax.vmap(member_step)``) followed, on request, by the dropout-free
validation loss. :func:`train_chunk` returns the compiled chunk of a config
from a small bounded cache. Randomness is explicit: member ``m``'s dropout
key at global step ``g`` is ``fold_in(dropout_keys[m], g)``. Throughput:
BENCHMARKS.md (``benchmarks/bench_train.py``).
"""

from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import nnx

from ntq_jax.training.config import TrainConfig

__all__ = [
    "TrainState",
    "make_optimizer",
    "member_step",
    "member_val_loss",
    "make_train_chunk",
    "train_chunk",
]

Array = jax.Array


class TrainState(NamedTuple):
    """Stacked training state: every leaf has a leading member axis."""

    params: Any
    opt_state: Any


def make_optimizer(train_cfg: TrainConfig) -> optax.GradientTransformation:
    """The optimizer of every member (MPNet: Adagrad with lr 0.01).

    Adagrad uses ``eps = 1e-10`` (optax adds it under the square root, PyTorch
    outside) and starts its accumulator at ``train.adagrad_initial_accumulator``
    (default 0, as PyTorch's ``torch.optim.Adagrad`` that MPNet uses; the
    paper-width configs use 0.1, see ``configs/point.yaml``).
    """
    lr = train_cfg.learning_rate
    if train_cfg.optimizer == "adagrad":
        return optax.adagrad(
            lr, initial_accumulator_value=train_cfg.adagrad_initial_accumulator, eps=1e-10
        )
    if train_cfg.optimizer == "adam":
        return optax.adam(lr)
    return optax.sgd(lr)


def _tree_where(cond: Array, new, old):
    return jax.tree.map(lambda a, b: jnp.where(cond, a, b), new, old)


def member_step(graphdef, tx, params, opt_state, x, y, key, idx, mask, active):
    """One optimisation step of one member on rows ``idx`` of its data ``(x, y)``.

    A no-op (parameters and optimizer state returned unchanged) when ``active`` is False.

    Returns:
        ``(params, opt_state, loss)``.
    """

    def loss_fn(p):
        return nnx.merge(graphdef, p).loss(x[idx], y[idx], mask, key)

    loss, grads = jax.value_and_grad(loss_fn)(params)
    updates, new_opt = tx.update(grads, opt_state, params)
    new_params = optax.apply_updates(params, updates)
    return (_tree_where(active, new_params, params), _tree_where(active, new_opt, opt_state), loss)


def member_val_loss(graphdef, params, x, y, mask):
    """Dropout-free loss of one member over padded validation rows.

    Args:
        x, y, mask: ``(C, R, 2d)``, ``(C, R, d)``, ``(C, R)``: rows in ``C`` chunks of ``R``.

    Returns:
        The mean loss over the unmasked rows.
    """
    model = nnx.merge(graphdef, params)

    def one(args):
        xc, yc, mc = args
        return model.loss(xc, yc, mc, None, deterministic=True) * jnp.sum(mc)

    total = jnp.sum(jax.lax.map(one, (x, y, mask)))
    return total / jnp.maximum(jnp.sum(mask), 1.0)


def make_train_chunk(graphdef, tx, steps: int) -> Callable:
    """A jitted function running ``steps`` ensemble steps (``lax.scan`` of a vmapped step),
    then, if asked, the validation loss (fused: one compilation instead of two).

    Returns:
        ``fn(state, x (M, N, 2d), y (M, N, d), dropout_keys (M,), g0, idx (K, M, B),
        mask (K, M, B), active (K, M), val_x, val_y, val_mask, do_eval) -> (state,
        losses (K, M), val_loss (M,))``; member ``m`` at global step ``g0 + k`` uses the
        dropout key ``fold_in(dropout_keys[m], g0 + k)``; ``val_loss`` is 0 unless
        ``do_eval`` (validation arrays as in :func:`member_val_loss`, with a member axis).
        ``state`` is donated.
    """

    def one(p, o, x, y, k, i, mk, a):
        return member_step(graphdef, tx, p, o, x, y, k, i, mk, a)

    def vstep(*args):
        if args[-1].shape[0] == 1:  # one member: no vmap (XLA:CPU runs its dots faster)
            squeeze = functools.partial(jax.tree.map, lambda v: v[0])
            return jax.tree.map(lambda v: v[None], one(*squeeze(args)))
        return jax.vmap(one)(*args)

    veval = jax.vmap(lambda p, x, y, mk: member_val_loss(graphdef, p, x, y, mk))

    def chunk(
        state: TrainState,
        x,
        y,
        dropout_keys,
        g0,
        idx,
        mask,
        active,
        val_x,
        val_y,
        val_mask,
        do_eval,
    ):
        def body(carry, inp):
            k, idx_k, mask_k, act_k = inp

            def step(carry):
                params, opt = carry
                keys = jax.vmap(lambda dk: jax.random.fold_in(dk, g0 + k))(dropout_keys)
                params, opt, loss = vstep(params, opt, x, y, keys, idx_k, mask_k, act_k)
                return (params, opt), loss

            def skip(carry):  # no member active (padding of the last chunk): no compute
                return carry, jnp.zeros(act_k.shape, jnp.float32)

            return jax.lax.cond(jnp.any(act_k), step, skip, carry)

        (params, opt), losses = jax.lax.scan(
            body, (state.params, state.opt_state), (jnp.arange(steps), idx, mask, active)
        )
        val = jax.lax.cond(
            do_eval,
            lambda p: veval(p, val_x, val_y, val_mask),
            lambda p: jnp.zeros(val_mask.shape[:1], jnp.float32),
            params,
        )
        return TrainState(params, opt), losses, val

    return jax.jit(chunk, donate_argnums=(0,))


def train_chunk(graphdef, train_cfg: TrainConfig) -> Callable:
    """:func:`make_train_chunk` for ``train_cfg``'s optimizer and ``steps_per_call``.

    Cached (at most 16 entries) on the fields that shape the compiled program, so
    repeated trainings of one architecture (members trained alone, a resume in the
    same process) reuse one compilation.
    """
    return _cached_chunk(
        graphdef,
        train_cfg.optimizer,
        train_cfg.learning_rate,
        train_cfg.adagrad_initial_accumulator,
        train_cfg.steps_per_call,
    )


@functools.lru_cache(maxsize=16)
def _cached_chunk(
    graphdef, optimizer: str, learning_rate: float, initial_accumulator: float, steps: int
) -> Callable:
    cfg = TrainConfig(
        optimizer=optimizer,
        learning_rate=learning_rate,
        adagrad_initial_accumulator=initial_accumulator,
    )
    return make_train_chunk(graphdef, make_optimizer(cfg), steps)
