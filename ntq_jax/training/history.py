"""Training curves: the per-evaluation records, their files, and the loss accumulator.

A training run keeps a list of records, one per evaluation: ``{"step",
"epoch": [M], "train_loss": [M], "val_loss": [M]}`` (None where a member has
no value). The list goes into every checkpoint (so a resumed run continues it),
into ``history.jsonl`` / ``history.csv`` and ``curves.png``
(:func:`write_history`, the figure through :func:`ntq_jax.plotting.curves_figure`),
and is returned as a :class:`History` of arrays.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from ntq_jax import artifacts, plotting

__all__ = ["History", "write_history", "LossMeter"]


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

    @classmethod
    def from_records(cls, records: list[dict], num: int) -> "History":
        """The arrays of ``records`` (``num`` members; None -> NaN)."""
        if not records:
            z = np.zeros((0, num))
            return cls(np.zeros((0,), np.int64), z, z.copy(), z.copy())
        f = lambda k: np.array([[np.nan if v is None else v for v in r[k]] for r in records], float)
        return cls(
            np.array([r["step"] for r in records]), f("epoch"), f("train_loss"), f("val_loss")
        )


def write_history(out: Path, records: list[dict], labels: Sequence[str], png: bool = True):
    """Writes ``history.jsonl``, ``history.csv`` and (``png``) ``curves.png`` into ``out``.

    The figure costs far more than the text files, so the training loop redraws
    it only at checkpoints and at the end.
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
        plotting.curves_figure(
            History.from_records(records, len(labels)), labels, out / "curves.png"
        )


class LossMeter:
    """Accumulates each member's training losses between two evaluations.

    :meth:`add` takes a chunk's ``(K, M)`` losses and active flags; :meth:`record`
    turns the sums into a history record and starts over; :meth:`postfix` is the
    progress bar's text (every member's latest chunk loss).
    """

    def __init__(self, num: int):
        self.total = np.zeros(num)
        self.count = np.zeros(num)
        self.last = np.full(num, np.nan)
        self.active = np.zeros(num)  # active steps of each member in the latest chunk

    def add(self, losses: np.ndarray, active: np.ndarray) -> None:
        summed = np.where(active, losses, 0.0).sum(0)
        self.total += summed
        self.count += active.sum(0)
        self.active = active.sum(0)
        self.last = np.where(self.active > 0, summed / np.maximum(self.active, 1), self.last)

    def postfix(self, labels: Sequence[str]) -> str:
        return " ".join(
            f"{lab}={self.last[m]:.4g}{'' if self.active[m] else '(done)'}"
            for m, lab in enumerate(labels)
        )

    def record(
        self, step: int, epochs: Sequence[float], val: np.ndarray, has_val: Sequence[bool]
    ) -> dict:
        """The record at ``step`` (val_loss None for members without validation rows or
        without training steps since the previous record); resets the sums."""
        num = len(self.total)
        rec = {
            "step": step,
            "epoch": list(epochs),
            "train_loss": [
                float(self.total[m] / self.count[m]) if self.count[m] else None for m in range(num)
            ],
            "val_loss": [
                float(val[m]) if has_val[m] and self.count[m] else None for m in range(num)
            ],
        }
        self.total[:] = 0
        self.count[:] = 0
        return rec
