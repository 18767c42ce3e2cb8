"""The neural planner's checks on the host, for robots whose checks are costly to compile.

A robot whose ``shared_check_programs`` is True (the 3-D serial arm: its obstacle,
self-collision and motion checks cost tens of seconds to compile) does not get a fused
copy of them in every stage of :mod:`ntq_jax.neural.steps`. The stages made only of checks run
here instead, on host arrays, through the package's shared batched programs, which data
generation, path verification and the planners compile anyway:

* :func:`ends_valid`: the validity of the queries' starts and goals, the first step of
  the coarse plan (the plan itself, with its PNet and steerTo inside a loop, stays one
  compiled stage: :func:`ntq_jax.neural.steps.coarse_plan_core`);
* :func:`valid_host`: the ``"valid"`` stage, every path state's validity;
* :func:`check_host`: the ``"check"`` stage, lazy states contraction
  (:func:`ntq_jax.planners.smoothing.shortcut_paths`, the greedy rule of
  :func:`~ntq_jax.planners.smoothing.shortcut_batch` driven from the host) and the
  feasibility check of every segment (:func:`ntq_jax.planners.verify.motions_free`).

They check the same states and motions with the same kernels as the fused stages, so
they return the same answers; only the programs that run them differ.
``tests/test_neural_planner.py::test_host_stages_plan_as_the_fused_stages`` holds it on
the point robot given the flag, and ``benchmarks/bench_neural_stages.py`` compares every
output array of both on the Panda (panda/table_pick/1, 256 queries, certified check,
replanning). Every function takes ``(robot, opts, world, ...)`` as its fused
stage does and returns host NumPy arrays.
"""

from __future__ import annotations

import numpy as np

from ntq_jax.neural.motions import feasible_rows
from ntq_jax.planners.smoothing import shortcut_paths
from ntq_jax.planners.verify import motions_free, states_valid

__all__ = ["ends_valid", "valid_host", "check_host"]


def ends_valid(robot, opts, world, starts, goals, active) -> np.ndarray:
    """``(N,)`` bool: the ``active`` rows whose start and goal ``(N, d)`` are both valid at
    ``opts.eval_padding`` (:func:`ntq_jax.neural.steps.coarse_core`'s ``valid``)."""
    starts, goals = np.asarray(starts), np.asarray(goals)
    valid = np.asarray(active, bool).copy()
    rows = np.flatnonzero(valid)
    if rows.size:
        ok = states_valid(
            robot, world, np.concatenate([starts[rows], goals[rows]]), opts.eval_padding
        )
        valid[rows] = ok[: rows.size] & ok[rows.size :]
    return valid


def valid_host(robot, opts, world, p, n) -> list[np.ndarray]:
    """:func:`ntq_jax.neural.steps.valid_core` on the host: ``[ok (N, L)]``, the states
    ``p[i, :n[i]]`` valid at ``opts.eval_padding`` (False past a path's end)."""
    p, n = np.asarray(p), np.asarray(n)
    inside = np.arange(p.shape[1])[None, :] < n[:, None]
    ok = np.zeros(inside.shape, bool)
    r, c = np.nonzero(inside)
    if r.size:
        ok[r, c] = states_valid(robot, world, p[r, c], opts.eval_padding)
    return [ok]


def _contract(robot, opts, world, p: np.ndarray, n: np.ndarray, mask: np.ndarray) -> None:
    """Lazy states contraction of the masked paths with two or more states, in place
    (:func:`ntq_jax.neural.steps.contract`'s rule and checks)."""
    rows = np.flatnonzero(mask & (n >= 2))
    if not rows.size:
        return
    q, m, _ = shortcut_paths(robot, world, p[rows], n[rows], opts.plan_padding)
    p[rows] = np.nan
    p[rows, : q.shape[1]] = q
    n[rows] = m


def check_host(robot, opts, world, p, n, todo) -> list[np.ndarray]:
    """:func:`ntq_jax.neural.steps.check_core` on the host: contraction of the rows ``todo``
    (where ``opts.repairs and opts.contract``) and their feasibility check.

    Returns ``[p, n, feasible, blocked]`` as the fused stage does: ``blocked (N, L-1)``
    the existing segments of the rows ``todo`` in collision at ``opts.eval_padding`` by
    ``opts.eval_check``; ``feasible`` by the stage's rule,
    :func:`ntq_jax.neural.motions.feasible_rows`.
    """
    p = np.array(p, np.float32)
    n = np.array(n)
    todo = np.asarray(todo, bool)
    if opts.repairs and opts.contract:
        _contract(robot, opts, world, p, n, todo)
    seg = (np.arange(p.shape[1] - 1)[None, :] < (n - 1)[:, None]) & todo[:, None]
    free = np.zeros(seg.shape, bool)
    r, c = np.nonzero(seg)
    if r.size:
        free[r, c] = motions_free(
            robot, world, p[r, c], p[r, c + 1], opts.eval_padding, opts.eval_check
        )
    blocked = seg & ~free
    states_ok = lambda: valid_host(robot, opts, world, p, n)[0]  # noqa: E731
    return [p, n, feasible_rows(opts, todo, n, blocked, states_ok, np), blocked]
