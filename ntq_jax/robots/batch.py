"""Batched, jitted versions of the single-state robot kernels.

Inputs are row-major ``(N, d)`` arrays, as users hold them. Inside the compiled
function they are transposed to coordinate-major ``(d, N)`` and the one-state
kernels are vmapped over the minor axis, so XLA emits one fused elementwise loop
over contiguous rows (the layout the kernels are fast in).

:func:`steer_to_pairs`, :func:`valid_states` and :func:`distances` take host
arrays of any length and run them through one compiled program of a fixed
chunk size (the tail padded and masked): the batched entry points of every
stage above the kernels (includeData, path verification, snapping, ...).

The robot and the padding are static (hashable) arguments; the world is traced,
so a different map with the same obstacle counts reuses the compiled code. The
entry points compile with :data:`ntq_jax.geometry.KERNEL_COMPILER_OPTIONS`.
"""

from __future__ import annotations

import functools

import jax
import numpy as np

from ntq_jax.batching import map_chunks
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.robots.certified import MOTION_CHECKS

Array = jax.Array

_kernel_jit = functools.partial(jax.jit, compiler_options=KERNEL_COMPILER_OPTIONS)


@functools.partial(_kernel_jit, static_argnames=("robot", "padding"))
def is_valid_batch(robot, world: World, states: Array, padding: float) -> Array:
    """``(N, d) -> (N,)`` bool."""
    return jax.vmap(robot.is_valid, in_axes=(1, None, None))(states.T, world, padding)


def motion_check(robot, check: str):
    """The coordinate-major batched motion check ``check`` of ``robot``.

    ``"discretized"``: ``robot.steer_to_batch`` (states ``resolution`` apart, the
    paper's check; exact for the point robot). ``"certified"``:
    ``robot.certified_steer_to_batch`` (every configuration proven clear, see
    :mod:`ntq_jax.robots.certified`; the point robot's exact test is already that).
    """
    if check == "discretized":
        return robot.steer_to_batch
    if check == "certified":
        return robot.certified_steer_to_batch
    raise ValueError(f"check must be one of {MOTION_CHECKS}, got {check!r}")


@functools.partial(_kernel_jit, static_argnames=("robot", "padding", "check"))
def _steer_to_batch(robot, world: World, a: Array, b: Array, padding: float, check: str) -> Array:
    return motion_check(robot, check)(a.T, b.T, world, padding)


def steer_to_batch(robot, world: World, a: Array, b: Array, padding: float,
                   check: str = "discretized") -> Array:
    """``(N, d), (N, d) -> (N,)`` bool, True where the connection is collision-free.

    ``check``: see :func:`motion_check`. One compiled program per robot, padding,
    check and shape, however the arguments are passed.
    """
    return _steer_to_batch(robot, world, a, b, padding, check)


@functools.partial(_kernel_jit, static_argnames=("robot",))
def distance_batch(robot, a: Array, b: Array) -> Array:
    """``(N, d), (N, d) -> (N,)`` cost-metric distances."""
    return jax.vmap(robot.distance, in_axes=(1, 1))(a.T, b.T)


def is_valid_cm(robot, world: World, states_cm: Array, padding: float) -> Array:
    """Coordinate-major ``(d, N) -> (N,)``, for use inside other jitted code."""
    return jax.vmap(robot.is_valid, in_axes=(1, None, None))(states_cm, world, padding)


def steer_to_cm(robot, world: World, a_cm: Array, b_cm: Array, padding: float,
                mask: Array | None = None, check: str = "discretized") -> Array:
    """Coordinate-major ``(d, N), (d, N) -> (N,)``, for use inside other jitted code.

    ``mask`` (optional, ``(N,)`` bool): only these connections are checked, the
    others are reported blocked (False) without any work. ``check``: see
    :func:`motion_check`.
    """
    return motion_check(robot, check)(a_cm, b_cm, world, padding, mask)


STEER_CHUNK = 8192  # pairs per compiled call of steer_to_pairs (discretised check)
#: Pairs per compiled call of the certified check (:func:`steer_to_pairs` and
#: ``Env.steer_to(check="certified")`` alike): its program is large and costly to
#: compile, so every caller shares this one shape per (robot, map, padding); a call
#: checks a thousand motions, so the chunk's dispatch is a negligible share of it.
CERTIFIED_CHUNK = 1024
CHECK_CHUNK = 2048  # states per compiled call of valid_states / distances


@functools.partial(_kernel_jit, static_argnames=("robot", "padding", "check"))
def _steer_masked(robot, world: World, a: Array, b: Array, mask: Array, padding: float,
                  check: str) -> Array:
    return steer_to_cm(robot, world, a.T, b.T, padding, mask=mask, check=check)


def steer_to_pairs(robot, world: World, a, b, padding: float,
                   chunk: int | None = None, check: str = "discretized") -> np.ndarray:
    """``steer_to`` over any number of ``(N, d)`` pairs in fixed-size compiled chunks.

    ``chunk``: pairs per compiled call; None = :data:`CERTIFIED_CHUNK` for the
    certified check, :data:`STEER_CHUNK` for the discretised one. The answers do
    not depend on it.

    Returns ``(N,)`` bool (host), True where the straight connection is
    collision-free by the motion check ``check`` (see :func:`motion_check`).
    """
    motion_check(robot, check)  # an unknown check fails here, before any work
    if chunk is None:
        chunk = CERTIFIED_CHUNK if check == "certified" else STEER_CHUNK
    a = np.asarray(a, np.float32).reshape(-1, robot.dim)
    b = np.asarray(b, np.float32).reshape(-1, robot.dim)
    return map_chunks(lambda x, y, m: _steer_masked(robot, world, x, y, m, padding, check), a, b,
                      chunk=chunk, with_mask=True).astype(bool)


def valid_states(robot, world: World, states, padding: float,
                 chunk: int = CHECK_CHUNK) -> np.ndarray:
    """``is_valid`` over any number of ``(N, d)`` states in fixed-size compiled chunks."""
    states = np.asarray(states, np.float32).reshape(-1, robot.dim)
    return map_chunks(lambda x: is_valid_batch(robot, world, x, padding), states,
                      chunk=chunk).astype(bool)


def distances(robot, a, b, chunk: int = CHECK_CHUNK) -> np.ndarray:
    """The cost metric over any number of ``(N, d)`` pairs (float32 kernel, host array)."""
    a = np.asarray(a, np.float32).reshape(-1, robot.dim)
    b = np.asarray(b, np.float32).reshape(-1, robot.dim)
    return map_chunks(lambda x, y: distance_batch(robot, x, y), a, b, chunk=chunk,
                      empty=np.zeros(0, np.float32))


# ---------------------------------------------------------------------------
# NumPy input without a host-to-device copy
#
# On the CPU backend a float32 NumPy array whose data starts on a
# HOST_ALIGN-byte boundary is handed to XLA without a copy; any other array is
# copied first, which for large batches costs several times the kernel itself.
# Arrays from NumPy's allocator usually start 16 bytes past such a boundary, so
# the rows are split: the first ``k < HOST_HEAD`` rows and the last
# ``HOST_HEAD - k`` (small copies, in one ``(2 HOST_HEAD, d)`` edge array) and the
# ``N - HOST_HEAD`` rows between, which start on the boundary and are used in
# place. ``k`` is traced, so every alignment shares one compiled program per
# ``N``: one call evaluates both parts and puts the answers back in row order.

HOST_ALIGN = 64  # bytes
HOST_HEAD = 16  # rows: a row of 4*d bytes reaches the boundary within 16 rows
HOST_MIN_ROWS = 1 << 16  # smaller batches take the ordinary (copying) path
_CAST_CHUNK_ROWS = 1 << 16


def _aligned_empty(shape: tuple[int, ...], dtype=np.float32) -> np.ndarray:
    """An uninitialised C-contiguous array whose data starts on a HOST_ALIGN boundary."""
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    buf = np.empty(nbytes + HOST_ALIGN, np.uint8)
    off = -buf.ctypes.data % HOST_ALIGN
    return buf[off:off + nbytes].view(dtype).reshape(shape)


def host_rows(x, dim: int) -> np.ndarray | None:
    """``x`` as a C-contiguous float32 NumPy ``(N, dim)`` array for :func:`split_host_rows`.

    Returns ``x`` itself when it already is one, an aligned float32 copy of a
    NumPy float array of another dtype or layout (one pass, cast as
    ``jnp.asarray(x, jnp.float32)`` casts: round to nearest), and None for
    anything else (not a NumPy float array, another shape, or fewer than
    :data:`HOST_MIN_ROWS` rows): the caller's ordinary path handles those.
    """
    if (not isinstance(x, np.ndarray) or x.dtype.kind != "f" or x.dtype.itemsize > 8
            or x.ndim != 2 or x.shape[1] != dim or x.shape[0] < HOST_MIN_ROWS):
        return None
    if x.dtype == np.float32 and x.dtype.isnative and x.flags.c_contiguous:
        return x
    out = _aligned_empty(x.shape)
    for lo in range(0, x.shape[0], _CAST_CHUNK_ROWS):  # chunks stay in cache
        np.copyto(out[lo:lo + _CAST_CHUNK_ROWS], x[lo:lo + _CAST_CHUNK_ROWS], casting="unsafe")
    return out


def split_host_rows(arrays: list[np.ndarray]) -> tuple[Array, list[np.ndarray], list[Array]]:
    """Splits same-shape ``(N, d)`` float32 C-contiguous arrays (``N >= 2 HOST_HEAD``)
    for the ``*_split`` kernels.

    Returns ``(k, edges, bulks)``: ``k`` an int32 scalar in ``[0, HOST_HEAD)``;
    ``edges[i]`` a ``(2 HOST_HEAD, d)`` copy whose rows ``0..k-1`` are
    ``arrays[i][:k]`` and whose rows ``HOST_HEAD..2 HOST_HEAD - k - 1`` are the last
    ``HOST_HEAD - k`` rows of ``arrays[i]`` (the rest zero); ``bulks[i]`` is
    ``arrays[i][k:N - HOST_HEAD + k]`` on the device, sharing the NumPy memory when
    it is aligned. :func:`join_split` puts per-row answers back in row order.
    ``k`` is chosen so that every array's bulk is aligned when possible, else the
    first array's (the others are then copied by ``jax.device_put``). The bulks
    read the callers' memory in place: wait for the results before the arrays
    may change or be freed.
    """
    n, d = arrays[0].shape
    row = 4 * d

    def aligned_from(x, k):
        return (x.ctypes.data + k * row) % HOST_ALIGN == 0

    ks = range(min(HOST_HEAD, n))
    k = next((k for k in ks if all(aligned_from(x, k) for x in arrays)), None)
    if k is None:
        k = next((k for k in ks if aligned_from(arrays[0], k)), 0)
    end = n - HOST_HEAD + k
    edges = []
    for x in arrays:
        e = np.zeros((2 * HOST_HEAD, d), np.float32)
        e[:k] = x[:k]
        e[HOST_HEAD:2 * HOST_HEAD - k] = x[end:]
        edges.append(e)
    bulks = [jax.device_put(x[k:end], may_alias=True) for x in arrays]
    return np.int32(k), edges, bulks


def join_split(edge: Array, bulk: Array, k: Array) -> Array:
    """Per-row answers of :func:`split_host_rows`' parts (``edge`` ``(2 HOST_HEAD,)``,
    ``bulk`` ``(N - HOST_HEAD,)``) in the rows' order, ``(N,)``."""
    full = jax.numpy.concatenate([edge[:HOST_HEAD], bulk, edge[HOST_HEAD:]])
    i = jax.numpy.arange(bulk.shape[0] + HOST_HEAD, dtype=jax.numpy.int32)
    return full[jax.numpy.where(i < k, i, i + HOST_HEAD - k)]


@functools.partial(_kernel_jit, static_argnames=("robot", "padding", "check"))
def steer_to_batch_split(robot, world: World, edge_a: Array, edge_b: Array, bulk_a: Array,
                         bulk_b: Array, padding: float, k: Array,
                         check: str = "discretized") -> Array:
    """:func:`steer_to_batch` of the rows split by :func:`split_host_rows`, in row order."""
    steer = motion_check(robot, check)
    return join_split(steer(edge_a.T, edge_b.T, world, padding),
                      steer(bulk_a.T, bulk_b.T, world, padding), k)


@functools.partial(_kernel_jit, static_argnames=("robot", "padding"))
def is_valid_batch_split(robot, world: World, edge: Array, bulk: Array, padding: float,
                         k: Array) -> Array:
    """:func:`is_valid_batch` of the rows split by :func:`split_host_rows`, in row order."""
    return join_split(is_valid_cm(robot, world, edge.T, padding),
                      is_valid_cm(robot, world, bulk.T, padding), k)


@functools.partial(_kernel_jit, static_argnames=("robot",))
def distance_batch_split(robot, edge_a: Array, edge_b: Array, bulk_a: Array, bulk_b: Array,
                         k: Array) -> Array:
    """:func:`distance_batch` of the rows split by :func:`split_host_rows`, in row order."""
    dist = jax.vmap(robot.distance, in_axes=(1, 1))
    return join_split(dist(edge_a.T, edge_b.T), dist(bulk_a.T, bulk_b.T), k)
