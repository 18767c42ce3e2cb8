"""The training configuration of an ensemble: :class:`TrainConfig` (section ``train`` of a config file)."""

from __future__ import annotations

import dataclasses
from typing import Optional

from ntq_jax.errors import check_config as _check

__all__ = ["TrainConfig"]


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Ensemble training.

    Attributes:
        epochs: passes over each member's dataset.
        batch_size: minibatch size (same for every member).
        optimizer: ``adagrad`` (MPNet's), ``adam`` or ``sgd``.
        adagrad_initial_accumulator: Adagrad's starting accumulator. 0 (PyTorch's
            and so MPNet's default) makes the first update ``lr * sign(grad)`` for
            every weight; 0.1 (optax's and TensorFlow's default) damps the first steps.
        learning_rate: step size.
        val_fraction: held-out fraction of each dataset's paths for validation.
        checkpoint_every: steps between checkpoints.
        eval_every: steps between validation passes (0 = once per epoch of the
            largest dataset).
        steps_per_call: training steps fused into one compiled call (``lax.scan``);
            checkpoints and validation happen between calls.
        keep_checkpoints: how many recent checkpoints to keep.
        seed: the seed of the members' initialisation, minibatch order and dropout
            (``null``, the default: the run's ``seed``). Set it to train again on
            the same data (data and test queries follow the run's ``seed``), e.g. to
            measure the spread over training seeds. Left out of the config hash when
            null.
    """

    epochs: int = 50
    batch_size: int = 100
    optimizer: str = "adagrad"
    learning_rate: float = 0.01
    adagrad_initial_accumulator: float = 0.0
    val_fraction: float = 0.1
    checkpoint_every: int = 500
    eval_every: int = 0
    steps_per_call: int = 20
    keep_checkpoints: int = 2
    seed: Optional[int] = None

    # left out of to_dict (and so of the config hash) when None: configs hash as before
    _OMIT_NONE = ("seed",)

    def seed_for(self, run_seed: int) -> int:
        """The training seed: ``seed``, or the run's seed when null."""
        return run_seed if self.seed is None else self.seed

    def validate(self, p: str):
        _check(self.seed is None or self.seed >= 0, f"{p}.seed", f"must be >= 0, got {self.seed}")
        _check(self.epochs >= 1, f"{p}.epochs", f"must be >= 1, got {self.epochs}")
        _check(self.batch_size >= 1, f"{p}.batch_size", f"must be >= 1, got {self.batch_size}")
        _check(
            self.optimizer in ("adagrad", "adam", "sgd"),
            f"{p}.optimizer",
            f"must be adagrad, adam or sgd; got {self.optimizer!r}",
        )
        _check(
            self.adagrad_initial_accumulator >= 0.0,
            f"{p}.adagrad_initial_accumulator",
            f"must be >= 0, got {self.adagrad_initial_accumulator}",
        )
        _check(
            self.learning_rate > 0, f"{p}.learning_rate", f"must be > 0, got {self.learning_rate}"
        )
        _check(
            0.0 <= self.val_fraction < 1.0,
            f"{p}.val_fraction",
            f"must be in [0, 1), got {self.val_fraction}",
        )
        _check(
            self.checkpoint_every >= 1,
            f"{p}.checkpoint_every",
            f"must be >= 1, got {self.checkpoint_every}",
        )
        _check(self.eval_every >= 0, f"{p}.eval_every", f"must be >= 0, got {self.eval_every}")
        _check(
            self.steps_per_call >= 1,
            f"{p}.steps_per_call",
            f"must be >= 1, got {self.steps_per_call}",
        )
        _check(
            self.keep_checkpoints >= 1,
            f"{p}.keep_checkpoints",
            f"must be >= 1, got {self.keep_checkpoints}",
        )
