"""Query sampling: uniform, non-trivial (Alg. 3) and the p_nt mixture (Alg. 2).

Everything here is deterministic for a ``jax.random`` key and independent of
how many items are requested: candidates are drawn in fixed-size blocks, block
``i`` from ``fold_in(key, i)``, so asking for more queries extends the same
stream (the first ``k`` queries never change).

* Uniform valid states: vectorised rejection from the robot's configuration box.
* Uniform queries: consecutive pairs of the valid-state stream (start and goal
  independent and uniform on the free space).
* Non-trivial queries (Alg. 3): the paper's sequential sampler draws a uniform
  query, returns it if ``steer_to`` fails, and after ``n_max`` trivial attempts
  returns the last (trivial) one. Here the candidate stream is checked
  thousands at a time with the shared ``steer_to`` kernel and the sequential
  bookkeeping is replayed with array operations, so the output is exactly what
  the sequential sampler returns on the same candidate stream.
* Kinds: ``UNIFORM = 0``, ``NON_TRIVIAL = 1``, and ``NT_EXHAUSTED = 2`` for a
  query the non-trivial sampler returned after ``n_max`` trivial attempts.
* gamma_nt, the fraction of uniform valid queries that are non-trivial, is estimated
  by :mod:`ntq_jax.gamma`.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import prng
from ntq_jax.geometry import World
from ntq_jax.robots.batch import steer_to_pairs, valid_states
from ntq_jax.validation import check_count, check_padding, check_probability

Array = jax.Array

#: Query kind: a query drawn uniformly (its straight motion may be free).
UNIFORM = 0
#: Query kind: a non-trivial query (valid ends, the straight motion between them blocked).
NON_TRIVIAL = 1
#: Query kind: asked for non-trivial, but ``n_max`` draws were all trivial; the sampler
#: returns the last (trivial) draw.
NT_EXHAUSTED = 2

STATE_BLOCK = 8192  # candidate states drawn per block (fixed: results do not depend on n)
QUERY_BLOCK = 4096  # candidate queries checked per block by the non-trivial sampler
DEFAULT_N_MAX = 10_000
MAX_STATE_BLOCKS = 100_000  # ~8e8 candidates before giving up on a nearly-full map


class FreeSpaceTooSmall(ValueError):
    """Raised when rejection sampling finds (almost) no valid state."""


# ---------------------------------------------------------------------------
# Uniform valid states
# ---------------------------------------------------------------------------


@functools.partial(jax.jit, static_argnames=("robot", "size"))
def _uniform_block(robot, world: World, key: Array, size: int) -> Array:
    """``(size, d)`` states uniform on the robot's configuration box."""
    lo, hi = robot.config_bounds(world)
    u = jax.random.uniform(key, (robot.dim, size), jnp.float32)
    return (lo[:, None] + u * (hi - lo)[:, None]).T


def _state_block(robot, world: World, key: Array, padding: float, size: int):
    """A block of uniform candidates and their validity (host arrays); the validity by
    :func:`ntq_jax.robots.batch.valid_states`, whose compiled program every other
    validity check of the robot, map and padding shares."""
    cand = np.asarray(_uniform_block(robot, world, key, size))
    return cand, valid_states(robot, world, cand, padding)


def valid_state_stream(robot, world: World, key: Array, padding: float):
    """Yields blocks of uniform valid states ``(m, d)`` (NumPy float32), forever.

    Raises:
        FreeSpaceTooSmall: when the first 64 blocks hold no valid state, or the
            acceptance rate makes further sampling hopeless.
    """
    key = prng.typed_key(key)  # raw and typed keys share one compiled program
    accepted = drawn = 0
    for i in range(MAX_STATE_BLOCKS):
        cand, ok = _state_block(robot, world, jax.random.fold_in(key, i), padding, STATE_BLOCK)
        ok = np.asarray(ok)
        drawn += ok.size
        accepted += int(ok.sum())
        if i == 63 and accepted == 0:
            raise FreeSpaceTooSmall(
                f"no valid state among {drawn} uniform samples (padding={padding}): the free "
                "space is empty or too small to sample; reduce the padding or the obstacles"
            )
        if ok.any():
            yield cand[ok]
    raise FreeSpaceTooSmall(
        f"only {accepted} valid states among {drawn} samples "
        f"(padding={padding}); the free space is too small to sample"
    )


def _take(stream, n: int, d: int) -> np.ndarray:
    out, have = [], 0
    while have < n:
        blk = next(stream)
        out.append(blk)
        have += len(blk)
    return np.concatenate(out)[:n] if out else np.zeros((0, d), np.float32)


def sample_states(robot, world: World, key: Array, n: int, padding: float) -> np.ndarray:
    """``n`` uniform valid states, ``(n, d)`` float32 (``n`` an int >= 0)."""
    n = check_count("n", n)
    padding = check_padding(padding)
    return _take(valid_state_stream(robot, world, key, padding), n, robot.dim)


def sample_uniform_queries(robot, world: World, key: Array, n: int, padding: float) -> np.ndarray:
    """``n`` uniform queries ``(n, 2, d)``: independent uniform valid start and goal (``n`` >= 0)."""
    n = check_count("n", n)
    s = sample_states(robot, world, key, 2 * n, padding)
    return s.reshape(n, 2, robot.dim)


# ---------------------------------------------------------------------------
# Non-trivial queries (Alg. 3)
# ---------------------------------------------------------------------------


def replay_nontrivial(blocked: np.ndarray, n_max: int, attempts0: int = 0):
    """Replays the sequential sampler of Alg. 3 over a stream of candidate queries.

    The sequential sampler counts attempts; candidate ``k`` is returned when it
    is blocked (non-trivial), or when it is the ``n_max``-th attempt of the
    current call (returned trivial, flagged). This computes, with array
    operations, which candidates are returned.

    Args:
        blocked: ``(m,)`` bool, ``True`` where ``steer_to`` failed.
        n_max: the attempt limit ``N_max`` (>= 1).
        attempts0: attempts already made in the current call before this block.

    Returns:
        ``(emit_index, exhausted, attempts_after)``: indices into the block of the
        returned candidates in order, whether each was returned after ``n_max``
        trivial attempts, and the attempt count carried into the next block.
    """
    n_max = check_count("n_max", n_max, 1)
    blocked = np.asarray(blocked, bool)
    m = blocked.size
    if m == 0:
        return np.zeros(0, np.int64), np.zeros(0, bool), attempts0
    run = np.concatenate([[0], np.cumsum(blocked)[:-1]])  # run id: blocked ones end their run
    pos = np.arange(m)
    run_start = np.zeros(int(run[-1]) + 1, np.int64)
    starts = np.flatnonzero(np.concatenate([[True], blocked[:-1]]))
    run_start[: len(starts)] = starts
    # attempt number of candidate k within the current call (1-based), before emission resets
    base = np.where(run == 0, attempts0, 0)
    attempt = base + pos - run_start[run] + 1
    exhausted = ~blocked & (attempt % n_max == 0)
    emit = blocked | exhausted
    idx = np.flatnonzero(emit)
    # attempts carried over: those after the last emission in the final run
    if blocked[-1]:
        after = 0
    else:
        after = int(attempt[-1] % n_max)
    return idx, exhausted[idx], after


def sample_nontrivial_queries(
    robot, world: World, key: Array, n: int, padding: float, n_max: int = DEFAULT_N_MAX
):
    """``n`` queries from Alg. 3, ``((n, 2, d), exhausted (n,) bool)``.

    Exactly the sequential rejection sampler applied to the stream of uniform
    candidate queries; ``exhausted[i]`` marks a trivial query returned after
    ``n_max`` failed attempts. ``n`` is an int >= 0, ``n_max`` an int >= 1.
    """
    n = check_count("n", n)
    n_max = check_count("n_max", n_max, 1)
    padding = check_padding(padding)
    stream = valid_state_stream(robot, world, key, padding)
    buf = np.zeros((0, robot.dim), np.float32)
    out_q, out_x, have, attempts = [], [], 0, 0
    while have < n:
        while len(buf) < 2 * QUERY_BLOCK:
            buf = np.concatenate([buf, next(stream)])
        cand = buf[: 2 * QUERY_BLOCK].reshape(QUERY_BLOCK, 2, robot.dim)
        buf = buf[2 * QUERY_BLOCK :]
        # the shared chunked program of steer_to_pairs (the same answers at any batch size)
        blocked = ~steer_to_pairs(robot, world, cand[:, 0], cand[:, 1], padding)
        idx, exh, attempts = replay_nontrivial(blocked, n_max, attempts)
        out_q.append(cand[idx])
        out_x.append(exh)
        have += len(idx)
    q = np.concatenate(out_q)[:n]
    x = np.concatenate(out_x)[:n]
    return q, x


# ---------------------------------------------------------------------------
# The p_nt mixture (Alg. 2)
# ---------------------------------------------------------------------------


def sample_queries(
    robot, world: World, key: Array, n: int, p_nt: float, padding: float, n_max: int = DEFAULT_N_MAX
):
    """``n`` queries of Alg. 2: each non-trivial with probability ``p_nt``, else uniform.

    Args:
        n: number of queries, an int >= 0.
        p_nt: probability of a non-trivial query, in ``[0, 1]``.
        padding: clearance (a finite number >= 0).
        n_max: attempts of the non-trivial sampler, an int >= 1.

    Returns:
        ``(queries (n, 2, d) float32, kind (n,) int8)`` with kind ``UNIFORM``,
        ``NON_TRIVIAL`` or ``NT_EXHAUSTED``.

    Raises:
        TypeError, ValueError: an argument of the wrong type or out of range
            (the message names it).
    """
    n = check_count("n", n)
    p_nt = check_probability("p_nt", p_nt)
    n_max = check_count("n_max", n_max, 1)
    padding = check_padding(padding)
    k_mix, k_uni, k_nt = jax.random.split(key, 3)
    use_nt = prng.uniform_prefix(k_mix, n) < p_nt
    n_nt = int(use_nt.sum())
    queries = np.zeros((n, 2, robot.dim), np.float32)
    kind = np.zeros(n, np.int8)
    if n - n_nt:
        queries[~use_nt] = sample_uniform_queries(robot, world, k_uni, n - n_nt, padding)
    if n_nt:
        q, exh = sample_nontrivial_queries(robot, world, k_nt, n_nt, padding, n_max)
        queries[use_nt] = q
        kind[use_nt] = np.where(exh, NT_EXHAUSTED, NON_TRIVIAL)
    return queries, kind
