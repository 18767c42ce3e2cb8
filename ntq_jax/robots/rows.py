"""Per-row kernels over any number of rows: full speed at every size, a handful of programs.

A jitted kernel compiles once per input shape, so the rows of a batch reach it
in pieces of a few sizes only (powers of two), and the pieces are read where
the rows already lie, never copied as a whole:

* On the CPU a float32 C-contiguous NumPy array, and the buffer of a JAX array,
  are host memory. :func:`host_rows` gives it as a NumPy array without a copy;
  a piece of it that starts on a :data:`HOST_ALIGN`-byte boundary is handed to
  XLA in place.
* :func:`plan_rows` splits ``N`` rows into in-place *pieces* (as many of
  ``piece_max`` rows as fit, then smaller powers of two down to ``piece_min``,
  the last one allowed to overlap the others by a few rows when that saves
  pieces) and an *edge*: the fewer than ``piece_min`` rows left at the end,
  plus the up to :data:`HOST_HEAD` rows before the first aligned one, copied into one small array
  padded to a power of two.
* :func:`run_rows` calls the kernel on every piece and on the edge (the calls
  are dispatched asynchronously, so they overlap) and joins the per-row answers
  in row order: one trivial concatenation, or none when the batch is one piece.

A batch of ``N`` rows therefore costs at most ``1.25 N`` rows of kernel work
(``N`` plus a quarter of the edge) and about ``N / piece_max + log2(piece_max /
piece_min) + 2`` dispatches; the kernel compiles once per piece size used and
once per edge bucket (64 rows up to about ``piece_min``). The answers do not
depend on the split: the kernels are per-row.
"""

from __future__ import annotations

import functools
import math
from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.batching import fine_bucket_size

Array = jax.Array

HOST_ALIGN = 64  # bytes: XLA's CPU client reads host memory in place from such a boundary
HOST_HEAD = 16  # rows: a float32 row of 4 d bytes reaches the boundary within 16 rows
MIN_BUCKET = 64  # rows: the smallest compiled size
PIECE_MIN = 1 << 13  # rows: the smallest in-place piece (fewer rows left go to the edge)
PIECE_MAX = 1 << 20  # rows: the largest compiled piece (larger batches run as several)
_CAST_CHUNK_ROWS = 1 << 16


class RowPlan(NamedTuple):
    """How :func:`run_rows` splits ``n`` rows (see the module docstring).

    Attributes:
        n: the number of rows.
        head: rows ``0 .. head - 1`` go to the edge (they precede the first aligned row).
        pieces: ``(start, size)`` of each in-place piece, consecutive from ``head``.
        tail: rows ``tail .. n - 1`` go to the edge, after the head rows (a piece may
            start before the previous one ends: the rows they share are taken from
            the earlier piece).
        bucket: the edge's padded size (0 when the edge is empty).
    """

    n: int
    head: int
    pieces: tuple[tuple[int, int], ...]
    tail: int
    bucket: int

    @property
    def edge_rows(self) -> int:
        return self.head + self.n - self.tail


def plan_rows(
    n: int,
    head: int = 0,
    piece_max: int = PIECE_MAX,
    piece_min: int = PIECE_MIN,
    min_bucket: int = MIN_BUCKET,
    period: int = 1,
    two_sizes: bool = False,
) -> RowPlan:
    """Splits ``n`` rows into in-place pieces from row ``head`` on, and an edge.

    Pieces (``piece_max`` and ``piece_min`` powers of two, or equal): as many of
    ``piece_max`` rows as fit; then, while at least ``piece_min`` rows are left,
    either one last piece of the power of two just above what is left, when that
    is less than a quarter more and fits before the end of the batch (it then
    starts earlier, overlapping the previous pieces, at a row ``head + j *
    period``: the rows aligned like ``head``), or a piece of the power of two just
    below. The rest (fewer than ``piece_min`` rows, and the ``head`` rows) is the
    edge, padded to :func:`~ntq_jax.batching.fine_bucket_size` (at least
    ``min_bucket``). A batch with fewer than ``head + piece_min`` rows is all edge.
    ``two_sizes``: pieces of ``piece_max`` and then of ``piece_min`` rows only (no
    sizes between, no overlap): two compiled shapes with ``min_bucket = piece_min``.
    """
    if n - head < piece_min:  # all edge (an empty batch: one bucket of padding, no rows)
        return RowPlan(n, 0, (), 0, fine_bucket_size(n, min_bucket))
    pieces, lo = [], head
    while n - lo >= piece_max:
        pieces.append((lo, piece_max))
        lo += piece_max
    while two_sizes and n - lo >= piece_min:
        pieces.append((lo, piece_min))
        lo += piece_min
    while n - lo >= piece_min:
        r = n - lo
        up = 1 << (r - 1).bit_length()
        start = head + (n - up - head) // period * period
        if 4 * up <= 5 * r and start >= head:
            pieces.append((start, up))
            lo = start + up
            break
        size = 1 << (r.bit_length() - 1)
        pieces.append((lo, size))
        lo += size
    edge = head + n - lo
    return RowPlan(n, head, tuple(pieces), lo, fine_bucket_size(edge, min_bucket) if edge else 0)


def aligned_period(x: np.ndarray) -> int:
    """Rows between consecutive :data:`HOST_ALIGN`-byte boundaries of ``x``'s rows (row
    ``k`` aligned implies row ``k + period`` aligned)."""
    row = x.strides[0]
    return HOST_ALIGN // math.gcd(HOST_ALIGN, row) if row > 0 else 1


def aligned_head(arrays: Sequence[np.ndarray]) -> int:
    """The first row ``k < HOST_HEAD`` at which every array's data lies on a
    :data:`HOST_ALIGN` boundary; else 0: some array's pieces are then copied by the
    jitted call whatever the start (as a bare call copies it), and starting at row 0
    keeps the pieces as few as the batch size allows (answers unchanged)."""
    n = arrays[0].shape[0]
    ks = range(min(HOST_HEAD, n))

    def aligned(x, k):
        return (x.ctypes.data + k * x.strides[0]) % HOST_ALIGN == 0

    return next((k for k in ks if all(aligned(x, k) for x in arrays)), 0)


def _aligned_empty(shape: tuple[int, ...], dtype=np.float32) -> np.ndarray:
    """An uninitialised C-contiguous array whose data starts on a HOST_ALIGN boundary."""
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    buf = np.empty(nbytes + HOST_ALIGN, np.uint8)
    off = -buf.ctypes.data % HOST_ALIGN
    return buf[off : off + nbytes].view(dtype).reshape(shape)


def on_host(x) -> bool:
    """Whether ``x`` is a concrete JAX array whose one buffer lies in host memory (CPU)."""
    if not isinstance(x, jax.Array) or isinstance(x, jax.core.Tracer):
        return False
    try:
        devices = x.devices()
    except Exception:  # a deleted or otherwise unreadable array: the caller's path reports it
        return False
    return len(devices) == 1 and next(iter(devices)).platform == "cpu"


def host_rows(x) -> np.ndarray | None:
    """``x`` as a C-contiguous float32 NumPy array, without a copy where it can be.

    A float32 C-contiguous NumPy array is returned itself and a CPU JAX array's
    buffer as a read-only view; a NumPy array of another float or integer dtype
    or layout, or a CPU JAX array of another dtype, is converted (one aligned
    copy, rounding to nearest as ``jnp.asarray(x, jnp.float32)`` does). Returns
    None for anything else (traced values, arrays on other devices): the caller
    runs those through the kernel directly.
    """
    if isinstance(x, jax.Array):
        if not on_host(x):
            return None
        if x.dtype != jnp.float32:
            x = jnp.asarray(x, jnp.float32)
        return np.asarray(x)
    if not isinstance(x, np.ndarray) or x.dtype.kind not in "fiu":
        return None
    if x.dtype == np.float32 and x.dtype.isnative and x.flags.c_contiguous:
        return x
    if x.ndim == 0 or x.size == 0:  # nothing to cast in chunks (and no rows to reshape)
        return np.ascontiguousarray(x, np.float32)
    out = _aligned_empty(x.shape)
    flat_in, flat_out = x.reshape(x.shape[0], -1), out.reshape(x.shape[0], -1)
    for lo in range(0, x.shape[0], _CAST_CHUNK_ROWS):  # chunks stay in cache
        np.copyto(
            flat_out[lo : lo + _CAST_CHUNK_ROWS],
            flat_in[lo : lo + _CAST_CHUNK_ROWS],
            casting="unsafe",
        )
    return out


@functools.lru_cache(maxsize=64)
def _all_rows(size: int) -> Array:
    """A ``(size,)`` all-True mask on the device (every row of a piece is real)."""
    return jnp.ones((size,), bool)


@functools.lru_cache(maxsize=256)
def _first_rows(n: int, size: int) -> Array:
    """A ``(size,)`` mask on the device, True on the first ``n`` rows (the real ones)."""
    return jnp.arange(size) < n


@functools.partial(jax.jit, static_argnames=("size",))
def _pad(xs: tuple[Array, ...], size: int) -> tuple[Array, ...]:
    """Each array padded with zero rows to ``size`` rows, on the device (one dispatch)."""
    return tuple(jnp.pad(x, ((0, size - x.shape[0]),) + ((0, 0),) * (x.ndim - 1)) for x in xs)


def _joined(concatenate, edge, pieces, head: int, tail: int, skips: tuple[int, ...]):
    """The answers in row order: the edge's head rows, the pieces (each without its first
    ``skips`` rows, shared with the previous piece), the edge's tail rows."""
    body = [p[k:] for p, k in zip(pieces, skips)]
    if edge is None:
        return concatenate(body)
    return concatenate([edge[:head], *body, edge[head : head + tail]])


@functools.partial(jax.jit, static_argnames=("head", "tail", "skips"))
def _join(
    edge: Array | None, pieces: tuple[Array, ...], head: int, tail: int, skips: tuple[int, ...]
) -> Array:
    """:func:`_joined` on the device, one compiled program per layout."""
    return _joined(jnp.concatenate, edge, pieces, head, tail, skips)


def _join_host(edge, pieces, head: int, tail: int, skips: tuple[int, ...]) -> np.ndarray:
    """:func:`_joined` on the host: the answers waited for, nothing compiled."""
    edge = None if edge is None else np.asarray(edge)
    return _joined(np.concatenate, edge, [np.asarray(p) for p in pieces], head, tail, skips)


@functools.partial(jax.jit, static_argnames=("n",))
def _first(x: Array, n: int) -> Array:
    return x[:n]


def run_rows(
    kernel: Callable[..., Array],
    arrays: Sequence[np.ndarray],
    plan: RowPlan,
    whole: Sequence[Array] | None = None,
    host: bool = False,
) -> Array | np.ndarray:
    """``kernel`` over the rows of ``arrays`` (host NumPy, same length) as ``plan`` splits them.

    ``kernel(*rows, mask)`` gets ``m``-row arrays (JAX or NumPy) and an ``(m,)``
    bool mask of the real rows (False on the edge's zero padding) and returns
    per-row answers ``(m, ...)``. ``whole``: the same rows as JAX arrays when
    the caller has them (``arrays`` are then their host views): a batch that is
    one piece, or all edge, is handed to the kernel as they are (padded on the
    device), without a host round trip.

    Returns the ``(n, ...)`` answers as a JAX array, without waiting for them:
    the pieces read ``arrays`` in place, so a caller that does not own them must
    wait (``block_until_ready``) before they may change. ``host=True``: as a NumPy
    array, waited for, the pieces joined and the edge's padding cut on the host (no
    compiled program per batch length for that).
    """
    n, m = plan.n, plan.bucket
    if (
        whole is not None
        and not plan.head
        and (plan.pieces == ((0, n),) or (not plan.pieces and m))
    ):
        if not m or m == n:  # one piece, or an edge of exactly a bucket: the whole batch
            out = kernel(*whole, _all_rows(n))
            return np.asarray(out) if host else out
        out = kernel(*_pad(tuple(whole), m), _first_rows(n, m))
        return np.asarray(out)[:n] if host else _first(out, n)
    join = _join_host if host else _join
    outs = [
        kernel(*[x[lo : lo + size] for x in arrays], _all_rows(size)) for lo, size in plan.pieces
    ]
    ends = [plan.head] + [lo + size for lo, size in plan.pieces]
    skips = tuple(max(0, end - lo) for end, (lo, _) in zip(ends, plan.pieces))
    if not m:
        if len(outs) == 1 and not host:
            return outs[0]
        return join(None, tuple(outs), 0, 0, skips)
    rows = plan.edge_rows
    edge_in = []
    for x in arrays:
        e = np.zeros((m,) + x.shape[1:], x.dtype)
        e[: plan.head] = x[: plan.head]
        e[plan.head : rows] = x[plan.tail :]
        edge_in.append(e)
    edge = kernel(*edge_in, _first_rows(rows, m))
    if not outs:
        if host:
            return np.asarray(edge)[:rows]
        return edge if rows == m else _first(edge, rows)
    return join(edge, tuple(outs), plan.head, n - plan.tail, skips)
