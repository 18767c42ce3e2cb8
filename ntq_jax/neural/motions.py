"""The neural planner's motion checks inside its jitted steps (:mod:`ntq_jax.neural.steps`).

:func:`steer` is the planner's steerTo on row-major pairs; :func:`segments` checks every
segment of a batch of NaN-padded paths; :func:`feasible_rows` is the check stage's
feasibility rule from those verdicts (also run on the host,
:mod:`ntq_jax.neural.host_stages`). A path buffer has room for the coarse plan and every
replanning round (``PlannerOptions.max_len`` states), so after contraction most of its
segments are padding: with the certified check, whose fixed cost per checked motion (the
clearances of both ends, every part of the robot) is paid for masked motions too,
:func:`segments` first gathers the existing segments and checks them in chunks of
:data:`SEGMENT_CHUNK`, as many chunks as there are segments (a ``while_loop``). Each
motion's answer is its own (the check's lanes only schedule motions), so the result is
the same as checking the whole buffer. On the Panda (749 parts; panda/table_pick/1, 10
non-trivial queries, a PNet trained at tiny size, taskset -c 1 on a loaded core) a call
of the check stage (256 path buffers of 152 states) fell from 5.5 to 0.1-0.2 s wall, and
the whole compiled plan of the 10 queries from 5.9 to 0.2 CPU seconds.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ntq_jax.robots.batch import steer_to_cm

Array = jax.Array

#: Segments per certified check inside :func:`segments` (the certified program's one shape
#: in the neural planner's check stage).
SEGMENT_CHUNK = 1024


def steer(
    robot, world, a: Array, b: Array, padding: float, mask: Array, check: str = "discretized"
) -> Array:
    """``(M, d), (M, d) -> (M,)`` via the package's batched motion check; unmasked = False."""
    return steer_to_cm(robot, world, a.T, b.T, padding, mask, check=check)


def steer_gathered(
    robot,
    world,
    a: Array,
    b: Array,
    padding: float,
    mask: Array,
    check: str,
    chunk: int = SEGMENT_CHUNK,
) -> Array:
    """:func:`steer` of the masked pairs only, gathered into chunks of ``chunk`` rows.

    The masked rows are moved to the front (a stable sort), checked ``chunk`` at a
    time while any is left, and their answers scattered back; unmasked rows are False.
    """
    total = a.shape[0]
    chunk = max(1, min(int(chunk), total))
    size = -(-total // chunk) * chunk
    order = jnp.argsort(~mask, stable=True).astype(jnp.int32)
    order = jnp.concatenate([order, jnp.zeros(size - total, jnp.int32)])
    count = jnp.sum(mask, dtype=jnp.int32)
    lanes = jnp.arange(chunk, dtype=jnp.int32)

    def cond(c):
        return c[0] * chunk < count

    def body(c):
        i, out = c
        idx = jax.lax.dynamic_slice(order, (i * chunk,), (chunk,))
        live = i * chunk + lanes < count
        got = steer(robot, world, a[idx], b[idx], padding, live, check)
        return i + 1, jax.lax.dynamic_update_slice(out, got, (i * chunk,))

    _, got = jax.lax.while_loop(cond, body, (jnp.int32(0), jnp.zeros(size, bool)))
    pos = jnp.arange(size, dtype=jnp.int32)
    return jnp.zeros(total, bool).at[jnp.where(pos < count, order, total)].set(got, mode="drop")


def segments(
    robot,
    world,
    p: Array,
    n: Array,
    padding: float,
    mask: Array,
    check: str = "discretized",
    chunk: int = SEGMENT_CHUNK,
):
    """Per-segment freedom ``(N, L-1)`` and the segment mask (existing segments of masked rows).

    The certified check runs on the existing segments only, ``chunk`` at a time
    (:func:`steer_gathered`); the discretised one, whose masked motions cost
    nothing, on the whole buffer.
    """
    num, length, d = p.shape
    seg = (jnp.arange(length - 1)[None, :] < (n - 1)[:, None]) & mask[:, None]
    a, b = p[:, :-1].reshape(-1, d), p[:, 1:].reshape(-1, d)
    if check == "certified":
        free = steer_gathered(robot, world, a, b, padding, seg.reshape(-1), check, chunk)
    else:
        free = steer(robot, world, a, b, padding, seg.reshape(-1), check)
    return free.reshape(num, length - 1), seg


def feasible_rows(opts, mask, n, blocked, states_ok, xp=jnp):
    """The feasibility rule of the check stage, from its segment verdicts: ``(N,)`` bool.

    ``mask`` rows with a state (``n >= 1``) and, with steerTo (or ``opts.nosteer_check``
    True / ``"replan"``), no ``blocked (N, L-1)`` segment; with ``"states"``, every state
    valid (``states_ok()``, called only then, gives ``(N, L)``); with False (the paper's
    variant) unchecked. ``xp``: ``jax.numpy`` inside the jitted stage, ``numpy`` on the
    host (:mod:`ntq_jax.neural.host_stages`); the same rule either way.
    """
    feasible = mask & (n >= 1)
    if opts.steer or opts.nosteer_check not in (False, "states"):
        return feasible & ~xp.any(blocked, axis=1)
    if opts.nosteer_check == "states":  # the waypoints only
        ok = states_ok()
        return feasible & xp.all(ok | (xp.arange(ok.shape[1])[None, :] >= n[:, None]), axis=1)
    return feasible  # the paper's variant, unchecked
