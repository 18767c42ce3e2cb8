"""Training the PNet ensemble: four members, one compiled step, resumable checkpoints.

:func:`train_ensemble` trains ``M`` PNets (one per dataset, D0..D3 in the paper)
together: the parameters and the optax state of all members are stacked on a
leading member axis, and one ``jax.jit``-compiled call runs ``steps_per_call``
steps (``lax.scan``) of ``jax.vmap(member_step)`` over that axis. Every member
draws its minibatches from its own dataset; all members share the batch size,
epochs and optimizer, as in the paper.

**Unequal dataset sizes** (D3, pruned, is smaller): *per-member epoch counting
with masking*. Member ``i`` has ``S_i = ceil(n_i / B)`` steps per epoch and
trains for exactly ``epochs * S_i`` steps, seeing every training row exactly
``epochs`` times (the last minibatch of an epoch is padded and masked). The
compiled step runs ``max_i epochs * S_i`` times; once a member has finished its
epochs its update is masked out (parameters and optimizer state are kept by a
``where``). The alternative, equal steps for all, would give the small dataset
more epochs than the others, i.e. different training parameters, which the
paper holds constant. The cost: member ``j``'s lanes idle (masked) during the
last ``max_i epochs * S_i - epochs * S_j`` steps.

**Randomness** is explicit and keyed by the member's *id*, never by ``M``:
member ``i``'s initial weights come from ``fold_in(fold_in(key(seed), 0), i)``,
its dropout key at global step ``g`` from ``fold_in(fold_in(fold_in(key(seed),
1), i), g)``, its epoch ``e`` shuffle from ``numpy.random.default_rng([seed, i,
e])`` and its validation paths from ``default_rng([seed, i, 2**31 - 1])``.
Hence a member trained alone (``member_ids=[i]``) follows exactly the same
trajectory as inside the ensemble, which the tests check.

**Validation** holds out ``val_fraction`` of each dataset's *paths* (whole
paths, so no training row's path is ever validated on); the validation loss
is the dropout-free loss on all held-out rows, every ``eval_every`` steps.

**Outputs** (when ``ckpt_dir`` is given): ``history.jsonl`` and
``history.csv`` (per member: step, epoch, training loss averaged since the
previous evaluation, validation loss), ``curves.png``, ``checkpoints/<step>/``
(orbax: parameters, optimizer states, step, data-loader position, the resolved
config and the history so far) and, at the end, ``ensemble/`` for
:func:`load_ensemble`. Re-running the same call after an interruption (even
``kill -9``) resumes from the latest complete checkpoint and ends with the same
parameters as an uninterrupted run: the data order and dropout keys depend only
on the seed and the global step.

**Devices.** With ``D >= 2`` devices that can hold equal shares of the ``M``
members (GPUs, or CPU devices from :func:`use_cpu_devices`, the
``jax_num_cpu_devices`` option or ``XLA_FLAGS=--xla_force_host_platform_device_count``)
the member axis of every stacked array is sharded over the largest such ``D``
with a ``NamedSharding`` (``shard=None`` = automatic): 4 members on 4 devices
one each, on 2 devices two each. Otherwise everything runs on one device. On a
CPU, one device per core lets each core run its own members (the training
scripts call :func:`use_cpu_devices`); see BENCHMARKS.md for the measured effect.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import re
import shutil
import sys
import time
from pathlib import Path
from typing import Any, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from ntq_jax import artifacts, models, plotting
from ntq_jax.config import ModelConfig, TrainConfig

Array = jax.Array

VAL_CHUNK = 4096  # validation rows per member per compiled evaluation chunk
FORMAT_VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be used: unreadable, corrupt, or from another run."""


# ---------------------------------------------------------------------------
# Data
# ---------------------------------------------------------------------------

class MemberData(NamedTuple):
    """One member's data after the split by path (host NumPy arrays).

    Attributes:
        train_x, train_y: training rows ``(n_train, 2 d)``, ``(n_train, d)``.
        val_x, val_y: validation rows.
        n_train_paths, n_val_paths: paths on each side of the split.
        fingerprint: a hash of the member's full data (resume checks).
    """

    train_x: np.ndarray
    train_y: np.ndarray
    val_x: np.ndarray
    val_y: np.ndarray
    n_train_paths: int
    n_val_paths: int
    fingerprint: str


def infer_path_index(inputs: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Path ids of rows laid out path after path (MPNet's format), from their chaining.

    Row ``r + 1`` continues row ``r``'s path when its current state is row
    ``r``'s target and both have the same goal.
    """
    inputs, targets = np.asarray(inputs), np.asarray(targets)
    n, d = targets.shape
    if n == 0:
        return np.zeros((0,), np.int32)
    cont = (np.all(inputs[1:, :d] == targets[:-1], axis=1)
            & np.all(inputs[1:, d:] == inputs[:-1, d:], axis=1))
    return np.concatenate([[0], np.cumsum(~cont)]).astype(np.int32)


def as_arrays(ds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(inputs, targets, path_index)`` from a Dataset or an ``(inputs, targets[, path_index])`` tuple.

    Without ``path_index`` the path of every row is inferred (:func:`infer_path_index`).
    """
    if hasattr(ds, "inputs") and hasattr(ds, "targets"):
        x, y = ds.inputs, ds.targets
        pi = getattr(ds, "path_index", None)
    else:
        if not isinstance(ds, (tuple, list)) or len(ds) not in (2, 3):
            raise TypeError("each dataset must be a Dataset or an (inputs, targets[, path_index]) "
                            f"tuple, got {type(ds).__name__}")
        x, y = ds[0], ds[1]
        pi = ds[2] if len(ds) == 3 else None
    x = np.asarray(x, np.float32)
    y = np.asarray(y, np.float32)
    if x.ndim != 2 or y.ndim != 2 or x.shape[0] != y.shape[0] or x.shape[1] != 2 * y.shape[1]:
        raise ValueError(f"dataset arrays must be inputs (N, 2d) and targets (N, d), got "
                         f"{x.shape} and {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("dataset contains NaN or infinite values in inputs/targets")
    pi = infer_path_index(x, y) if pi is None else np.asarray(pi, np.int32)
    if pi.shape != (x.shape[0],):
        raise ValueError(f"path_index must have shape ({x.shape[0]},), got {pi.shape}")
    return x, y, pi


def split_by_path(path_index: np.ndarray, val_fraction: float, seed: int,
                  member_id: int) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Row indices of the training and validation sides, whole paths on each side.

    ``round(val_fraction * P)`` of the ``P`` paths (at least one when
    ``val_fraction > 0`` and ``P >= 2``; never all) go to validation.

    Returns:
        ``(train_rows, val_rows, n_train_paths, n_val_paths)``.
    """
    paths = np.unique(path_index)
    n_val = int(round(val_fraction * len(paths)))
    if val_fraction > 0 and len(paths) >= 2:
        n_val = max(n_val, 1)
    n_val = min(n_val, len(paths) - 1)
    rng = np.random.default_rng([seed, member_id, 2**31 - 1])
    val_paths = rng.choice(paths, size=n_val, replace=False) if n_val > 0 else paths[:0]
    is_val = np.isin(path_index, val_paths)
    return (np.flatnonzero(~is_val), np.flatnonzero(is_val), len(paths) - n_val, n_val)


def prepare_member(ds, val_fraction: float, seed: int, member_id: int) -> MemberData:
    """Splits one dataset by path (see :func:`split_by_path`)."""
    x, y, pi = as_arrays(ds)
    if x.shape[0] == 0:
        raise ValueError(f"dataset of member {member_id} is empty")
    tr, va, ntp, nvp = split_by_path(pi, val_fraction, seed, member_id)
    h = hashlib.sha1()
    for a in (x, y, pi):
        h.update(np.ascontiguousarray(a).tobytes())
    return MemberData(x[tr], y[tr], x[va], y[va], ntp, nvp, h.hexdigest()[:16])


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Per-member epoch counting (see the module docstring).

    Attributes:
        n_train: training rows per member.
        batch_size: rows per minibatch.
        epochs: passes over each member's training rows.
    """

    n_train: tuple[int, ...]
    batch_size: int
    epochs: int

    @property
    def steps_per_epoch(self) -> tuple[int, ...]:
        return tuple(math.ceil(n / self.batch_size) for n in self.n_train)

    @property
    def member_steps(self) -> tuple[int, ...]:
        return tuple(self.epochs * s for s in self.steps_per_epoch)

    @property
    def total_steps(self) -> int:
        return max(self.member_steps)

    def position(self, step: int) -> list[dict]:
        """The data-loader position of every member after ``step`` global steps."""
        out = []
        for s, tot in zip(self.steps_per_epoch, self.member_steps):
            done = min(step, tot)
            out.append({"steps": done, "epoch": done // s, "batch": done % s,
                        "finished": step >= tot})
        return out


class BatchPlan:
    """Host-side minibatch indices: deterministic functions of ``(seed, member id, step)``."""

    def __init__(self, schedule: Schedule, seed: int, member_ids: Sequence[int]):
        self.schedule = schedule
        self.seed = seed
        self.member_ids = list(member_ids)
        self._perm: dict[int, tuple[int, np.ndarray]] = {}

    def _permutation(self, m: int, epoch: int) -> np.ndarray:
        cached = self._perm.get(m)
        if cached is None or cached[0] != epoch:
            rng = np.random.default_rng([self.seed, self.member_ids[m], epoch])
            cached = (epoch, rng.permutation(self.schedule.n_train[m]).astype(np.int32))
            self._perm[m] = cached
        return cached[1]

    def chunk(self, g0: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Indices ``(k, M, B)`` int32, masks ``(k, M, B)`` float32, active ``(k, M)`` bool."""
        sch, bsz, num = self.schedule, self.schedule.batch_size, len(self.member_ids)
        idx = np.zeros((k, num, bsz), np.int32)
        mask = np.zeros((k, num, bsz), np.float32)
        active = np.zeros((k, num), bool)
        for j in range(k):
            g = g0 + j
            for m in range(num):
                if g >= sch.member_steps[m]:
                    continue
                spe = sch.steps_per_epoch[m]
                epoch, b = divmod(g, spe)
                rows = self._permutation(m, epoch)[b * bsz:(b + 1) * bsz]
                idx[j, m, :len(rows)] = rows
                mask[j, m, :len(rows)] = 1.0
                active[j, m] = True
        return idx, mask, active


# ---------------------------------------------------------------------------
# Optimisation (small pure functions)
# ---------------------------------------------------------------------------

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
        return optax.adagrad(lr, initial_accumulator_value=train_cfg.adagrad_initial_accumulator,
                             eps=1e-10)
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
    return (_tree_where(active, new_params, params), _tree_where(active, new_opt, opt_state),
            loss)


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


def make_train_chunk(graphdef, tx, steps: int):
    """A jitted function running ``steps`` ensemble steps (``lax.scan`` of a vmapped step),
    then, if asked, the validation loss (fused: one compilation instead of two).

    Returns:
        ``fn(state, x (M, N, 2d), y (M, N, d), dropout_keys (M,), g0, idx (K, M, B),
        mask (K, M, B), active (K, M), val_x, val_y, val_mask, do_eval) -> (state,
        losses (K, M), val_loss (M,))``; member ``m`` at global step ``g0 + k`` uses the
        dropout key ``fold_in(dropout_keys[m], g0 + k)``; ``val_loss`` is 0 unless
        ``do_eval`` (validation arrays as in :func:`member_val_loss`, with a member axis).
    """
    def one(p, o, x, y, k, i, mk, a):
        return member_step(graphdef, tx, p, o, x, y, k, i, mk, a)

    def vstep(*args):
        if args[-1].shape[0] == 1:  # one member: no vmap (XLA:CPU runs its dots ~1.5x faster)
            squeeze = functools.partial(jax.tree.map, lambda v: v[0])
            return jax.tree.map(lambda v: v[None], one(*squeeze(args)))
        return jax.vmap(one)(*args)

    veval = jax.vmap(lambda p, x, y, mk: member_val_loss(graphdef, p, x, y, mk))

    def chunk(state: TrainState, x, y, dropout_keys, g0, idx, mask, active, val_x, val_y,
              val_mask, do_eval):
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
            body, (state.params, state.opt_state), (jnp.arange(steps), idx, mask, active))
        val = jax.lax.cond(do_eval, lambda p: veval(p, val_x, val_y, val_mask),
                           lambda p: jnp.zeros(val_mask.shape[:1], jnp.float32), params)
        return TrainState(params, opt), losses, val

    return jax.jit(chunk, donate_argnums=(0,))


@functools.lru_cache(maxsize=16)
def _cached_chunk_fn(graphdef, optimizer: str, learning_rate: float, initial_accumulator: float,
                     steps: int):
    cfg = TrainConfig(optimizer=optimizer, learning_rate=learning_rate,
                      adagrad_initial_accumulator=initial_accumulator)
    return make_train_chunk(graphdef, make_optimizer(cfg), steps)


# ---------------------------------------------------------------------------
# Devices
# ---------------------------------------------------------------------------

def use_cpu_devices(count: int | None = None) -> int:
    """Exposes the host's cores as ``count`` JAX CPU devices (call right after ``import jax``).

    On a CPU, :func:`train_ensemble` then shards the member axis over these devices
    (:func:`member_mesh`): each device runs its members on its own core instead of
    every small matmul being split over all cores. Measured on 2 cores
    (``scripts/bench_train.py``, BENCHMARKS.md): 1.17x the steps/s of one
    device at the quick widths (median; 0.98-1.39x per repeat), equal at the
    paper's widths (large matmuls already use both cores). Results differ from a
    one-device run at float level, hence the scripts' default of one device.
    Other computations keep running on device 0 with all cores.

    Nothing is changed when ``XLA_FLAGS`` already forces a host device count, or when
    ``count`` is 1.

    Args:
        count: devices to create; None = ``min(os.cpu_count(), 4)`` (the ensemble's size).

    Returns:
        The number of CPU devices requested (or already forced).

    Raises:
        RuntimeError: JAX has already run a computation in this process (the device
            count is fixed then); call this before any JAX operation.
    """
    forced = re.search(r"--xla_force_host_platform_device_count=(\d+)", os.environ.get("XLA_FLAGS", ""))
    if forced:
        return int(forced.group(1))
    count = min(os.cpu_count() or 1, 4) if count is None else int(count)
    if count < 1:
        raise ValueError(f"use_cpu_devices: count must be >= 1, got {count}")
    if count > 1:
        try:
            jax.config.update("jax_num_cpu_devices", count)
        except RuntimeError as e:
            raise RuntimeError("use_cpu_devices must be called before any JAX operation "
                               f"(right after `import jax`): {e}") from None
    return count


def mesh_size(num_members: int, num_devices: int) -> int:
    """The largest device count ``<= num_devices`` that divides ``num_members`` (>= 1)."""
    return max(d for d in range(1, min(num_devices, num_members) + 1) if num_members % d == 0)


def member_mesh(num_members: int, shard: bool | None = None):
    """A 1-D mesh ``("member",)`` to shard the member axis over, or None to run on one device.

    The mesh has the largest number of devices ``D <= len(jax.devices())`` that
    divides ``M`` (each device then holds ``M / D`` members): 4 members on 4
    devices one each, on 2 devices two each.

    Args:
        num_members: ``M``.
        shard: True requires a mesh of >= 2 devices, False never shards, None shards
            whenever such a mesh exists.
    """
    devices = jax.devices()
    size = mesh_size(num_members, len(devices))
    if shard is False or (shard is None and size < 2):
        return None
    if size < 2:
        raise ValueError(f"shard=True needs >= 2 devices and a member count they divide; "
                         f"found {len(devices)} device(s) for {num_members} members")
    return jax.sharding.Mesh(np.array(devices[:size]), ("member",))


def _place(tree, mesh, axis: int = 0):
    if mesh is None:
        return jax.device_put(tree, jax.devices()[0])
    spec = [None] * axis + ["member"]
    sh = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(*spec))
    return jax.device_put(tree, sh)


# ---------------------------------------------------------------------------
# Checkpoints
# ---------------------------------------------------------------------------

def _flat(tree) -> dict[str, Any]:
    return {jax.tree_util.keystr(p): v for p, v in jax.tree_util.tree_leaves_with_path(tree)}


def _unflat(template, flat: dict[str, Any]):
    paths_leaves, treedef = jax.tree_util.tree_flatten_with_path(template)
    return jax.tree_util.tree_unflatten(
        treedef, [flat[jax.tree_util.keystr(p)] for p, _ in paths_leaves])


def _abstract(tree):
    return jax.tree.map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=a.sharding),
                        tree)


def _manager(path: Path, keep: int, read_only: bool = False):
    import orbax.checkpoint as ocp
    opts = ocp.CheckpointManagerOptions(max_to_keep=keep, enable_async_checkpointing=False,
                                        create=not read_only, read_only=read_only,
                                        cleanup_tmp_directories=not read_only)
    return ocp.CheckpointManager(path.absolute(), options=opts, item_names=("state", "meta"))


def _save_checkpoint(mgr, step: int, state: TrainState, meta: dict):
    import orbax.checkpoint as ocp
    mgr.save(step, args=ocp.args.Composite(state=ocp.args.StandardSave(_flat(state)),
                                           meta=ocp.args.JsonSave(meta)), force=True)
    mgr.wait_until_finished()


def _fingerprint_diff(saved: dict, current: dict, prefix: str = "") -> list[str]:
    """``key: checkpoint has X, this run has Y`` for every differing (nested) key."""
    out = []
    for k in sorted(set(saved) | set(current), key=str):
        a, b = saved.get(k), current.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _fingerprint_diff(a, b, f"{prefix}{k}.")
        elif a != b:
            out.append(f"{prefix}{k}: checkpoint has {a!r}, this run has {b!r}")
    return out


def _restore_checkpoint(mgr, ckpt_root: Path, step: int, template: TrainState,
                        fingerprint: dict) -> tuple[TrainState, dict]:
    import orbax.checkpoint as ocp
    where = ckpt_root / str(step)
    try:
        meta = mgr.restore(step, args=ocp.args.Composite(meta=ocp.args.JsonRestore()))["meta"]
    except Exception as e:  # noqa: BLE001 (any failure here means an unreadable checkpoint)
        raise CheckpointError(
            f"checkpoint {where} is unreadable ({type(e).__name__}: {e}); delete {where} to "
            f"resume from an earlier checkpoint, or the whole {ckpt_root} to start afresh"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_VERSION:
        raise CheckpointError(f"checkpoint {where} has no valid metadata (format "
                              f"{FORMAT_VERSION} expected); delete {ckpt_root} to start afresh")
    diff = _fingerprint_diff(meta.get("fingerprint", {}), fingerprint)
    if diff:
        raise CheckpointError(
            f"checkpoint {where} was written by a different run:\n  " + "\n  ".join(diff)
            + f"\nUse another output folder, or delete {ckpt_root} to start afresh.")
    try:
        flat = mgr.restore(step, args=ocp.args.Composite(
            state=ocp.args.StandardRestore(_abstract(_flat(template)))))["state"]
        state = _unflat(template, flat)
        for a, b in zip(jax.tree.leaves(state), jax.tree.leaves(template)):
            if a.shape != b.shape or a.dtype != b.dtype:
                raise ValueError(f"array {a.shape}/{a.dtype}, expected {b.shape}/{b.dtype}")
            if not bool(jnp.all(jnp.isfinite(a))):
                raise ValueError("non-finite values")
    except CheckpointError:
        raise
    except Exception as e:  # noqa: BLE001
        raise CheckpointError(
            f"checkpoint {where} is corrupt ({type(e).__name__}: {str(e)[:300]}); delete {where} "
            f"to resume from an earlier checkpoint, or {ckpt_root} to start afresh") from None
    return state, meta


def save_ensemble(ens: models.Ensemble, path: str | os.PathLike, extra: dict | None = None):
    """Writes an ensemble for planning: ``ensemble.json`` (spec) and ``params/`` (orbax).

    Written into ``<path>.tmp`` and renamed, so ``path`` is complete or absent.
    """
    import orbax.checkpoint as ocp
    path = Path(path).absolute()
    tmp = path.with_name(path.name + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    params = jax.device_get(ens.params)
    with ocp.StandardCheckpointer() as ckpt:
        ckpt.save(tmp / "params", _flat(params))
        ckpt.wait_until_finished()
    info = {"format": FORMAT_VERSION, "spec": ens.spec.to_json(), "num_members": ens.num_members,
            **(extra or {})}
    (tmp / "ensemble.json").write_text(json.dumps(info, indent=1))
    if path.exists():
        shutil.rmtree(path)
    os.replace(tmp, path)


def load_ensemble(path: str | os.PathLike) -> models.Ensemble:
    """Loads a trained ensemble for planning.

    Args:
        path: a training output folder (holding ``ensemble/``) or an ``ensemble/`` folder.

    Raises:
        CheckpointError: nothing loadable there (with the reason and the fix).
    """
    import orbax.checkpoint as ocp
    path = Path(path).absolute()
    if (path / "ensemble" / "ensemble.json").is_file():
        path = path / "ensemble"
    info_file = path / "ensemble.json"
    if not info_file.is_file():
        if (path / "checkpoints").is_dir():
            raise CheckpointError(f"{path}: training has not finished (no ensemble/ yet); "
                                  "re-run the same training command to resume and finish it")
        raise CheckpointError(f"{path}: no trained ensemble here (expected ensemble.json); pass "
                              "the output folder of scripts/train.py")
    try:
        info = json.loads(info_file.read_text())
        spec = models.ModelSpec.from_json(info["spec"])
        num = int(info["num_members"])
    except Exception as e:  # noqa: BLE001
        raise CheckpointError(f"{info_file} is corrupt ({type(e).__name__}: {e})") from None
    template = models.init_ensemble(spec, 0, num_members=num)
    try:
        with ocp.StandardCheckpointer() as ckpt:
            flat = ckpt.restore(path / "params", _abstract(_flat(template.params)))
        params = _unflat(template.params, flat)
    except Exception as e:  # noqa: BLE001
        raise CheckpointError(f"{path / 'params'} is corrupt or does not match ensemble.json "
                              f"({type(e).__name__}: {str(e)[:300]})") from None
    return models.Ensemble(graphdef=template.graphdef, params=params, spec=spec)


# ---------------------------------------------------------------------------
# History files
# ---------------------------------------------------------------------------

class History(NamedTuple):
    """Training curves, one row per evaluation (NaN where a member had finished).

    Attributes:
        step: ``(T,)`` global steps.
        epoch: ``(T, M)`` each member's epochs done.
        train_loss: ``(T, M)`` mean training minibatch loss since the previous row
            (NaN in the first row, step 0, which holds the untrained validation loss).
        val_loss: ``(T, M)`` validation loss (dropout off); NaN without validation rows
            and once a member has finished.
    """

    step: np.ndarray
    epoch: np.ndarray
    train_loss: np.ndarray
    val_loss: np.ndarray


def _history(records: list[dict], num: int) -> History:
    if not records:
        z = np.zeros((0, num))
        return History(np.zeros((0,), np.int64), z, z.copy(), z.copy())
    f = lambda k: np.array([[np.nan if v is None else v for v in r[k]] for r in records], float)
    return History(np.array([r["step"] for r in records]), f("epoch"), f("train_loss"),
                   f("val_loss"))




def write_history(out: Path, records: list[dict], labels: Sequence[str], png: bool = True):
    """Writes ``history.jsonl``, ``history.csv`` and (``png``) ``curves.png`` into ``out``.

    The figure (matplotlib, Agg backend) costs far more than the text files, so the
    training loop redraws it only at checkpoints and at the end.
    """
    artifacts.write_text(out / "history.jsonl", "".join(json.dumps(r) + "\n" for r in records))
    lines = ["step,member,dataset,epoch,train_loss,val_loss"]
    fmt = lambda v: "" if v is None else format(v, ".8g")
    for r in records:
        for m, lab in enumerate(labels):
            t, v = r["train_loss"][m], r["val_loss"][m]
            if t is None and v is None:
                continue
            lines.append(f"{r['step']},{m},{lab},{r['epoch'][m]:.6g},{fmt(t)},{fmt(v)}")
    artifacts.write_text(out / "history.csv", "\n".join(lines) + "\n")
    if png:
        plotting.curves_figure(_history(records, len(labels)), labels, out / "curves.png")


# ---------------------------------------------------------------------------
# The training loop
# ---------------------------------------------------------------------------

def _pad_stack(arrays: Sequence[np.ndarray], rows: int) -> np.ndarray:
    out = np.zeros((len(arrays), rows) + arrays[0].shape[1:], np.float32)
    for m, a in enumerate(arrays):
        out[m, :len(a)] = a
    return out


def _val_arrays(members: Sequence[MemberData]):
    vmax = max(1, max(len(md.val_x) for md in members))
    chunk = min(VAL_CHUNK, vmax)
    nch = math.ceil(vmax / chunk)
    rows = nch * chunk
    x = _pad_stack([md.val_x for md in members], rows)
    y = _pad_stack([md.val_y for md in members], rows)
    mask = np.zeros((len(members), rows), np.float32)
    for m, md in enumerate(members):
        mask[m, :len(md.val_x)] = 1.0
    num = len(members)
    return (x.reshape(num, nch, chunk, -1), y.reshape(num, nch, chunk, -1),
            mask.reshape(num, nch, chunk))


def train_ensemble(datasets: Sequence[Any], env, model_cfg: ModelConfig, train_cfg: TrainConfig,
                   *, seed: int, ckpt_dir: str | os.PathLike | None = None, progress: bool = True,
                   member_ids: Sequence[int] | None = None, labels: Sequence[str] | None = None,
                   shard: bool | None = None, stop_after: int | None = None,
                   extra_fingerprint: dict | None = None,
                   on_checkpoint: Callable[[int], None] | None = None,
                   resolved_config: dict | None = None,
                   ) -> tuple[models.Ensemble, History]:
    """Trains one PNet per dataset, all members together (see the module docstring).

    Args:
        datasets: ``M`` datasets: :class:`ntq_jax.data.Dataset` objects or
            ``(inputs, targets[, path_index])`` array tuples.
        env: the environment (its robot's bounds normalise the states).
        model_cfg: widths and dropout.
        train_cfg: epochs, batch size, optimizer, validation fraction, checkpointing.
        seed: master seed (weights, dropout, shuffles, validation split).
        ckpt_dir: output folder for checkpoints, curves and the final ``ensemble/``;
            None keeps everything in memory (no resume).
        progress: show a tqdm bar with every member's loss.
        member_ids: ids keying each member's randomness (default ``0..M-1``);
            ``member_ids=[i]`` with ``datasets=[D_i]`` reproduces member ``i`` alone.
        labels: names of the members in logs and files (default ``D<id>``).
        shard: shard the member axis over devices (None = whenever >= 2 devices can
            hold equal shares of the members, see :func:`member_mesh`).
        stop_after: stop (after checkpointing) once this many global steps are done;
            for tests and benchmarks, as an interruption would.
        extra_fingerprint: more values that must match for a resume (e.g. the
            resolved experiment config's hash).
        on_checkpoint: called with the global step after each checkpoint is saved.
        resolved_config: the whole experiment config (a plain dict) to store in every
            checkpoint's metadata (the model and train sections are always stored).

    Returns:
        ``(ensemble, history)``: the trained :class:`ntq_jax.models.Ensemble`
        (parameters on the default device) and the :class:`History`.

    Raises:
        CheckpointError: ``ckpt_dir`` holds a corrupt checkpoint or one from a
            different configuration, dataset or seed.
    """
    if len(datasets) < 1:
        raise ValueError("train_ensemble needs at least one dataset")
    ids = list(range(len(datasets))) if member_ids is None else [int(i) for i in member_ids]
    if len(ids) != len(datasets):
        raise ValueError(f"member_ids has {len(ids)} entries for {len(datasets)} datasets")
    labels = [f"D{i}" for i in ids] if labels is None else list(labels)
    num = len(ids)
    spec = models.ModelSpec.from_env(env, model_cfg)

    members = [prepare_member(ds, train_cfg.val_fraction, seed, i) for ds, i in zip(datasets, ids)]
    for md, lab in zip(members, labels):
        if md.train_x.shape[1] != 2 * spec.dim:
            raise ValueError(f"dataset {lab}: inputs have {md.train_x.shape[1]} columns, the "
                             f"{env.robot.kind} robot needs {2 * spec.dim}")
    schedule = Schedule(tuple(len(md.train_x) for md in members), train_cfg.batch_size,
                        train_cfg.epochs)
    plan = BatchPlan(schedule, seed, ids)
    total = schedule.total_steps
    eval_every = train_cfg.eval_every or max(schedule.steps_per_epoch)
    k_steps = train_cfg.steps_per_call

    # -- model, optimizer, devices -----------------------------------------------
    mesh = member_mesh(num, shard)
    root = jax.random.key(seed)
    ens = models.init_ensemble(spec, jax.random.fold_in(root, 0), member_ids=ids)
    tx = make_optimizer(train_cfg)
    opt_state = jax.vmap(tx.init)(ens.params)
    state = _place(TrainState(ens.params, opt_state), mesh)
    dropout_keys = _place(jnp.stack([jax.random.fold_in(jax.random.fold_in(root, 1), i)
                                     for i in ids]), mesh)
    nmax = max(len(md.train_x) for md in members)
    x_dev = _place(jnp.asarray(_pad_stack([md.train_x for md in members], nmax)), mesh)
    y_dev = _place(jnp.asarray(_pad_stack([md.train_y for md in members], nmax)), mesh)
    vx, vy, vmask = (_place(jnp.asarray(a), mesh) for a in _val_arrays(members))
    has_val = [len(md.val_x) > 0 for md in members]
    chunk_fn = _cached_chunk_fn(ens.graphdef, train_cfg.optimizer, train_cfg.learning_rate,
                                train_cfg.adagrad_initial_accumulator, k_steps)

    fingerprint = {
        "model": dataclasses.asdict(model_cfg) | {"hidden": list(model_cfg.hidden)},
        "train": {k: v for k, v in dataclasses.asdict(train_cfg).items()
                  if k not in ("checkpoint_every", "keep_checkpoints", "eval_every",
                               "steps_per_call")},  # these do not change the result
        "seed": seed, "member_ids": ids, "robot": env.robot.to_json(),
        "spec": spec.to_json(), "data": [md.fingerprint for md in members],
        **(extra_fingerprint or {}),
    }
    fingerprint = json.loads(json.dumps(fingerprint))

    # -- resume --------------------------------------------------------------
    g = 0
    records: list[dict] = []
    out = mgr = None
    if ckpt_dir is not None:
        out = Path(ckpt_dir)
        out.mkdir(parents=True, exist_ok=True)
        ckpt_root = out / "checkpoints"
        if ckpt_root.exists() and not ckpt_root.is_dir():
            raise CheckpointError(f"{ckpt_root} is not a folder; remove it")
        try:
            mgr = _manager(ckpt_root, train_cfg.keep_checkpoints)
        except Exception as e:  # noqa: BLE001
            raise CheckpointError(f"cannot open checkpoints in {ckpt_root} ({type(e).__name__}: "
                                  f"{e}); delete it to start afresh") from None
        latest = mgr.latest_step()
        if latest is not None:
            state, meta = _restore_checkpoint(mgr, ckpt_root, latest, state, fingerprint)
            state = _place(state, mesh)
            g = int(meta["step"])
            if meta.get("position") != json.loads(json.dumps(schedule.position(g))):
                raise CheckpointError(f"checkpoint {ckpt_root / str(latest)}: data-loader "
                                      "position does not match its step; delete it")
            records = list(meta.get("history", []))

    def meta_at(step: int) -> dict:
        return {"format": FORMAT_VERSION, "step": step, "total_steps": total,
                "position": schedule.position(step), "fingerprint": fingerprint,
                "labels": labels, "history": records, "time": time.time(),
                "config": resolved_config or {"model": fingerprint["model"],
                                              "train": dataclasses.asdict(train_cfg)}}

    # -- loop ----------------------------------------------------------------
    bar = None
    if progress and g < total:
        from tqdm.auto import tqdm
        bar = tqdm(total=total, initial=g, desc="train", unit="step", dynamic_ncols=True,
                   file=sys.stderr)
    loss_sum = np.zeros(num)
    loss_cnt = np.zeros(num)
    last_loss = np.full(num, np.nan)  # the bar shows each member's latest chunk loss
    next_eval = (g // eval_every + 1) * eval_every
    next_ckpt = (g // train_cfg.checkpoint_every + 1) * train_cfg.checkpoint_every
    end = total if stop_after is None else min(total, int(stop_after))
    def run_chunk(g0: int, do_eval: bool, train: bool = True):
        idx, mask, active = plan.chunk(g0, k_steps)
        if not train:
            active[:] = False
        st, losses, val = chunk_fn(state, x_dev, y_dev, dropout_keys, jnp.int32(g0),
                                   _place(jnp.asarray(idx), mesh, 1),
                                   _place(jnp.asarray(mask), mesh, 1),
                                   _place(jnp.asarray(active), mesh, 1), vx, vy, vmask,
                                   jnp.bool_(do_eval))
        return st, np.asarray(losses), np.asarray(val), active

    if g == 0 and not records and any(has_val):  # the untrained baseline of the curves
        state, _, val, _ = run_chunk(0, True, train=False)
        records.append({"step": 0, "epoch": [0.0] * num, "train_loss": [None] * num,
                        "val_loss": [float(v) if hv else None for v, hv in zip(val, has_val)]})
    while g < end:
        g_new = min(g + k_steps, total)
        do_eval = g_new >= next_eval or g_new >= total
        state, losses, val, active = run_chunk(g, do_eval)
        loss_sum += np.where(active, losses, 0.0).sum(0)
        loss_cnt += active.sum(0)
        n_act = active.sum(0)
        last_loss = np.where(n_act > 0, np.where(active, losses, 0.0).sum(0) / np.maximum(n_act, 1),
                             last_loss)
        if bar is not None:
            bar.update(g_new - g)
            bar.set_postfix_str(" ".join(f"{lab}={last_loss[m]:.4g}{'' if n_act[m] else '(done)'}"
                                         for m, lab in enumerate(labels)))
        g = g_new
        if do_eval:
            pos = schedule.position(g)
            records.append({
                "step": g,
                "epoch": [p["steps"] / s for p, s in zip(pos, schedule.steps_per_epoch)],
                "train_loss": [float(loss_sum[m] / loss_cnt[m]) if loss_cnt[m] else None
                               for m in range(num)],
                "val_loss": [float(val[m]) if has_val[m] and loss_cnt[m] else None
                             for m in range(num)],
            })
            loss_sum[:] = 0
            loss_cnt[:] = 0
            next_eval = (g // eval_every + 1) * eval_every
            if out is not None:
                write_history(out, records, labels, png=False)
        if mgr is not None and (g >= next_ckpt or g >= end):
            _save_checkpoint(mgr, g, state, meta_at(g))
            write_history(out, records, labels)
            if on_checkpoint is not None:
                on_checkpoint(g)
            next_ckpt = (g // train_cfg.checkpoint_every + 1) * train_cfg.checkpoint_every
    if bar is not None:
        bar.close()

    params = jax.device_put(state.params, jax.devices()[0])
    result = models.Ensemble(graphdef=ens.graphdef, params=params, spec=spec)
    if out is not None:
        if mgr is None or not (out / "curves.png").exists() or not records:
            write_history(out, records, labels)
        if g >= total:
            save_ensemble(result, out / "ensemble",
                          {"labels": labels, "member_ids": ids, "steps": total,
                           "env": getattr(env, "name", None), "fingerprint": fingerprint})
    if mgr is not None:
        mgr.close()
    return result, _history(records, num)


def train_from_folder(env_dir: str | os.PathLike, cfg, out_dir: str | os.PathLike, *,
                      progress: bool = True, shard: bool | None = None):
    """Trains the ensemble on ``<env_dir>/D0..D3`` (written by :mod:`ntq_jax.data`).

    Args:
        env_dir: folder holding ``env.json`` and the dataset folders.
        cfg: the resolved :class:`ntq_jax.config.Config` (model, train, seed).
        out_dir: output folder (checkpoints, curves, ``ensemble/``, ``config.json``).

    Returns:
        ``(ensemble, history)`` of :func:`train_ensemble`.
    """
    from ntq_jax import data as data_mod  # lazy: data.py is another module's concern
    from ntq_jax.envs import make_env

    env_dir = Path(env_dir)
    env = make_env(env_dir / "env.json")
    datasets = data_mod.load_datasets(env_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    artifacts.write_text(out / "config.json", json.dumps(cfg.to_dict(), indent=1))
    return train_ensemble(datasets, env, cfg.model, cfg.train, seed=cfg.seed, ckpt_dir=out,
                          progress=progress, labels=[f"D{i}" for i in range(len(datasets))],
                          shard=shard, resolved_config=cfg.to_dict())
