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

Vectorisation: a batch of ``B`` NaN-padded paths ``(B, L, d)`` with lengths
``(B,)`` is shortcut in one ``lax.while_loop``; each iteration checks, for every
path, the connections from its current waypoint to all ``L`` waypoints (masked
to the later ones) as one coordinate-major batch of ``B * L`` segments through
:func:`ntq_jax.robots.batch.steer_to_cm`, and stops when every path reached its
goal. Shapes are static: :func:`shortcut_paths` runs any batch in chunks of a
fixed size with the path buffer padded to a power of two, so one program
serves many calls. :func:`shortcut_batch` is the traceable core (the neural
planner calls it inside its own jitted code). Measurements: BENCHMARKS.md.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ntq_jax.batching import bucket_size, padded_chunks
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.robots.batch import steer_to_cm

Array = jax.Array


def shortcut_batch(robot, world: World, paths: Array, lengths: Array, padding: float,
                   check: str = "discretized"):
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


shortcut = jax.jit(shortcut_batch, static_argnames=("robot", "padding", "check"),
                   compiler_options=KERNEL_COMPILER_OPTIONS)
shortcut.__doc__ = shortcut_batch.__doc__


def shortcut_paths(robot, world: World, paths, lengths, padding: float, *,
                   chunk_size: int = 128, check: str = "discretized") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shortcuts a batch of NaN-padded paths (greedy farthest-visible rule), any batch size.

    The batch is processed in chunks of exactly ``chunk_size`` paths (the last
    one padded with empty paths) and the path buffer is padded to a power of
    two >= 16 (from the longest path of the batch), so repeated calls reuse
    one compiled program per buffer size.

    Args:
        robot, world: the geometry.
        paths: ``(B, L, d)`` waypoints, start first; rows after ``lengths[b]`` are ignored.
        lengths: ``(B,)`` int waypoint counts.
        padding: planning clearance (a number).
        chunk_size: paths per jitted call.
        check: the motion check (see :func:`ntq_jax.robots.batch.motion_check`).

    Returns:
        ``(paths (B, L', d) float32 NaN-padded, lengths (B,) int32, ok (B,) bool)``
        with ``L' <= L`` the longest smoothed path (at least 2 when B > 0); ``ok``
        is False where an input connection was blocked (see the module docstring).
    """
    d = robot.dim
    p = np.asarray(paths, np.float32)
    n_in = np.asarray(lengths, np.int64).reshape(-1)
    if p.ndim != 3 or p.shape[2] != d or p.shape[0] != n_in.shape[0]:
        raise ValueError(f"paths must be (B, L, {d}) with lengths (B,), got {p.shape} "
                         f"and {n_in.shape}")
    bsz = p.shape[0]
    if bsz == 0:
        return np.zeros((0, 2, d), np.float32), np.zeros(0, np.int32), np.zeros(0, bool)
    chunk = int(chunk_size)
    if chunk < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    n_in = np.clip(n_in, 0, p.shape[1]).astype(np.int32)
    lp = bucket_size(int(n_in.max()), 16)
    buf = np.full((bsz, lp, d), np.nan, np.float32)  # the path buffer of every chunk
    w = min(lp, p.shape[1])
    buf[:, :w] = p[:, :w]
    # padding rows are empty paths (length 0): never checked, dropped below
    pending = [(m, shortcut(robot, world, jnp.asarray(b), jnp.asarray(n), padding, check))
               for _, m, (b, n), _ in padded_chunks([buf, n_in], chunk, fill=0)]
    out, n_out, ok = (np.concatenate([np.asarray(r[i])[:m] for m, r in pending]) for i in range(3))
    width = max(2, int(n_out.max()))
    return out[:, :width], n_out, ok


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
