"""Training the PNet ensemble: every member on its own dataset, in one compiled step.

Modules: :mod:`~ntq_jax.training.config` (:class:`TrainConfig`),
:mod:`~ntq_jax.training.batches` (split by path, epoch schedule,
minibatch indices), :mod:`~ntq_jax.training.step` (pure state and step),
:mod:`~ntq_jax.training.devices` (CPU devices, member mesh),
:mod:`~ntq_jax.training.checkpoint` (orbax checkpoints, saved ensembles),
:mod:`~ntq_jax.training.history` (curves and their files),
:mod:`~ntq_jax.training.loop` (:func:`train_ensemble`, :func:`train_from_folder`).
Measurements: BENCHMARKS.md.
"""

from ntq_jax.training.batches import (
    BatchPlan,
    MemberData,
    Schedule,
    as_arrays,
    infer_path_index,
    prepare_member,
    split_by_path,
)
from ntq_jax.training.checkpoint import CheckpointError, load_ensemble, save_ensemble
from ntq_jax.training.config import TrainConfig
from ntq_jax.training.devices import member_mesh, mesh_size, use_cpu_devices
from ntq_jax.training.history import History, write_history
from ntq_jax.training.loop import train_ensemble, train_from_folder
from ntq_jax.training.step import (
    TrainState,
    make_optimizer,
    make_train_chunk,
    member_step,
    member_val_loss,
)

__all__ = [
    "TrainConfig",
    "train_ensemble",
    "train_from_folder",
    "load_ensemble",
    "save_ensemble",
    "CheckpointError",
    "History",
    "write_history",
    "use_cpu_devices",
    "member_mesh",
    "mesh_size",
    "MemberData",
    "infer_path_index",
    "as_arrays",
    "split_by_path",
    "prepare_member",
    "Schedule",
    "BatchPlan",
    "TrainState",
    "make_optimizer",
    "member_step",
    "member_val_loss",
    "make_train_chunk",
]
