"""Neural replanning on the host, and the per-query state of a batch (:mod:`ntq_jax.neural.driver`).

:func:`repair_windows` gives the windows one replanning round reconnects in a path and
:func:`splice` puts a connection in place of its window. The stages here run the jitted
steps (:mod:`ntq_jax.neural.steps`) over chunks of a batch (its paths, lengths and
outcomes: host arrays updated stage by stage): the contraction and feasibility check of
its paths, and one round of neural replanning (step 4 of
:func:`ntq_jax.neural.driver.plan_batch`).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ntq_jax.batching import group_chunks, padded_chunks
from ntq_jax.neural.proposals import fold_in
from ntq_jax.neural.steps import CHECK_ROWS, Stages
from ntq_jax.types import PlanCause

# ---------------------------------------------------------------------------
# Host side: windows, splices and the per-query state of a batch
# ---------------------------------------------------------------------------


def repair_windows(blocked: np.ndarray, ok: np.ndarray, n: int) -> list[tuple[int, int]]:
    """The windows ``(ia, ib)`` one replanning round reconnects in a path, last first.

    Take the last blocked segment ``(k, k+1)`` not yet covered, widen it to the
    nearest states not in collision (``ia <= k`` and ``ib > k``; the start and
    the goal are always valid), and continue left of ``min(ia, k)``. Windows never
    overlap (neighbours may share an end state), so splicing them right to left
    never moves a window still to splice, and all of them can be connected at once.

    Args:
        blocked: ``(L-1,)`` blocked segments of the path.
        ok: ``(L,)`` validity of its states (False beyond its end).
        n: its length.
    """
    length = ok.shape[0]
    segs = np.flatnonzero(blocked[: max(n - 1, 0)])
    good = np.flatnonzero(ok[:n])
    out, cursor = [], length
    for k in segs[::-1]:
        if k >= cursor:
            continue
        left = good[good <= k]
        right = good[good > k]
        ia = int(left[-1]) if len(left) else 0
        ib = min(int(right[0]) if len(right) else length, n - 1)
        out.append((ia, ib))
        cursor = min(ia, int(k))
    return out


def splice(path: np.ndarray, n: int, ia: int, ib: int, sub: np.ndarray):
    """``path[:ia] + sub + path[ib+1:n]`` NaN-padded to ``len(path)`` rows, and its length.

    The states ``ia..ib`` of the first ``n`` are replaced by ``sub`` (which runs
    from ``path[ia]`` to ``path[ib]``). Returns ``(new_path, new_length)``, or
    None when the result would not fit in ``len(path)`` rows.
    """
    nn = n - (ib - ia + 1) + len(sub)
    if nn > path.shape[0]:
        return None
    out = np.full_like(path, np.nan)
    out[:ia] = path[:ia]
    out[ia : ia + len(sub)] = sub
    out[ia + len(sub) : nn] = path[ib + 1 : n]
    return out, nn


@dataclasses.dataclass
class _Batch:
    """The per-query state of a :func:`plan_batch` call (host arrays, updated stage by stage).

    With several members (:func:`plan_members`) the rows are ``members`` blocks of
    the same ``K`` queries, one block per member.
    """

    paths: np.ndarray  # (K, L, d) float32, NaN padded
    lengths: np.ndarray  # (K,) int32
    valid: np.ndarray  # (K,) bool: start and goal valid on the evaluation geometry
    reached: np.ndarray  # (K,) bool: the coarse plan reached the goal
    feasible: np.ndarray  # (K,) bool: every segment free on the evaluation geometry
    blocked: np.ndarray  # (K, L-1) bool: segments in collision
    calls: np.ndarray  # (K,) int32 PNet predictions
    replans: np.ndarray  # (K,) int32 replanning rounds
    members: int = 1  # planners side by side: rows m*K/M.. (m+1)*K/M-1 are member m's

    @staticmethod
    def empty(k: int, length: int, d: int, members: int = 1) -> "_Batch":
        return _Batch(
            np.full((k, length, d), np.nan, np.float32),
            np.zeros(k, np.int32),
            np.zeros(k, bool),
            np.zeros(k, bool),
            np.zeros(k, bool),
            np.zeros((k, length - 1), bool),
            np.zeros(k, np.int32),
            np.zeros(k, np.int32),
            members,
        )

    def cause(self) -> np.ndarray:
        """``(K,)`` int8 :class:`PlanCause` of every query."""
        success = self.reached & self.feasible
        return np.where(
            ~self.valid,
            PlanCause.INVALID_QUERY,
            np.where(
                ~self.reached,
                PlanCause.NO_PATH,
                np.where(success, PlanCause.SUCCESS, PlanCause.INFEASIBLE),
            ),
        ).astype(np.int8)


# ---------------------------------------------------------------------------
# The stages of plan_batch: contraction, feasibility check, neural replanning
# ---------------------------------------------------------------------------


def _member_rows(b: _Batch, rows: np.ndarray) -> list[np.ndarray]:
    """Positions in ``rows`` (batch rows) of each member's rows, in order (one group per member)."""
    k = b.paths.shape[0] // b.members
    who = np.asarray(rows) // k
    return [np.flatnonzero(who == m) for m in range(b.members)]


def _window_validity(stages: Stages, b: _Batch, todo: np.ndarray, width: int) -> np.ndarray:
    """``(len(todo), L)`` validity of the states of the paths ``todo``."""
    ok = np.zeros((len(todo), b.paths.shape[1]), bool)
    for lo, m, (sel,), _ in padded_chunks([np.arange(len(todo))], width):
        (o,) = stages("valid", jnp.asarray(b.paths[todo[sel]]), jnp.asarray(b.lengths[todo[sel]]))
        ok[lo : lo + m] = o[:m]
    return ok


def _reconnect(stages: Stages, b: _Batch, rows, wa, wb, key, width: int):
    """Neural connections of the windows ``paths[rows, wa] -> paths[rows, wb]``.

    Each member's windows are connected by its own PNet, ``width`` of each per call.
    Returns ``(sub, ns, connected)``; the PNet calls are added to ``b.calls``.
    """
    d = b.paths.shape[2]
    sub = np.zeros((len(rows), stages.opts.replan_steps + 2, d), np.float32)
    ns = np.zeros(len(rows), np.int64)
    conn = np.zeros(len(rows), bool)
    a, z = b.paths[rows, wa], b.paths[rows, wb]
    for lo, sel, mask in group_chunks(_member_rows(b, rows), width):
        o = stages(
            "connect",
            stages.pnet,
            fold_in(key, lo // width),
            jnp.asarray(a[sel]),
            jnp.asarray(z[sel]),
            jnp.asarray(mask),
        )
        part = sel[mask]
        sub[part], ns[part], conn[part] = o[0][mask], o[1][mask], o[2][mask]
        np.add.at(b.calls, rows[part], o[3][mask])
    return sub, ns, conn


def _recheck(stages: Stages, b: _Batch, todo: np.ndarray) -> None:
    """Contraction and feasibility check of the paths ``todo`` (:data:`CHECK_ROWS` per call)."""
    for lo, m, (sel,), mask in padded_chunks([np.arange(len(todo))], CHECK_ROWS):
        o = stages(
            "check",
            jnp.asarray(b.paths[todo[sel]]),
            jnp.asarray(b.lengths[todo[sel]]),
            jnp.asarray(mask),
        )
        idx = todo[lo : lo + m]
        b.paths[idx], b.lengths[idx], b.feasible[idx], b.blocked[idx] = (x[:m] for x in o)


def _replan_round(stages: Stages, b: _Batch, todo: np.ndarray, key, width: int) -> None:
    """Step 4, one round on the infeasible paths ``todo``.

    The windows of every blocked segment of every path in ``todo``
    (:func:`repair_windows`) are reconnected in one batch of neural connections
    (chunks of ``width``), spliced in right to left (:func:`splice`; a splice that
    would overflow the path buffer is skipped), and the paths contracted and
    checked again.
    """
    ok = _window_validity(stages, b, todo, width)
    wins = [
        (i, ia, ib)
        for j, i in enumerate(todo)
        for ia, ib in repair_windows(b.blocked[i], ok[j], int(b.lengths[i]))
    ]
    rows, wa, wb = np.array(wins, np.int64).reshape(-1, 3).T
    sub, ns, conn = _reconnect(stages, b, rows, wa, wb, key, width)
    for w in np.flatnonzero(conn):  # each path's windows are listed last first
        i = rows[w]
        out = splice(b.paths[i], int(b.lengths[i]), wa[w], wb[w], sub[w, : ns[w]])
        if out is not None:
            b.paths[i], b.lengths[i] = out
    _recheck(stages, b, todo)
    b.replans[todo] += 1
