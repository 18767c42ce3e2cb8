"""The training orchestrator: :func:`train_ensemble` and :func:`train_from_folder`.

:func:`train_ensemble` trains ``M`` PNets (one per dataset, D0..D3 in the
paper) together: parameters and optimizer states are stacked on a member axis
and one compiled call runs ``steps_per_call`` vmapped steps
(:mod:`ntq_jax.training.step`). All members share the batch size, epochs and
optimizer, as in the paper.

**Unequal dataset sizes** (D3, pruned, is smaller): each member counts its own
epochs and trains for exactly ``epochs * ceil(n_i / B)`` steps, seeing every
training row exactly ``epochs`` times (:class:`~ntq_jax.training.batches.Schedule`);
once it has finished, its update is masked out while the larger members go on.
Equal steps for all would give the small dataset more epochs, i.e. different
training parameters, which the paper holds constant.

**Randomness** is keyed by the member's *id*, never by ``M``: member ``i``'s
initial weights come from ``fold_in(fold_in(key(seed), 0), i)``, its dropout
key at global step ``g`` from ``fold_in(fold_in(fold_in(key(seed), 1), i), g)``,
its epoch ``e`` shuffle from ``default_rng([seed, i, e])`` and its validation
paths from ``default_rng([seed, i, 2**31 - 1])``. A member trained alone
(``member_ids=[i]``) follows the same trajectory as inside the ensemble.

**Validation** holds out ``val_fraction`` of each dataset's whole paths; the
validation loss (dropout off) is computed every ``eval_every`` steps.

**Outputs** (with ``ckpt_dir``): ``history.jsonl``, ``history.csv``,
``curves.png`` (:mod:`ntq_jax.training.history`), ``checkpoints/<step>/`` and,
at the end, ``ensemble/`` (:mod:`ntq_jax.training.checkpoint`). Re-running the
same call after an interruption (even ``kill -9``) resumes from the latest
complete checkpoint and ends with the parameters of an uninterrupted run.

**Devices**: the member axis is sharded over the devices that can hold equal
shares of it (:mod:`ntq_jax.training.devices`). Measurements: BENCHMARKS.md.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
from pathlib import Path
from typing import Any, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import artifacts, data, models
from ntq_jax.data.format import DatasetError
from ntq_jax.envs import make_env
from ntq_jax.models import ModelConfig
from ntq_jax.progress import Bar, Progress, open_bar
from ntq_jax.training import devices
from ntq_jax.training.batches import (
    BatchPlan,
    MemberData,
    Schedule,
    prepare_member,
    stack_rows,
    val_chunks,
)
from ntq_jax.training.checkpoint import (
    CheckpointError,
    Checkpoints,
    checkpoint_meta,
    run_fingerprint,
    save_ensemble,
)
from ntq_jax.training.config import TrainConfig
from ntq_jax.training.history import History, LossMeter, write_history
from ntq_jax.training.step import TrainState, make_optimizer, train_chunk

__all__ = ["train_ensemble", "train_from_folder"]


class _Run(NamedTuple):
    """What stays fixed during one training call (host values and placed arrays)."""

    labels: list[str]
    schedule: Schedule
    plan: BatchPlan
    train_cfg: TrainConfig
    eval_every: int
    mesh: Any
    chunk_fn: Callable
    dropout_keys: jax.Array  # (M,)
    x: jax.Array  # (M, N, 2d) training rows, zero-padded
    y: jax.Array
    val: tuple  # val_chunks(), placed
    has_val: list[bool]


# ---------------------------------------------------------------------------
# Setup: members, model and devices
# ---------------------------------------------------------------------------


def _member_ids(num: int, member_ids, labels) -> tuple[list[int], list[str]]:
    if num < 1:
        raise ValueError("train_ensemble needs at least one dataset")
    ids = list(range(num)) if member_ids is None else [int(i) for i in member_ids]
    if len(ids) != num:
        raise ValueError(f"member_ids has {len(ids)} entries for {num} datasets")
    return ids, [f"D{i}" for i in ids] if labels is None else list(labels)


def _prepare_members(datasets, ids, labels, env, spec, train_cfg, seed) -> list[MemberData]:
    members = [prepare_member(ds, train_cfg.val_fraction, seed, i) for ds, i in zip(datasets, ids)]
    for md, lab in zip(members, labels):
        if md.train_x.shape[1] != 2 * spec.dim:
            raise ValueError(
                f"dataset {lab}: inputs have {md.train_x.shape[1]} columns, the "
                f"{env.robot.kind} robot needs {2 * spec.dim}"
            )
    return members


def _setup(members, ids, labels, spec, train_cfg, seed, mesh) -> tuple[_Run, TrainState, Any]:
    """The initial (placed) state, the run's fixed arrays, and the ensemble's graphdef."""
    schedule = Schedule(
        tuple(len(md.train_x) for md in members), train_cfg.batch_size, train_cfg.epochs
    )
    root = jax.random.key(seed)
    ens = models.init_ensemble(spec, jax.random.fold_in(root, 0), member_ids=ids)
    tx = make_optimizer(train_cfg)
    state = devices.place(TrainState(ens.params, jax.vmap(tx.init)(ens.params)), mesh)
    keys = jnp.stack([jax.random.fold_in(jax.random.fold_in(root, 1), i) for i in ids])
    nmax = max(len(md.train_x) for md in members)
    run = _Run(
        labels=labels,
        schedule=schedule,
        plan=BatchPlan(schedule, seed, ids),
        train_cfg=train_cfg,
        eval_every=train_cfg.eval_every or max(schedule.steps_per_epoch),
        mesh=mesh,
        chunk_fn=train_chunk(ens.graphdef, train_cfg),
        dropout_keys=devices.place(keys, mesh),
        x=devices.place(jnp.asarray(stack_rows([md.train_x for md in members], nmax)), mesh),
        y=devices.place(jnp.asarray(stack_rows([md.train_y for md in members], nmax)), mesh),
        val=tuple(devices.place(jnp.asarray(a), mesh) for a in val_chunks(members)),
        has_val=[len(md.val_x) > 0 for md in members],
    )
    return run, state, ens.graphdef


def _resume(
    ckpts: Checkpoints | None, run: _Run, state: TrainState, fingerprint: dict
) -> tuple[TrainState, int, list[dict]]:
    """``(state, step, records)`` of the latest checkpoint, or the initial ones."""
    latest = None if ckpts is None else ckpts.latest_step()
    if latest is None:
        return state, 0, []
    state, meta = ckpts.restore(latest, state, fingerprint)
    g = int(meta["step"])
    if meta.get("position") != json.loads(json.dumps(run.schedule.position(g))):
        raise CheckpointError(
            f"checkpoint {ckpts.root / str(latest)}: data-loader "
            "position does not match its step; delete it"
        )
    return devices.place(state, run.mesh), g, list(meta.get("history", []))


# ---------------------------------------------------------------------------
# The loop
# ---------------------------------------------------------------------------


def _run_chunk(run: _Run, state: TrainState, g0: int, do_eval: bool, train: bool = True):
    """One compiled call from global step ``g0``: ``(state, losses, val, active)``."""
    k = run.train_cfg.steps_per_call
    idx, mask, active = run.plan.chunk(g0, k)
    if not train:
        active[:] = False
    batch = (devices.place(jnp.asarray(a), run.mesh, 1) for a in (idx, mask, active))
    st, losses, val = run.chunk_fn(
        state, run.x, run.y, run.dropout_keys, jnp.int32(g0), *batch, *run.val, jnp.bool_(do_eval)
    )
    return st, np.asarray(losses), np.asarray(val), active


def _baseline(run: _Run, state: TrainState) -> tuple[TrainState, dict]:
    """The untrained validation loss: the curves' first record (step 0)."""
    state, _, val, _ = _run_chunk(run, state, 0, True, train=False)
    num = len(run.labels)
    return state, {
        "step": 0,
        "epoch": [0.0] * num,
        "train_loss": [None] * num,
        "val_loss": [float(v) if hv else None for v, hv in zip(val, run.has_val)],
    }


def _next(g: int, every: int) -> int:
    return (g // every + 1) * every


def _train_loop(
    run: _Run,
    state: TrainState,
    g: int,
    end: int,
    records: list[dict],
    bar: Bar,
    out: Path | None,
    ckpts: Checkpoints | None,
    meta: Callable[[int], dict],
    on_checkpoint: Callable[[int], None] | None,
) -> tuple[TrainState, int]:
    """Steps from ``g`` to ``end``; evaluates, records and checkpoints on the way."""
    total, every_ckpt = run.schedule.total_steps, run.train_cfg.checkpoint_every
    meter = LossMeter(len(run.labels))
    next_eval, next_ckpt = _next(g, run.eval_every), _next(g, every_ckpt)
    while g < end:
        g_new = min(g + run.train_cfg.steps_per_call, total)
        do_eval = g_new >= next_eval or g_new >= total
        state, losses, val, active = _run_chunk(run, state, g, do_eval)
        meter.add(losses, active)
        bar.update(g_new - g)
        bar.set_postfix_str(meter.postfix(run.labels))
        g = g_new
        if do_eval:
            records.append(meter.record(g, run.schedule.epochs_done(g), val, run.has_val))
            next_eval = _next(g, run.eval_every)
            if out is not None:
                write_history(out, records, run.labels, png=False)
        if ckpts is not None and (g >= next_ckpt or g >= end):
            ckpts.save(g, state, meta(g))
            write_history(out, records, run.labels)
            if on_checkpoint is not None:
                on_checkpoint(g)
            next_ckpt = _next(g, every_ckpt)
    return state, g


def _write_outputs(
    out: Path,
    ens: models.Ensemble,
    records: list[dict],
    labels: list[str],
    finished: bool,
    info: dict,
) -> None:
    """The final curves (unless a checkpoint drew them) and, when finished, ``ensemble/``."""
    if not (out / "curves.png").exists() or not records:
        write_history(out, records, labels)
    if finished:
        save_ensemble(ens, out / "ensemble", info)


# ---------------------------------------------------------------------------
# Entry points
# ---------------------------------------------------------------------------


def train_ensemble(
    datasets: Sequence[Any],
    env,
    model_cfg: ModelConfig,
    train_cfg: TrainConfig,
    *,
    seed: int,
    ckpt_dir: str | os.PathLike | None = None,
    progress: Progress = True,
    member_ids: Sequence[int] | None = None,
    labels: Sequence[str] | None = None,
    shard: bool | None = None,
    stop_after: int | None = None,
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
        progress: the progress bar (:func:`ntq_jax.progress.open_bar`: False/None
            silent, True tqdm, or a factory); it shows every member's loss.
        member_ids: ids keying each member's randomness (default ``0..M-1``);
            ``member_ids=[i]`` with ``datasets=[D_i]`` reproduces member ``i`` alone.
        labels: names of the members in logs and files (default ``D<id>``).
        shard: shard the member axis over devices (None = whenever >= 2 devices can
            hold equal shares of the members, see :func:`~ntq_jax.training.member_mesh`).
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
    # -- members ---------------------------------------------------------------
    ids, labels = _member_ids(len(datasets), member_ids, labels)
    spec = models.ModelSpec.from_env(env, model_cfg)
    members = _prepare_members(datasets, ids, labels, env, spec, train_cfg, seed)

    # -- model, optimizer, devices ---------------------------------------------
    run, state, graphdef = _setup(
        members, ids, labels, spec, train_cfg, seed, devices.member_mesh(len(ids), shard)
    )
    fingerprint = run_fingerprint(
        model_cfg,
        train_cfg,
        seed=seed,
        member_ids=ids,
        env=env,
        spec=spec,
        data=[md.fingerprint for md in members],
        extra=extra_fingerprint,
    )
    config = resolved_config or {
        "model": fingerprint["model"],
        "train": dataclasses.asdict(train_cfg),
    }

    # -- resume ----------------------------------------------------------------
    out = None if ckpt_dir is None else Path(ckpt_dir)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    ckpts = None if out is None else Checkpoints(out, train_cfg.keep_checkpoints)
    try:
        state, g, records = _resume(ckpts, run, state, fingerprint)
        meta = functools.partial(
            checkpoint_meta,
            schedule=run.schedule,
            fingerprint=fingerprint,
            labels=labels,
            records=records,
            config=config,
        )

        # -- train -------------------------------------------------------------
        total = run.schedule.total_steps
        end = total if stop_after is None else min(total, int(stop_after))
        if g == 0 and not records and any(run.has_val):
            state, first = _baseline(run, state)
            records.append(first)
        with open_bar(
            progress if g < total else None, desc="train", total=total, unit="step", initial=g
        ) as bar:
            state, g = _train_loop(
                run, state, g, end, records, bar, out, ckpts, meta, on_checkpoint
            )

        # -- outputs -----------------------------------------------------------
        params = jax.device_put(state.params, jax.devices()[0])
        result = models.Ensemble(graphdef=graphdef, params=params, spec=spec)
        if out is not None:
            _write_outputs(
                out,
                result,
                records,
                labels,
                finished=g >= total,
                info={
                    "labels": labels,
                    "member_ids": ids,
                    "steps": total,
                    "env": env.name,
                    "fingerprint": fingerprint,
                },
            )
    finally:
        if ckpts is not None:
            ckpts.close()
    return result, History.from_records(records, len(ids))


def train_from_folder(
    env_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    model: ModelConfig | None = None,
    train: TrainConfig | None = None,
    seed: int = 0,
    progress: Progress = True,
    shard: bool | None = None,
    record: dict | None = None,
):
    """Trains the ensemble on ``<env_dir>/D0..D3`` (written by :mod:`ntq_jax.data`).

    Args:
        env_dir: folder holding ``env.json`` and the dataset folders.
        out_dir: output folder (checkpoints, curves, ``ensemble/``, ``config.json``).
        model: the PNets' widths and dropout (None: :class:`~ntq_jax.models.ModelConfig`'s
            defaults, the paper's).
        train: epochs, batch size, optimizer, ... (None: :class:`TrainConfig`'s defaults).
        seed: the run's seed; training uses ``train.seed`` when set
            (:meth:`TrainConfig.seed_for`).
        record: what ``config.json`` and every checkpoint's metadata record (a plain
            dict; None: the model and train settings and the seed). The experiment
            layer passes its whole resolved config.

    Returns:
        ``(ensemble, history)`` of :func:`train_ensemble`.
    """
    model = ModelConfig() if model is None else model
    train = TrainConfig() if train is None else train
    env_dir = Path(env_dir)
    env = make_env(env_dir / "env.json")
    datasets = data.load_datasets(env_dir)
    for i, ds in enumerate(datasets):
        if len(ds.inputs) == 0:  # one line with the generator's reason, before any training
            why = next(
                (w for w in ds.meta.get("warnings", []) if "no samples" in w),
                f"{env_dir} D{i} has no samples",
            )
            raise DatasetError(
                f"{why}. PNet_{i} cannot be trained on an empty dataset: drop "
                f"D{i} from data.datasets (or use a map where it has samples)"
            )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if record is None:
        record = json.loads(
            json.dumps(
                {
                    "model": dataclasses.asdict(model),
                    "train": dataclasses.asdict(train),
                    "seed": seed,
                }
            )
        )
    artifacts.write_text(out / "config.json", json.dumps(record, indent=1))
    return train_ensemble(
        datasets,
        env,
        model,
        train,
        seed=train.seed_for(seed),
        ckpt_dir=out,
        progress=progress,
        labels=[f"D{i}" for i in range(len(datasets))],
        shard=shard,
        resolved_config=record,
    )
