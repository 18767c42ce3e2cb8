"""Training checkpoints and saved ensembles (orbax), refused when they belong to another run.

A training run's ``<out>/checkpoints/<step>/`` (:class:`Checkpoints`) holds the
stacked :class:`~ntq_jax.training.step.TrainState` (``state``) and a JSON
``meta``: format, step, data-loader position, the run's fingerprint
(:func:`run_fingerprint`: every input that changes the result), the resolved
config and the history so far. A checkpoint is restored only when its
fingerprint equals the current run's; otherwise, or when it is unreadable or
corrupt, :class:`CheckpointError` says why and what to delete.
:func:`save_ensemble` / :func:`load_ensemble` write and read the final
``ensemble/`` (``ensemble.json`` + ``params/``) used for planning.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Any, Sequence

import jax
import jax.numpy as jnp

from ntq_jax import artifacts, models
from ntq_jax.models import ModelConfig
from ntq_jax.training.batches import Schedule
from ntq_jax.training.config import TrainConfig
from ntq_jax.training.step import TrainState

__all__ = [
    "FORMAT_VERSION",
    "CheckpointError",
    "run_fingerprint",
    "checkpoint_meta",
    "Checkpoints",
    "save_ensemble",
    "load_ensemble",
]

FORMAT_VERSION = 1
# TrainConfig fields that do not change the trained parameters (not in the fingerprint)
RESULT_NEUTRAL = ("checkpoint_every", "keep_checkpoints", "eval_every", "steps_per_call")


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be used: unreadable, corrupt, or from another run."""


def run_fingerprint(
    model_cfg: ModelConfig,
    train_cfg: TrainConfig,
    *,
    seed: int,
    member_ids: Sequence[int],
    env,
    spec: models.ModelSpec,
    data: Sequence[str],
    extra: dict | None = None,
) -> dict:
    """Everything a resumed run must share with the checkpoint, as plain JSON values.

    ``data`` are the members' data digests (:attr:`MemberData.fingerprint`);
    ``extra`` adds caller values (e.g. the experiment config's hash).
    """
    fingerprint = {
        "model": dataclasses.asdict(model_cfg) | {"hidden": list(model_cfg.hidden)},
        "train": {
            k: v for k, v in dataclasses.asdict(train_cfg).items() if k not in RESULT_NEUTRAL
        },
        "seed": seed,
        "member_ids": list(member_ids),
        "robot": env.robot.to_json(),
        "spec": spec.to_json(),
        "data": list(data),
        **(extra or {}),
    }
    return json.loads(json.dumps(fingerprint))


def checkpoint_meta(
    step: int,
    schedule: Schedule,
    fingerprint: dict,
    labels: Sequence[str],
    records: list[dict],
    config: dict,
) -> dict:
    """The ``meta`` item of the checkpoint at global ``step``."""
    return {
        "format": FORMAT_VERSION,
        "step": step,
        "total_steps": schedule.total_steps,
        "position": schedule.position(step),
        "fingerprint": fingerprint,
        "labels": list(labels),
        "history": records,
        "time": time.time(),
        "config": config,
    }


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


# -- pytree <-> flat dict (orbax stores a flat mapping of key paths) -------------------


def _flat(tree) -> dict[str, Any]:
    return {jax.tree_util.keystr(p): v for p, v in jax.tree_util.tree_leaves_with_path(tree)}


def _unflat(template, flat: dict[str, Any]):
    paths_leaves, treedef = jax.tree_util.tree_flatten_with_path(template)
    return jax.tree_util.tree_unflatten(
        treedef, [flat[jax.tree_util.keystr(p)] for p, _ in paths_leaves]
    )


def _abstract(tree):
    return jax.tree.map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=a.sharding), tree)


def _check_like(state, template) -> None:
    for a, b in zip(jax.tree.leaves(state), jax.tree.leaves(template)):
        if a.shape != b.shape or a.dtype != b.dtype:
            raise ValueError(f"array {a.shape}/{a.dtype}, expected {b.shape}/{b.dtype}")
        if not bool(jnp.all(jnp.isfinite(a))):
            raise ValueError("non-finite values")


class Checkpoints:
    """The orbax checkpoints of one training run, in ``<out>/checkpoints/<step>/``.

    Saves are synchronous (a checkpoint is complete when :meth:`save` returns);
    the newest ``keep`` are kept.

    Raises:
        CheckpointError: the folder cannot be opened as a checkpoint folder.
    """

    def __init__(self, out: Path, keep: int):
        import orbax.checkpoint as ocp  # heavy: only when checkpointing

        self.root = Path(out) / "checkpoints"
        if self.root.exists() and not self.root.is_dir():
            raise CheckpointError(f"{self.root} is not a folder; remove it")
        opts = ocp.CheckpointManagerOptions(
            max_to_keep=keep,
            enable_async_checkpointing=False,
            create=True,
            read_only=False,
            cleanup_tmp_directories=True,
        )
        try:
            self.manager = ocp.CheckpointManager(
                self.root.absolute(), options=opts, item_names=("state", "meta")
            )
        except Exception as e:  # noqa: BLE001
            raise CheckpointError(
                f"cannot open checkpoints in {self.root} ({type(e).__name__}: "
                f"{e}); delete it to start afresh"
            ) from None

    def latest_step(self) -> int | None:
        return self.manager.latest_step()

    def save(self, step: int, state: TrainState, meta: dict) -> None:
        import orbax.checkpoint as ocp

        self.manager.save(
            step,
            args=ocp.args.Composite(
                state=ocp.args.StandardSave(_flat(state)), meta=ocp.args.JsonSave(meta)
            ),
            force=True,
        )
        self.manager.wait_until_finished()

    def restore(
        self, step: int, template: TrainState, fingerprint: dict
    ) -> tuple[TrainState, dict]:
        """The state and meta of checkpoint ``step``, after checking its fingerprint.

        Raises:
            CheckpointError: unreadable, from a different run, or corrupt.
        """
        meta = self._restore_meta(step)
        where = self.root / str(step)
        diff = _fingerprint_diff(meta.get("fingerprint", {}), fingerprint)
        if diff:
            raise CheckpointError(
                f"checkpoint {where} was written by a different run:\n  "
                + "\n  ".join(diff)
                + f"\nUse another output folder, or delete {self.root} to start afresh."
            )
        import orbax.checkpoint as ocp

        try:
            flat = self.manager.restore(
                step,
                args=ocp.args.Composite(state=ocp.args.StandardRestore(_abstract(_flat(template)))),
            )["state"]
            state = _unflat(template, flat)
            _check_like(state, template)
        except Exception as e:  # noqa: BLE001
            raise CheckpointError(
                f"checkpoint {where} is corrupt ({type(e).__name__}: {str(e)[:300]}); delete "
                f"{where} to resume from an earlier checkpoint, or {self.root} to start afresh"
            ) from None
        return state, meta

    def _restore_meta(self, step: int) -> dict:
        import orbax.checkpoint as ocp

        where = self.root / str(step)
        try:
            meta = self.manager.restore(step, args=ocp.args.Composite(meta=ocp.args.JsonRestore()))[
                "meta"
            ]
        except Exception as e:  # noqa: BLE001 (any failure here means an unreadable checkpoint)
            raise CheckpointError(
                f"checkpoint {where} is unreadable ({type(e).__name__}: {e}); delete {where} to "
                f"resume from an earlier checkpoint, or the whole {self.root} to start afresh"
            ) from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT_VERSION:
            raise CheckpointError(
                f"checkpoint {where} has no valid metadata (format "
                f"{FORMAT_VERSION} expected); delete {self.root} to start afresh"
            )
        return meta

    def close(self) -> None:
        self.manager.close()


# -- the trained ensemble ---------------------------------------------------------------


def save_ensemble(ens: models.Ensemble, path: str | os.PathLike, extra: dict | None = None):
    """Writes an ensemble for planning: ``ensemble.json`` (spec) and ``params/`` (orbax).

    Written atomically (:func:`ntq_jax.artifacts.write_folder`): ``path`` is complete or absent.
    """
    import orbax.checkpoint as ocp

    params = jax.device_get(ens.params)
    info = {
        "format": FORMAT_VERSION,
        "spec": ens.spec.to_json(),
        "num_members": ens.num_members,
        **(extra or {}),
    }

    def fill(tmp: Path) -> None:
        with ocp.StandardCheckpointer() as ckpt:
            ckpt.save(tmp / "params", _flat(params))
            ckpt.wait_until_finished()
        artifacts.write_json(tmp / "ensemble.json", info)

    return artifacts.write_folder(path, fill)


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
            raise CheckpointError(
                f"{path}: training has not finished (no ensemble/ yet); "
                "re-run the same training command to resume and finish it"
            )
        raise CheckpointError(
            f"{path}: no trained ensemble here (expected ensemble.json); pass "
            "the output folder of scripts/train.py"
        )
    fix = (
        f"delete {path} and rerun the training command (scripts/train.py or "
        "scripts/train_all.py) to write it again from the last checkpoint"
    )
    try:
        info = json.loads(info_file.read_text())
        spec = models.ModelSpec.from_json(info["spec"])
        num = int(info["num_members"])
    except Exception as e:  # noqa: BLE001
        raise CheckpointError(f"{info_file} is corrupt ({type(e).__name__}: {e}); {fix}") from None
    template = models.init_ensemble(spec, 0, num_members=num)
    try:
        with ocp.StandardCheckpointer() as ckpt:
            flat = ckpt.restore(path / "params", _abstract(_flat(template.params)))
        params = _unflat(template.params, flat)
    except Exception as e:  # noqa: BLE001
        raise CheckpointError(
            f"{path / 'params'} is corrupt or does not match ensemble.json "
            f"({type(e).__name__}: {str(e)[:300]}); {fix}"
        ) from None
    return models.Ensemble(graphdef=template.graphdef, params=params, spec=spec)
