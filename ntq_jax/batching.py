"""Fixed shapes for jitted calls: bucket sizes, padding, and mapping over fixed-size chunks.

A jitted function compiles once per input shape. Everything that feeds a
variable number of rows to a compiled kernel goes through here, so that a
batch of any size reuses one program (fixed ``chunk`` rows, the tail padded
and masked) or one of a few (sizes rounded up to a power of two).
"""

from __future__ import annotations

from typing import Callable, Iterator, Sequence

import numpy as np

from ntq_jax.validation import check_count

__all__ = [
    "bucket_size",
    "fine_bucket_size",
    "pad_rows",
    "padded_chunks",
    "group_chunks",
    "map_chunks",
]


def bucket_size(n: int, minimum: int = 1) -> int:
    """The next power of two ``>= n`` (and ``>= minimum``); 1 for ``n <= 1``."""
    return max(int(minimum), 1 << (max(int(n), 1) - 1).bit_length())


def fine_bucket_size(n: int, minimum: int = 1) -> int:
    """The smallest ``4 * 2^k``, ``5 * 2^k``, ``6 * 2^k`` or ``7 * 2^k`` that is ``>= n`` (and
    ``>= minimum``): four sizes per power of two, so padding adds less than a quarter of
    ``n`` rows (``n >= 4``); powers of two are among them."""
    n = max(int(n), int(minimum), 1)
    if n <= 4:
        return n if n != 3 else 4
    top = 1 << ((n - 1).bit_length() - 3)  # the step between sizes in n's octave
    return -(-n // top) * top


def pad_rows(a: np.ndarray, rows: int, fill=0) -> np.ndarray:
    """``a`` with its first axis padded to ``rows`` with ``fill`` values (``a`` itself when
    it already has ``rows`` rows)."""
    a = np.asarray(a)
    n = a.shape[0]
    if n == rows:
        return a
    if n > rows:
        raise ValueError(f"cannot pad {n} rows down to {rows}")
    extra = np.full((rows - n,) + a.shape[1:], fill, a.dtype)
    return np.concatenate([a, extra])


def padded_chunks(
    arrays: Sequence[np.ndarray], chunk: int, fill=0
) -> Iterator[tuple[int, int, list[np.ndarray], np.ndarray]]:
    """Yields ``(lo, m, padded, mask)`` for consecutive row chunks of ``arrays``.

    ``padded`` are the rows ``lo:lo+m`` of every array padded to exactly
    ``chunk`` rows with ``fill``; ``mask`` ``(chunk,)``
    is True on the ``m`` real rows.
    """
    chunk = check_count("chunk", chunk, 1)
    n = np.asarray(arrays[0]).shape[0]
    for lo in range(0, n, chunk):
        m = min(chunk, n - lo)
        padded = [pad_rows(np.asarray(a)[lo : lo + m], chunk, fill) for a in arrays]
        mask = np.zeros(chunk, bool)
        mask[:m] = True
        yield lo, m, padded, mask


def group_chunks(
    groups: Sequence[np.ndarray], width: int
) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yields ``(lo, idx, mask)``: chunks of several groups side by side, ``width`` rows each.

    Chunk ``j`` holds the items ``lo:lo+width`` (``lo = j * width``) of every
    group, each padded to ``width`` with 0: ``idx`` ``(G*width,)`` is their
    concatenation (group-major) and ``mask`` is True on the real items. With one
    group this is :func:`padded_chunks` of that group. The chunks run until the
    longest group is exhausted (a shorter group's block is then all padding).
    """
    width = check_count("width", width, 1)
    n = max((len(g) for g in groups), default=0)
    for lo in range(0, n, width):
        parts = [np.asarray(g)[lo : lo + width] for g in groups]
        idx = np.concatenate([pad_rows(p, width) for p in parts])
        mask = np.concatenate([np.arange(width) < len(p) for p in parts])
        yield lo, idx, mask


def map_chunks(
    fn: Callable, *arrays: np.ndarray, chunk: int, fill=0, with_mask: bool = False, empty=None
):
    """``fn`` over the rows of ``arrays`` in fixed-size padded chunks, outputs concatenated.

    Args:
        fn: a row-wise function of ``chunk``-row arrays (``fn(*padded)`` or, with
            ``with_mask``, ``fn(*padded, mask)``) returning an array or a tuple of
            arrays with ``chunk`` leading rows.
        *arrays: ``(N, ...)`` inputs.
        chunk: rows per call (the one compiled shape).
        fill: padding of the tail (:func:`pad_rows`).
        with_mask: pass the ``(chunk,)`` bool mask of real rows as the last argument.
        empty: the result for ``N == 0`` (default a ``(0,)`` bool array).

    Returns:
        The outputs' first ``N`` rows, as NumPy (a tuple when ``fn`` returns one).
    """
    outs = []
    for _, m, padded, mask in padded_chunks(arrays, chunk, fill):
        out = fn(*padded, mask) if with_mask else fn(*padded)
        if isinstance(out, tuple):
            outs.append(tuple(np.asarray(o)[:m] for o in out))
        else:
            outs.append(np.asarray(out)[:m])
    if not outs:
        return np.zeros(0, bool) if empty is None else empty
    if isinstance(outs[0], tuple):
        return tuple(np.concatenate(parts) for parts in zip(*outs))
    return np.concatenate(outs)
