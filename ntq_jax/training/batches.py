"""Training data: the split by path, per-member epoch counting, minibatch indices, padding.

Every member trains on its own dataset. :func:`prepare_member` holds out whole
paths for validation (:func:`split_by_path`); :class:`Schedule` counts each
member's epochs on its own (``ceil(n_i / B)`` steps per epoch, the last
minibatch padded and masked); :class:`BatchPlan` draws the minibatch indices
as a deterministic function of ``(seed, member id, global step)``, so a resumed
run sees the same data in the same order. :func:`stack_rows` and
:func:`val_chunks` stack the members' host arrays into the fixed shapes of the
compiled step (member axis first).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple, Sequence

import numpy as np

from ntq_jax import artifacts, batching, data

__all__ = [
    "VAL_CHUNK",
    "MemberData",
    "infer_path_index",
    "as_arrays",
    "split_by_path",
    "prepare_member",
    "Schedule",
    "BatchPlan",
    "stack_rows",
    "val_chunks",
]

VAL_CHUNK = 4096  # validation rows per member per compiled evaluation chunk


class MemberData(NamedTuple):
    """One member's data after the split by path (host NumPy arrays).

    Attributes:
        train_x, train_y: training rows ``(n_train, 2 d)``, ``(n_train, d)``.
        val_x, val_y: validation rows.
        n_train_paths, n_val_paths: paths on each side of the split.
        fingerprint: :func:`ntq_jax.artifacts.array_digest` of the member's full
            data (inputs, targets, path index): resume checks.
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
    cont = np.all(inputs[1:, :d] == targets[:-1], axis=1) & np.all(
        inputs[1:, d:] == inputs[:-1, d:], axis=1
    )
    return np.concatenate([[0], np.cumsum(~cont)]).astype(np.int32)


def as_arrays(ds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(inputs, targets, path_index)`` from a Dataset or an ``(inputs, targets[, path_index])`` tuple.

    Without ``path_index`` the path of every row is inferred (:func:`infer_path_index`).
    """
    if isinstance(ds, data.Dataset):
        x, y, pi = ds.inputs, ds.targets, ds.path_index
    else:
        if not isinstance(ds, (tuple, list)) or len(ds) not in (2, 3):
            raise TypeError(
                "each dataset must be a Dataset or an (inputs, targets[, path_index]) "
                f"tuple, got {type(ds).__name__}"
            )
        x, y = ds[0], ds[1]
        pi = ds[2] if len(ds) == 3 else None
    x = np.asarray(x, np.float32)
    y = np.asarray(y, np.float32)
    if x.ndim != 2 or y.ndim != 2 or x.shape[0] != y.shape[0] or x.shape[1] != 2 * y.shape[1]:
        raise ValueError(
            f"dataset arrays must be inputs (N, 2d) and targets (N, d), got {x.shape} and {y.shape}"
        )
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("dataset contains NaN or infinite values in inputs/targets")
    pi = infer_path_index(x, y) if pi is None else np.asarray(pi, np.int32)
    if pi.shape != (x.shape[0],):
        raise ValueError(f"path_index must have shape ({x.shape[0]},), got {pi.shape}")
    return x, y, pi


def split_by_path(
    path_index: np.ndarray, val_fraction: float, seed: int, member_id: int
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Row indices of the training and validation sides, whole paths on each side.

    ``round(val_fraction * P)`` of the ``P`` paths (at least one when
    ``val_fraction > 0`` and ``P >= 2``; never all) go to validation, drawn by
    ``numpy.random.default_rng([seed, member_id, 2**31 - 1])``.

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
    return MemberData(x[tr], y[tr], x[va], y[va], ntp, nvp, artifacts.array_digest(x, y, pi))


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Per-member epoch counting.

    Member ``i`` has ``ceil(n_i / B)`` steps per epoch and trains for exactly
    ``epochs`` times as many steps; the ensemble runs ``total_steps``, the
    longest member's count, and masks out every member that has finished.

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
            out.append(
                {"steps": done, "epoch": done // s, "batch": done % s, "finished": step >= tot}
            )
        return out

    def epochs_done(self, step: int) -> list[float]:
        """Every member's (fractional) epochs after ``step`` global steps."""
        return [p["steps"] / s for p, s in zip(self.position(step), self.steps_per_epoch)]


class BatchPlan:
    """Host-side minibatch indices: deterministic functions of ``(seed, member id, step)``.

    Member ``m``'s epoch ``e`` visits its rows in the order
    ``numpy.random.default_rng([seed, member_ids[m], e]).permutation(n_m)``.
    """

    def __init__(self, schedule: Schedule, seed: int, member_ids: Sequence[int]):
        self.schedule = schedule
        self.seed = seed
        self.member_ids = list(member_ids)
        self._perm: dict[int, tuple[int, np.ndarray]] = {}  # member -> its current epoch's

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
                rows = self._permutation(m, epoch)[b * bsz : (b + 1) * bsz]
                idx[j, m, : len(rows)] = rows
                mask[j, m, : len(rows)] = 1.0
                active[j, m] = True
        return idx, mask, active


def stack_rows(arrays: Sequence[np.ndarray], rows: int) -> np.ndarray:
    """The members' float32 arrays zero-padded to ``rows`` rows, stacked: ``(M, rows, ...)``."""
    return np.stack([batching.pad_rows(np.asarray(a, np.float32), rows) for a in arrays])


def val_chunks(members: Sequence[MemberData]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validation rows of every member in ``C`` chunks of ``R`` rows (zero-padded, masked).

    Returns:
        ``x (M, C, R, 2d)``, ``y (M, C, R, d)``, ``mask (M, C, R)`` float32, with
        ``R = min(VAL_CHUNK, longest)`` and ``C * R`` covering the longest member.
    """
    vmax = max(1, max(len(md.val_x) for md in members))
    chunk = min(VAL_CHUNK, vmax)
    nch = math.ceil(vmax / chunk)
    rows = nch * chunk
    x = stack_rows([md.val_x for md in members], rows)
    y = stack_rows([md.val_y for md in members], rows)
    mask = np.stack([(np.arange(rows) < len(md.val_x)).astype(np.float32) for md in members])
    num = len(members)
    return (
        x.reshape(num, nch, chunk, -1),
        y.reshape(num, nch, chunk, -1),
        mask.reshape(num, nch, chunk),
    )
