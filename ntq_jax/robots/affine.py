"""Python-level 3-vectors and 3x3 matrices whose entries are Python floats or traced scalars.

The serial arm's forward kinematics (:mod:`ntq_jax.robots.serial_arm`) is written with
these at trace time: an entry that is a Python float (a constant of the URDF) is folded
(``0 * x`` vanishes, ``1 * x`` is ``x``, constants multiply and add in Python), so the
traced program holds only the arithmetic that depends on the joint angles. Matrices
are nested lists ``[[r00, r01, r02], ...]``, vectors lists of three entries.
"""

from __future__ import annotations

__all__ = ["is_const", "mul", "add", "dot", "matmul", "matvec", "rows", "rotation"]


def is_const(x) -> bool:
    return isinstance(x, float)


def mul(a, b):
    if is_const(a) and is_const(b):
        return a * b
    if is_const(b):
        a, b = b, a
    if is_const(a):
        if a == 0.0:
            return 0.0
        if a == 1.0:
            return b
        if a == -1.0:
            return -b
    return a * b


def add(a, b):
    if is_const(a) and is_const(b):
        return a + b
    if is_const(a) and a == 0.0:
        return b
    if is_const(b) and b == 0.0:
        return a
    return a + b


def dot(xs, ys):
    out = 0.0
    for x, y in zip(xs, ys):
        out = add(out, mul(x, y))
    return out


def matmul(a, b):
    """``a b`` for 3x3 nested lists."""
    return [[dot(a[i], [b[m][j] for m in range(3)]) for j in range(3)] for i in range(3)]


def matvec(a, v):
    return [dot(a[i], v) for i in range(3)]


def rows(flat) -> list[list[float]]:
    return [[float(flat[3 * i + j]) for j in range(3)] for i in range(3)]


def rotation(axis, sin, cos):
    """Rotation by the angle ``(sin, cos)`` about the unit ``axis`` (Python floats)."""
    ux, uy, uz = axis
    if sum(1 for u in axis if u != 0.0) == 1:  # a coordinate axis: no (1 - cos) terms
        k = next(i for i, u in enumerate(axis) if u != 0.0)
        s = sin if axis[k] > 0 else -sin
        i, j = (k + 1) % 3, (k + 2) % 3
        r = [[0.0] * 3 for _ in range(3)]
        r[k][k] = 1.0
        r[i][i], r[j][j], r[i][j], r[j][i] = cos, cos, -s, s
        return r
    v = 1.0 - cos
    return [
        [cos + ux * ux * v, ux * uy * v - uz * sin, ux * uz * v + uy * sin],
        [uy * ux * v + uz * sin, cos + uy * uy * v, uy * uz * v - ux * sin],
        [uz * ux * v - uy * sin, uz * uy * v + ux * sin, cos + uz * uz * v],
    ]
