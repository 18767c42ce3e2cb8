"""Strict reading of user-given numbers: the rows of a map file, counts, probabilities, paddings.

Every check here is a pure function that returns the value it checked (as a
Python float, a tuple of floats or a float64 array) or raises ``ValueError``
with one line naming the key, the offending row and the expected form, e.g.
``boxes[2] is [1, 2, 3]: expected [cx, cy, half_w, half_h] (4 numbers)``.

A *number* is an int or float (Python or NumPy), never a bool and never a
string: JSON ``true`` is not 1, and ``"22"`` is not a list of two numbers.
Callers (:meth:`ntq_jax.envs.Env.from_json`, :meth:`ntq_jax.geometry.World.create`,
the robots' ``__post_init__``) turn the ``ValueError`` into their own error type.

The ``check_*`` functions are the argument checks of the library's public
functions (chunk sizes, query counts, probabilities, paddings, resolutions):
each returns the value as a Python ``int``/``float`` or raises ``TypeError``
(wrong kind: a bool, a string, a float where a count is due) or ``ValueError``
(out of range), with one line naming the argument and the accepted range.
"""

from __future__ import annotations

import math
import numbers
import operator
from typing import Any

import numpy as np

__all__ = [
    "is_number",
    "number",
    "number_list",
    "number_rows",
    "short_repr",
    "MAX_FLOAT32_MOVE",
    "check_float32",
    "check_count",
    "check_probability",
    "check_real",
    "check_padding",
    "check_positive",
]


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (with ``...``) for one-line messages."""
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def is_number(value: Any) -> bool:
    """True for int and float values (Python or NumPy scalars); False for bools, strings and the rest."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _finite(value: Any) -> float | None:
    """``value`` as a finite float, or None (not a number, NaN, infinite, too large for a float)."""
    if not is_number(value):
        return None
    try:
        v = float(value)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def number(value: Any, key: str, *, minimum: float | None = None, strict: bool = False) -> float:
    """``value`` as a finite float; ``minimum`` with ``strict`` means ``> minimum``, else ``>=``.

    Raises:
        ValueError: naming ``key``, the value and the expected form.
    """
    bound = "" if minimum is None else f" {'>' if strict else '>='} {minimum:g}"
    if not is_number(value):
        raise ValueError(
            f"{key} must be a number{bound}, got {short_repr(value)} ({type(value).__name__})"
        )
    v = _finite(value)
    if v is None or (minimum is not None and (v <= minimum if strict else v < minimum)):
        raise ValueError(f"{key} must be a finite number{bound}, got {short_repr(value)}")
    return v


def _is_sequence(value: Any) -> bool:
    """A list or tuple (or a 1-D+ NumPy array): what a JSON array becomes. Strings are not."""
    return isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim >= 1)


def number_list(
    value: Any, key: str, form: str, length: int | None = None, min_length: int = 0
) -> tuple[float, ...]:
    """A flat list of numbers (exactly ``length`` of them if given) as a tuple of floats.

    ``form`` is the expected form shown in the message (e.g. ``"[x, y]"``).

    Raises:
        ValueError: not a list (a string, null, a number), a wrong length, or an
        entry that is not a finite number; the message names ``key``, the entry and ``form``.
    """
    count = f"{length} numbers" if length is not None else f"at least {min_length} number(s)"
    if not _is_sequence(value):
        raise ValueError(
            f"{key} must be a list {form} ({count}), got {short_repr(value)}"
            f" ({type(value).__name__})"
        )
    items = list(value)
    if (length is not None and len(items) != length) or len(items) < min_length:
        raise ValueError(
            f"{key} is {short_repr(value)}: expected {form} ({count}), got {len(items)} entries"
        )
    out = []
    for i, v in enumerate(items):
        if _finite(v) is None:
            raise ValueError(
                f"{key}[{i}] is {short_repr(v)}: expected {form} with finite numbers ({count})"
            )
        out.append(float(v))
    return tuple(out)


def number_rows(value: Any, key: str, width: int, form: str) -> np.ndarray:
    """A list of rows of exactly ``width`` finite numbers, as a ``(R, width)`` float64 array.

    Accepts nested lists or tuples (the JSON form) and 2-D numeric NumPy or JAX
    arrays of ``width`` columns; an empty list or an array with no entries is
    ``(0, width)``. A flat list of numbers, a row of another width, a bool or a
    string entry, a non-finite entry and ``null`` are all refused: nothing is
    reshaped.

    Raises:
        ValueError: naming ``key``, the offending row (``key[i]``) and ``form``.
    """
    expected = f"a list of rows {form} ({width} numbers each)"
    if value is None:
        raise ValueError(f"{key} must be {expected} (or [] for none), got null")
    if (
        not isinstance(value, (list, tuple, np.ndarray))
        and hasattr(value, "__array__")
        and hasattr(value, "dtype")
    ):
        value = np.asarray(value)  # a JAX array
    if isinstance(value, np.ndarray):
        if value.size == 0:
            return np.zeros((0, width))
        if value.dtype.kind not in "iuf":
            raise ValueError(f"{key} must be {expected}, got an array of dtype {value.dtype}")
        if value.ndim != 2 or value.shape[1] != width:
            raise ValueError(f"{key} must be {expected}, got an array of shape {value.shape}")
        if not np.all(np.isfinite(value)):
            i = int(np.flatnonzero(~np.all(np.isfinite(value), axis=1))[0])
            raise ValueError(
                f"{key}[{i}] is {short_repr(value[i].tolist())}: expected {form} "
                "with finite numbers"
            )
        return value.astype(np.float64)
    if not isinstance(value, (list, tuple)):
        raise ValueError(
            f"{key} must be {expected}, got {short_repr(value)} ({type(value).__name__})"
        )
    rows = []
    for i, row in enumerate(value):
        if isinstance(row, np.ndarray):
            row = row.tolist()
        if not isinstance(row, (list, tuple)):
            raise ValueError(f"{key}[{i}] is {short_repr(row)}, not a row: expected {expected}")
        if len(row) != width:
            raise ValueError(
                f"{key}[{i}] is {short_repr(row)} ({len(row)} numbers): expected "
                f"{form} ({width} numbers)"
            )
        bad = [v for v in row if _finite(v) is None]
        if bad:
            raise ValueError(
                f"{key}[{i}] is {short_repr(row)}: {short_repr(bad[0])} is not a "
                f"finite number; expected {form}"
            )
        rows.append([float(v) for v in row])
    return np.asarray(rows, np.float64).reshape(-1, width)


# ---------------------------------------------------------------------------
# Arguments of the library's functions: counts, probabilities, paddings
# ---------------------------------------------------------------------------


def check_count(name: str, value, minimum: int = 0, maximum: int | None = None) -> int:
    """``value`` as a Python int in ``[minimum, maximum]``; TypeError / ValueError naming ``name``.

    Accepts Python and NumPy integers (and integer scalar arrays); refuses
    bools, floats (even whole ones: ``2.0`` is most likely a computed value
    that should have been rounded deliberately) and everything else.
    """
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an int >= {minimum}, got the bool {value!r}")
    try:
        v = operator.index(value)
    except TypeError:
        raise TypeError(
            f"{name} must be an int >= {minimum}, got {value!r} ({type(value).__name__})"
        ) from None
    if v < minimum:
        raise ValueError(f"{name} must be an int >= {minimum}, got {v}")
    if maximum is not None and v > maximum:
        raise ValueError(f"{name} must be an int in [{minimum}, {maximum:,}], got {v:,}")
    return int(v)


def check_probability(name: str, value) -> float:
    """``value`` as a float in ``[0, 1]``; TypeError / ValueError naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(
            f"{name} must be a number in [0, 1], got {value!r} ({type(value).__name__})"
        )
    if not 0.0 <= value <= 1.0:  # also refuses NaN
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}")
    return float(value)


def check_real(
    name: str, value, *, minimum: float = 0.0, inclusive: bool = False, maximum: float | None = None
) -> float:
    """``value`` as a finite float ``> minimum`` (``>=`` when ``inclusive``) and ``<= maximum``;
    TypeError (not a real number, or a bool) / ValueError (NaN, infinite, out of range)
    naming ``name`` and the range."""
    bound = f"{'>=' if inclusive else '>'} {minimum:g}"
    if maximum is not None:
        bound += f" and <= {maximum:g}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(
            f"{name} must be a finite number {bound}, got {value!r} ({type(value).__name__})"
        )
    v = float(value)
    ok = math.isfinite(v) and (v >= minimum if inclusive else v > minimum)
    if not ok or (maximum is not None and v > maximum):
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return v


def check_padding(padding, name: str = "padding") -> float:
    """``padding`` (or any distance named ``name``) as a finite float >= 0; never None here."""
    return check_real(name, padding, inclusive=True)


def check_positive(name: str, value) -> float:
    """``value`` as a finite float > 0 (a resolution, a cell size, a spacing)."""
    return check_real(name, value)


#: The largest move float32 rounding may give a map coordinate, as a fraction of the map's
#: size (its bounds' largest side): 1 ppm, e.g. 0.02 mm on a 20 m map. Coordinates up to
#: about 16 map sizes from the origin always pass (float32 keeps 24 bits).
MAX_FLOAT32_MOVE = 1e-6


def check_float32(rows: dict[str, Any]) -> None:
    """ValueError unless float32 (the worlds' coordinates) holds every number of ``rows``
    (key -> a map's rows, with ``"bounds"``): finite in float32 and moved by its rounding by
    at most :data:`MAX_FLOAT32_MOVE` times the map's size. Values that are not arrays of
    finite numbers are left to the full checks (they raise their own errors)."""
    arrays = {}
    with np.errstate(all="ignore"):
        for key, value in rows.items():
            try:
                a = np.asarray(value, np.float64)
            except (TypeError, ValueError, OverflowError):
                continue
            if a.dtype == np.float64 and a.size and np.isfinite(a).all():
                arrays[key] = a
        b = arrays.get("bounds")
        ok = b is not None and b.ndim == 2 and b.shape[1] == 2
        size = float(np.max(b[:, 1] - b[:, 0])) if ok else None
        for key, a in arrays.items():
            moved = np.abs(a.astype(np.float32).astype(np.float64) - a)
            limit = MAX_FLOAT32_MOVE * size if size and size > 0 else np.inf
            bad = np.argwhere(~(moved <= limit))
            if not len(bad):
                continue
            at = tuple(bad[0])
            where = key + "".join(f"[{i}]" for i in at)
            if not np.isfinite(np.float32(a[at])):
                raise ValueError(
                    f"{where} is {a[at]:g}, beyond float32's range (about "
                    "+-3.4e38) of the world's coordinates; use smaller units"
                )
            raise ValueError(
                f"{where} is {float(a[at])!r}, which float32 (the world's coordinates) "
                f"stores as {float(np.float32(a[at]))!r}: moved by {moved[at]:.3g}, "
                f"more than {MAX_FLOAT32_MOVE:g} of the map's size {size:g}; put the "
                "map near the origin (subtract an offset from every coordinate)"
            )
