"""gamma_nt: the fraction of uniform valid queries whose straight motion is blocked.

:func:`gamma_nt` is a fused, streaming estimator with a Wilson 95 % interval: each
chunk of candidate pairs is generated (uniforms from :mod:`ntq_jax.prng`, the same
stream at any chunk count), checked for validity and ``steer_to`` and counted in one
compiled call, so memory is that of one chunk whatever the number of queries. A robot
whose checks are costly to compile (``shared_check_programs``, the 3-D arm) runs each
chunk through its shared batched checks instead, with the same lanes. The queries
themselves (uniform, non-trivial, the p_nt mixture) are :mod:`ntq_jax.queries`.
"""

from __future__ import annotations

import functools
import math
import time
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import prng
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.queries import FreeSpaceTooSmall
from ntq_jax.robots.batch import is_valid_cm, steer_to_cm, steer_to_pairs, valid_states
from ntq_jax.stats import wilson_interval
from ntq_jax.validation import check_count, check_padding

Array = jax.Array

#: The largest chunk of :func:`gamma_nt`: candidate pairs per compiled chunk (~8 bytes each
#: for the point robot).
MAX_CHUNK = 1 << 26


class GammaEstimate(NamedTuple):
    """Result of :func:`gamma_nt`.

    Attributes:
        gamma: non-trivial fraction of uniform valid queries.
        ci95: Wilson 95% interval ``(lo, hi)``.
        queries: uniform valid queries examined (the denominator).
        non_trivial: how many of them ``steer_to`` rejected.
        candidates: raw candidate pairs drawn (valid or not).
        seconds: wall time.
    """

    gamma: float
    ci95: tuple[float, float]
    queries: int
    non_trivial: int
    candidates: int
    seconds: float

    @property
    def queries_per_second(self) -> float:
        return self.queries / self.seconds if self.seconds > 0 else float("inf")

    @property
    def candidates_per_second(self) -> float:
        return self.candidates / self.seconds if self.seconds > 0 else float("inf")


class GammaInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`gamma_nt`; ``estimate`` is the streaming estimate so far.

    A ``KeyboardInterrupt`` (so code that does not know it still stops), whose
    ``estimate`` is a :class:`GammaEstimate` over the whole chunks counted before
    the interrupt (an unbiased estimate over fewer queries, with its wider
    interval), or None when none was.
    """

    def __init__(self, estimate: GammaEstimate | None):
        super().__init__("gamma_nt interrupted")
        self.estimate = estimate


def _chunk_uniforms(seeds: Array, lane0: Array, size: int, k: int) -> list[Array]:
    """``k`` rows of ``size`` uniforms; row ``j`` of lane ``l`` uses counter ``l * k + j``."""
    lane = lane0 + jnp.arange(size, dtype=jnp.uint32)
    return [prng.uniform(seeds, lane * jnp.uint32(k) + jnp.uint32(j)) for j in range(k)]


def _pair_from_uniforms(robot, world: World, u) -> tuple[Array, Array]:
    """Coordinate-major ``(d, size)`` starts and goals from ``2 d`` rows of uniforms (rows
    ``0..d-1`` the start, ``d..2d-1`` the goal), each row scaled on its own to the
    robot's configuration box."""
    d = robot.dim
    lo, hi = robot.config_bounds(world)
    rows = [lo[j % d] + u[j] * (hi[j % d] - lo[j % d]) for j in range(2 * d)]
    return jnp.stack(rows[:d]), jnp.stack(rows[d:])


def _outcomes_from_uniforms(robot, world: World, u, padding: float):
    """Per-lane (both endpoints valid, blocked) of the candidate pairs drawn from uniforms.

    ``u`` holds ``2 d`` rows (a list of ``(size,)`` arrays, or a ``(2 d, size)``
    array) of uniforms in ``[0, 1)``: rows ``0..d-1`` place the start, rows
    ``d..2d-1`` the goal in the robot's configuration box. Each row is scaled on
    its own and the states are assembled coordinate-major, so XLA fuses the
    generator, the validity and ``steer_to`` tests and the counting into one loop.
    """
    a, b = _pair_from_uniforms(robot, world, u)
    both = is_valid_cm(robot, world, a, padding) & is_valid_cm(robot, world, b, padding)
    blocked = both & ~steer_to_cm(robot, world, a, b, padding, mask=both)
    return both, blocked


def _lane_outcomes(robot, world: World, seeds: Array, lane0: Array, size: int, padding: float):
    """Per-lane (both endpoints valid, blocked) for ``size`` candidate pairs of one chunk."""
    u = _chunk_uniforms(seeds, lane0, size, 2 * robot.dim)
    return _outcomes_from_uniforms(robot, world, u, padding)


COUNT_ROWS = (
    64  # lanes are counted as (COUNT_ROWS, size / COUNT_ROWS) so XLA splits them over cores
)


def count_rows(both: Array, blocked: Array) -> tuple[Array, Array]:
    """Per-row ``(sum(both), sum(blocked))``, each ``(rows,)`` int32, in ONE pass over the lanes.

    The lanes are split into ``rows = gcd(N, COUNT_ROWS)`` runs of consecutive
    lanes. A variadic reduction lets XLA fuse the per-lane work into the
    reduction loop (two separate ``jnp.sum`` calls recompute or materialise
    every lane); the row split gives the loop an outer dimension that XLA runs
    on all CPU cores.
    """
    rows = math.gcd(both.shape[0], COUNT_ROWS)
    v = both.astype(jnp.int32).reshape(rows, -1)
    b = blocked.astype(jnp.int32).reshape(rows, -1)
    zero = jnp.int32(0)
    return jax.lax.reduce((v, b), (zero, zero), lambda x, y: (x[0] + y[0], x[1] + y[1]), (1,))


def count_outcomes(both: Array, blocked: Array) -> tuple[Array, Array]:
    """``(sum(both), sum(blocked))`` as int32, in ONE pass over the lanes (see :func:`count_rows`)."""
    v, b = count_rows(both, blocked)
    return jnp.sum(v), jnp.sum(b)


_gamma_jit = functools.partial(
    jax.jit, static_argnames=("robot", "padding", "size"), compiler_options=KERNEL_COMPILER_OPTIONS
)


@_gamma_jit
def _fused_chunk_counts(robot, world, seeds, padding: float, size: int):
    return count_rows(*_lane_outcomes(robot, world, seeds, jnp.uint32(0), size, padding))


@_gamma_jit
def _fused_chunk_lanes(robot, world, seeds, lane0, padding: float, size: int):
    return _lane_outcomes(robot, world, seeds, lane0, size, padding)


@functools.partial(jax.jit, static_argnames=("robot", "size"))
def _chunk_pairs(robot, world, seeds, lane0, size: int) -> tuple[Array, Array]:
    """Row-major ``(size, d)`` starts and goals of a chunk's lanes (the fused chunk's)."""
    a, b = _pair_from_uniforms(robot, world, _chunk_uniforms(seeds, lane0, size, 2 * robot.dim))
    return a.T, b.T


def _shared_chunk_lanes(robot, world, seeds, lane0, padding: float, size: int):
    """The fused chunk's lanes through the robot's shared batched programs: the pairs
    drawn by one small program, then :func:`~ntq_jax.robots.batch.valid_states` on
    both ends and :func:`~ntq_jax.robots.batch.steer_to_pairs` on the valid pairs only
    (host arrays). The same uniforms and checks, so the same lanes; no program of its
    own for the checks, whose compilation costs seconds on a 3-D arm."""
    a, b = (np.asarray(x) for x in _chunk_pairs(robot, world, seeds, lane0, size))
    ok = valid_states(robot, world, np.concatenate([a, b]), padding)
    both = ok[:size] & ok[size:]
    idx = np.flatnonzero(both)
    blocked = np.zeros(size, bool)
    blocked[idx] = ~steer_to_pairs(robot, world, a[idx], b[idx], padding)
    return both, blocked


def _gamma_chunk_lanes(robot, world, seeds, lane0, padding: float, size: int):
    """Per-lane ``(both ends valid, blocked)`` of ``size`` lanes from ``lane0``: one fused
    program, or the shared programs for a robot whose ``shared_check_programs`` is True."""
    if getattr(robot, "shared_check_programs", False):
        return _shared_chunk_lanes(robot, world, seeds, lane0, padding, size)
    return _fused_chunk_lanes(robot, world, seeds, lane0, padding, size)


def _gamma_chunk_counts(robot, world, seeds, padding: float, size: int):
    """:func:`count_rows` of a whole chunk's lanes (as :func:`_gamma_chunk_lanes`)."""
    if getattr(robot, "shared_check_programs", False):
        both, blocked = _shared_chunk_lanes(robot, world, seeds, jnp.uint32(0), padding, size)
        rows = math.gcd(size, COUNT_ROWS)
        return (both.reshape(rows, -1).sum(1), blocked.reshape(rows, -1).sum(1))
    return _fused_chunk_counts(robot, world, seeds, padding, size)


def _chunk_prefix(
    robot,
    world: World,
    seeds: Array,
    padding: float,
    chunk: int,
    rows_valid: np.ndarray,
    rows_blocked: np.ndarray,
    need: int,
) -> tuple[int, int]:
    """``(blocked, candidates)`` of a chunk's lanes up to its ``need``-th valid one.

    From the chunk's per-row counts: the rows before the one holding that lane
    are summed, and only that row's lanes are generated and checked again.
    """
    row = chunk // len(rows_valid)
    cum = np.cumsum(rows_valid)
    r = int(np.searchsorted(cum, need))  # the first row whose running count reaches need
    before = int(cum[r - 1]) if r else 0
    both, blk = _gamma_chunk_lanes(robot, world, seeds, jnp.uint32(r * row), padding, row)
    both, blk = np.asarray(both), np.asarray(blk)
    last = int(np.flatnonzero(both)[need - before - 1])
    return int(rows_blocked[:r].sum()) + int(blk[: last + 1].sum()), r * row + last + 1


#: Rows of a chunk (:func:`count_rows`) that :func:`gamma_nt` checks lane by lane before it
#: counts whole chunks: an estimate over at most ``SMALL_ROWS / 2`` rows' worth of queries
#: is read off the first rows of chunk 0 (one compiled program, the one the last chunk's
#: prefix uses), and only a run that needs more counts whole chunks.
SMALL_ROWS = 8


def _small_estimate(
    robot, world: World, seeds: Array, padding: float, chunk: int, n: int
) -> tuple[int, int] | None:
    """``(blocked, candidates)`` of chunk 0's lanes up to its ``n``-th valid one, from its
    first :data:`SMALL_ROWS` rows checked lane by lane; None when they hold fewer than ``n``
    valid queries (or ``n`` is above half their lanes: whole chunks are then cheaper)."""
    rows = math.gcd(chunk, COUNT_ROWS)
    row = chunk // rows
    if n > row * min(SMALL_ROWS, rows) // 2:
        return None
    seen = blocked = 0
    for r in range(min(SMALL_ROWS, rows)):
        both, blk = _gamma_chunk_lanes(robot, world, seeds, jnp.uint32(r * row), padding, row)
        both, blk = np.asarray(both), np.asarray(blk)
        v = int(both.sum())
        if seen + v >= n:
            last = int(np.flatnonzero(both)[n - seen - 1])
            return blocked + int(blk[: last + 1].sum()), r * row + last + 1
        seen, blocked = seen + v, blocked + int(blk.sum())
    return None


#: Candidate pairs per chunk of :func:`gamma_nt` for the point robot on a world with a
#: broad-phase index (more than ``broadphase.UNROLL_MAX`` boxes): its work queue keeps about
#: half a kilobyte per pair, so 2**18 pairs hold the working memory near 150 MB whatever the
#: map's size (the fused kernel of the presets keeps 2**22).
INDEXED_POINT_CHUNK = 1 << 18


def default_chunk(robot, world: World | None = None) -> int:
    """Candidate pairs per compiled chunk of :func:`gamma_nt`: 2**22 for the point robot
    (:data:`INDEXED_POINT_CHUNK` on an indexed ``world``), 2**15 for the others. Memory
    is that of one chunk, whatever the number of queries."""
    if robot.kind != "point":
        return 1 << 15
    return INDEXED_POINT_CHUNK if getattr(world, "index", None) is not None else 1 << 22


def gamma_nt(
    robot,
    world: World,
    key: Array,
    n: int,
    padding: float,
    chunk: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> GammaEstimate:
    """Estimates gamma_nt over exactly ``n`` uniform valid queries, streaming in chunks.

    Each chunk of ``chunk`` candidate pairs is generated, checked and counted in
    one compiled call (its uniforms come from :mod:`ntq_jax.prng`, seeded per
    chunk from ``key``), so memory does not grow with ``n``; a robot with
    ``shared_check_programs`` (the 3-D arm) draws the chunk in one small program
    and checks it with its shared batched checks: the same lanes, no costly program
    of its own. The last chunk
    counts only the valid queries needed to reach exactly ``n`` (its lanes up to
    the ``n``-th valid query). The next chunk is queued while one is counted, so
    dispatch overlaps compute, except when the chunk being counted is expected
    to be the last. A small ``n`` (see :data:`SMALL_ROWS`) is read off the first rows of
    chunk 0 lane by lane instead: the same stream, the same counts.

    Args:
        n: uniform valid queries to examine, an int >= 1.
        padding: clearance (a finite number >= 0).
        chunk: candidate pairs per compiled chunk, an int in ``[1, MAX_CHUNK]``;
            None = :func:`default_chunk`.
        progress: called with the number of valid queries counted so far.

    Raises:
        TypeError, ValueError: an argument of the wrong type or out of range
            (the message names it).
        FreeSpaceTooSmall: no valid query among the first 65 chunks.
        GammaInterrupted: on Ctrl-C (a ``KeyboardInterrupt``), with the estimate
            over the chunks counted so far.
    """
    n = check_count("n", n, 1)
    padding = check_padding(padding)
    chunk = (
        default_chunk(robot, world) if chunk is None else check_count("chunk", chunk, 1, MAX_CHUNK)
    )
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be callable or None, got {type(progress).__name__}")
    t0 = time.perf_counter()

    def seeds(i):
        return prng.stream_seeds(key, i)

    counts = (0, 0, 0)  # valid queries, blocked, raw candidates: one tuple, updated at once
    i, nxt = 0, None
    try:
        small = _small_estimate(robot, world, seeds(0), padding, chunk, n)
        if small is not None:
            counts = (n, *small)
            if progress is not None:
                progress(n)
            return _estimate(counts, t0)
        pending = _gamma_chunk_counts(robot, world, seeds(0), padding, chunk)
        while True:
            queries, blocked, cands = counts
            # the next chunk is queued before this one is read, unless this one likely ends it
            expect = chunk * queries / cands if cands else chunk
            nxt = (
                _gamma_chunk_counts(robot, world, seeds(i + 1), padding, chunk)
                if queries + expect < n
                else None
            )
            v_rows, b_rows = (np.asarray(x) for x in pending)
            v = int(v_rows.sum())
            if queries + v >= n:
                blk, used = _chunk_prefix(
                    robot, world, seeds(i), padding, chunk, v_rows, b_rows, n - queries
                )
                counts = (n, blocked + blk, cands + used)
                break
            counts = (queries + v, blocked + int(b_rows.sum()), cands + chunk)
            if progress is not None:
                progress(counts[0])
            pending = (
                nxt
                if nxt is not None
                else _gamma_chunk_counts(robot, world, seeds(i + 1), padding, chunk)
            )
            i += 1
            if i > 64 and counts[0] == 0:
                raise FreeSpaceTooSmall(
                    f"no valid query among {counts[2]} candidates (padding={padding})"
                )
        jax.block_until_ready(nxt)
        if progress is not None:
            progress(counts[0])
    except KeyboardInterrupt:
        # the estimate over the whole chunks counted before the interrupt, if any
        raise GammaInterrupted(_estimate(counts, t0) if counts[0] else None) from None
    return _estimate(counts, t0)


def _estimate(counts: tuple[int, int, int], t0: float) -> GammaEstimate:
    queries, blocked, cands = counts
    return GammaEstimate(
        blocked / queries,
        wilson_interval(blocked, queries),
        queries,
        blocked,
        cands,
        time.perf_counter() - t0,
    )
