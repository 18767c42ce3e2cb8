"""Batched path shortcutting with the package's one ``steer_to`` kernel.

The rule is MPNet's *lazy states contraction* (Qureshi et al.), which is the
greedy "farthest visible waypoint" shortcut: starting at the first waypoint,
jump to the LAST waypoint of the path that can be reached by one straight
``steer_to`` connection, append it, and repeat from there until the goal is
reached. Waypoints are only removed, never moved or added, so

* the start and the goal are kept exactly (same float32 values);
* the cost never increases (triangle inequality of the robot's metric, up to
  float rounding of collinear points);
* every kept connection was checked by the exact kernel at the planning
  padding, in the direction it is travelled.

If a connection of the INPUT path between consecutive waypoints ``i -> i+1`` is
itself blocked (the input was not feasible) and nothing further is visible, the
rule keeps ``i + 1`` anyway and the path is flagged ``ok = False``; callers must
not report such a path as solved.

Vectorisation: :func:`shortcut_paths` (the host entry point every planner uses)
runs the rule in rounds: each round checks, for every path not yet at its goal,
the connections from its current waypoint to all its later waypoints, the
connections of all paths in one call of :func:`ntq_jax.planners.verify.motions_free`
(the planners' batched check, whose compiled programs every planner and the path
verification share), so shortcutting adds no
program of its own. :func:`shortcut_batch` is the traceable core for jitted
callers (the neural planner): the same rule in one ``lax.while_loop`` over a
batch of ``B`` NaN-padded paths ``(B, L, d)``, each iteration checking ``B * L``
masked connections through :func:`ntq_jax.robots.batch.steer_to_cm`. Both make
exactly the same checks and keep the same waypoints.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.planners.verify import motions_free
from ntq_jax.robots.batch import steer_to_cm

Array = jax.Array

#: Paths shortcut together by :func:`shortcut_paths` (bounds the connections of one round).
SHORTCUT_GROUP = 4096


def shortcut_batch(
    robot, world: World, paths: Array, lengths: Array, padding: float, check: str = "discretized"
):
    """Greedy farthest-visible shortcutting of a batch of paths (traceable, static shapes).

    Args:
        robot: the robot (static).
        world: the obstacles.
        paths: ``(B, L, d)`` float32 waypoints, NaN-padded after ``lengths[b]``.
        lengths: ``(B,)`` int32 waypoint counts (0 or 1: returned as they are).
        padding: clearance of the planning geometry (static).
        check: the motion check (static; see :func:`ntq_jax.robots.batch.motion_check`).

    Returns:
        ``(out (B, L, d), out_lengths (B,) int32, ok (B,) bool)``: the shortcut
        paths (NaN-padded), their lengths, and whether every kept connection was
        verified collision-free.
    """
    b, l, d = paths.shape
    lengths = jnp.clip(lengths.astype(jnp.int32), 0, l)
    pts = jnp.moveaxis(paths, 2, 0)  # (d, B, L)
    flat = pts.reshape(d, b * l)
    rows = jnp.arange(b)
    j = jnp.arange(l, dtype=jnp.int32)[None, :]

    def cond(state):
        return ~jnp.all(state[3])

    def body(state):
        cur, idx, n, done, ok = state
        a = pts[:, rows, cur]  # (d, B)
        a_b = jnp.broadcast_to(a[:, :, None], (d, b, l)).reshape(d, b * l)
        cand = (j > cur[:, None]) & (j < lengths[:, None]) & ~done[:, None]
        vis = steer_to_cm(robot, world, a_b, flat, padding, mask=cand.reshape(-1), check=check)
        vis = vis.reshape(b, l) & cand
        far = jnp.max(jnp.where(vis, j, -1), axis=1)
        seen = far > cur
        nxt = jnp.where(done, cur, jnp.where(seen, far, cur + 1))
        ok = ok & (done | seen)
        idx = idx.at[rows, jnp.where(done, l, n)].set(nxt, mode="drop")
        n = jnp.where(done, n, n + 1)
        done = done | (nxt >= lengths - 1)
        return nxt, idx, n, done, ok

    cur0 = jnp.zeros(b, jnp.int32)
    idx0 = jnp.full((b, l), -1, jnp.int32).at[:, 0].set(0)
    n0 = jnp.minimum(lengths, 1)
    done0 = lengths <= 1
    _, idx, n, _, ok = lax.while_loop(cond, body, (cur0, idx0, n0, done0, jnp.ones(b, bool)))
    keep = j < n[:, None]
    out = paths[rows[:, None], jnp.clip(idx, 0, l - 1)]
    out = jnp.where(keep[:, :, None], out, jnp.nan)
    n = jnp.where(lengths <= 1, lengths, n)
    return out, n, ok


shortcut = jax.jit(
    shortcut_batch,
    static_argnames=("robot", "padding", "check"),
    compiler_options=KERNEL_COMPILER_OPTIONS,
)
shortcut.__doc__ = shortcut_batch.__doc__


def shortcut_paths(
    robot,
    world: World,
    paths,
    lengths,
    padding: float,
    *,
    chunk_size: int = SHORTCUT_GROUP,
    check: str = "discretized",
    return_index: bool = False,
) -> tuple[np.ndarray, ...]:
    """Shortcuts a batch of NaN-padded paths (greedy farthest-visible rule), any batch size.

    The same rule and the same waypoints as :func:`shortcut_batch`, driven from the
    host: in each round, every path not yet at its goal checks the connections
    from its current waypoint to all its later waypoints, and the connections of
    all paths of a group go through :func:`ntq_jax.planners.verify.motions_free`
    together (its compiled program per robot, map, padding and check, shared with
    the path verification), so shortcutting compiles nothing of its own. A
    round's answers are exactly those of the check the traced core makes.

    Args:
        robot, world: the geometry.
        paths: ``(B, L, d)`` waypoints, start first; rows after ``lengths[b]`` are ignored.
        lengths: ``(B,)`` int waypoint counts.
        padding: planning clearance (a number).
        chunk_size: paths shortcut together (a round checks at most
            ``chunk_size * L`` connections at once); the answers do not depend on it.
        check: the motion check (see :func:`ntq_jax.robots.batch.motion_check`).

        return_index: also return ``index (B, L') int32``, the input waypoint each kept
            waypoint is (-1 after the path's end): what a caller needs to put back
            the waypoints a shortcut skipped (:func:`ntq_jax.planners.verify.finalize`'s
            ``fallback``).

    Returns:
        ``(paths (B, L', d) float32 NaN-padded, lengths (B,) int32, ok (B,) bool)``
        with ``L' <= L`` the longest smoothed path (at least 2 when B > 0); ``ok``
        is False where an input connection was blocked (see the module docstring);
        and ``index`` with ``return_index``.
    """
    d = robot.dim
    p = np.asarray(paths, np.float32)
    n_in = np.asarray(lengths, np.int64).reshape(-1)
    if p.ndim != 3 or p.shape[2] != d or p.shape[0] != n_in.shape[0]:
        raise ValueError(
            f"paths must be (B, L, {d}) with lengths (B,), got {p.shape} and {n_in.shape}"
        )
    bsz = p.shape[0]
    if bsz == 0:
        out = np.zeros((0, 2, d), np.float32), np.zeros(0, np.int32), np.zeros(0, bool)
        return out + (np.zeros((0, 2), np.int32),) if return_index else out
    chunk = int(chunk_size)
    if chunk < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    n_in = np.clip(n_in, 0, p.shape[1]).astype(np.int32)
    keep = np.full((bsz, max(1, p.shape[1])), -1, np.int64)  # kept waypoint indices per path
    n_out, ok = np.minimum(n_in, 1), np.ones(bsz, bool)
    keep[:, 0] = 0
    for lo in range(0, bsz, chunk):
        rows = np.arange(lo, min(lo + chunk, bsz))
        _greedy_rounds(robot, world, p, n_in, rows, keep, n_out, ok, padding, check)
    n_out = np.where(n_in <= 1, n_in, n_out).astype(np.int32)
    width = max(2, int(n_out.max()))
    cols = np.arange(width)
    take = np.clip(keep[:, :width], 0, None)
    if take.shape[1] < width:
        take = np.pad(take, ((0, 0), (0, width - take.shape[1])))
    out = (
        np.take_along_axis(p, take[:, :, None], axis=1)
        if p.shape[1]
        else np.zeros((bsz, width, d), np.float32)
    )
    inside = cols[None, :] < n_out[:, None]
    out = np.where(inside[:, :, None], out, np.float32(np.nan))
    if return_index:
        return out.astype(np.float32), n_out, ok, np.where(inside, take, -1).astype(np.int32)
    return out.astype(np.float32), n_out, ok


def _greedy_rounds(robot, world, p, n_in, rows, keep, n_out, ok, padding, check):
    """The rounds of :func:`shortcut_paths` for the paths ``rows`` (updates ``keep``,
    ``n_out`` and ``ok`` in place)."""
    cur = np.zeros(len(rows), np.int64)
    live = n_in[rows] > 1
    while live.any():
        r, c = rows[live], cur[live]
        count = n_in[r] - 1 - c  # the later waypoints of each live path
        owner = np.repeat(np.arange(len(r)), count)
        j = c[owner] + 1 + (np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count))
        vis = motions_free(
            robot, world, p[r[owner], c[owner]], p[r[owner], j], padding, check=check
        )
        far = np.full(len(r), -1, np.int64)
        np.maximum.at(far, owner[vis], j[vis])
        seen = far > c
        nxt = np.where(seen, far, c + 1)
        ok[r] &= seen
        keep[r, n_out[r]] = nxt
        n_out[r] += 1
        cur[live] = nxt
        live[live] = nxt < n_in[r] - 1


def shortcut_reference(steer, path: np.ndarray) -> tuple[np.ndarray, bool]:
    """Plain-Python reference of the same greedy rule, for one path (used by the tests).

    Args:
        steer: ``steer(a (d,), b (d,)) -> bool``.
        path: ``(n, d)`` waypoints.

    Returns:
        ``(smoothed path (m, d), ok)``.
    """
    path = np.asarray(path)
    n = len(path)
    if n <= 1:
        return path.copy(), True
    keep, i, ok = [0], 0, True
    while i < n - 1:
        nxt = None
        for jj in range(n - 1, i, -1):
            if steer(path[i], path[jj]):
                nxt = jj
                break
        if nxt is None:
            ok, nxt = False, i + 1
        keep.append(nxt)
        i = nxt
    return path[keep], ok


__all__ = ["shortcut_batch", "shortcut", "shortcut_paths", "shortcut_reference"]
