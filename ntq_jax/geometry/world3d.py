"""The 3-D world: obstacles as arrays (:class:`World3D`), and its JSON form.

Three primitive solids, each a closed set, stored as float32 rows:

* spheres ``[cx, cy, cz, r]``;
* cuboids (oriented boxes) ``[cx, cy, cz, hx, hy, hz, R00, R01, R02, R10, ..., R22]``:
  centre, half extents, and the row-major ``world_from_box`` rotation ``R`` (its
  columns are the box axes in the world frame, so a world point ``p`` has box
  coordinates ``R^T (p - c)``);
* capsules ``[ax, ay, az, bx, by, bz, r]``: every point within ``r`` of the segment
  ``a``-``b`` (a zero-length segment is a sphere).

``bounds`` ``[[xmin, xmax], [ymin, ymax], [zmin, zmax]]`` is the workspace box, used
for sampling and plots only: a robot is not required to stay inside it and the
clearance kernels (:mod:`ntq_jax.geometry.shapes3d`) ignore it.

Rotations: :meth:`World3D.create` accepts a matrix that is orthonormal within
:data:`ROTATION_TOL` with determinant +1 and stores its nearest rotation (the polar
factor, computed in float64), so the kernels always work in an orthonormal frame.

JSON (:meth:`World3D.to_json` / :meth:`World3D.from_json`): a dict with the keys
``"bounds"``, ``"spheres"``, ``"cuboids"`` and ``"capsules"`` (the last three may be
omitted for none). ``to_json`` writes every cuboid as its row of 15 numbers (lossless);
``from_json`` also reads a cuboid as ``{"center": [3], "half_extents": [3],
"quat_xyzw": [4]}`` (a unit quaternion within :data:`QUAT_TOL`, normalised before use;
ROS order x, y, z, w), which is how poses are written by hand.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import validation

Array = jax.Array

#: Largest entry of ``|R^T R - I|`` accepted for a cuboid's rotation.
ROTATION_TOL = 1e-4
#: Largest ``| |q| - 1 |`` accepted for a cuboid's quaternion in JSON.
QUAT_TOL = 1e-3

_SPHERE_FORM = "[cx, cy, cz, r]"
_CUBOID_FORM = "[cx, cy, cz, hx, hy, hz, R00, R01, R02, R10, R11, R12, R20, R21, R22]"
_CAPSULE_FORM = "[ax, ay, az, bx, by, bz, r]"
_KEYS = ("bounds", "spheres", "cuboids", "capsules")


def quat_to_matrix(quat_xyzw) -> np.ndarray:
    """The ``(3, 3)`` float64 rotation of the quaternion ``[x, y, z, w]`` (normalised first)."""
    q = np.asarray(quat_xyzw, np.float64)
    norm = np.linalg.norm(q)
    if not (q.shape == (4,) and np.isfinite(norm) and norm > 0):
        raise ValueError(
            f"a quaternion [x, y, z, w] must be 4 finite numbers, not all 0, got "
            f"{validation.short_repr(quat_xyzw)}"
        )
    x, y, z, w = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _nearest_rotation(r: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(r)
    return u @ vt


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class World3D:
    """A 3-D workspace with spheres, oriented cuboids and capsules (a pytree of arrays).

    Attributes:
        bounds: ``(3, 2)`` float32, ``[[xmin, xmax], [ymin, ymax], [zmin, zmax]]``.
        spheres: ``(S, 4)`` float32, ``[cx, cy, cz, r]`` per row.
        cuboids: ``(B, 15)`` float32, ``[cx, cy, cz, hx, hy, hz, R (row-major)]`` per row.
        capsules: ``(C, 7)`` float32, ``[ax, ay, az, bx, by, bz, r]`` per row.

    The row counts are static shapes of compiled kernels; the values are traced.
    """

    bounds: Array
    spheres: Array
    cuboids: Array
    capsules: Array

    @staticmethod
    def create(bounds, spheres=(), cuboids=(), capsules=()) -> "World3D":
        """Builds a World3D from nested sequences (or 2-D arrays), validating shapes and values.

        Strict: ``bounds`` is exactly three rows ``[min, max]`` with ``min < max``;
        every row has exactly its width (4, 15, 7) of finite numbers (bools and
        strings are refused, nothing is reshaped); radii and half extents are
        ``>= 0``; a cuboid's rotation is orthonormal within :data:`ROTATION_TOL` with
        determinant +1 (its nearest rotation is stored). ``[]`` means none.

        Raises:
            ValueError: one line naming the key, the row and the expected form.
        """
        b = validation.number_rows(bounds, "bounds", 2, "[min, max]")
        if b.shape != (3, 2):
            raise ValueError(
                "bounds must be [[xmin, xmax], [ymin, ymax], [zmin, zmax]] "
                f"(three rows), got {validation.short_repr(bounds)}"
            )
        for i, axis in enumerate("xyz"):
            if not b[i, 1] > b[i, 0]:
                raise ValueError(
                    f"bounds[{i}] is {b[i].tolist()}: expected [{axis}min, {axis}max] "
                    f"with {axis}min < {axis}max"
                )
        sp = validation.number_rows(spheres, "spheres", 4, _SPHERE_FORM)
        cu = validation.number_rows(cuboids, "cuboids", 15, _CUBOID_FORM)
        ca = validation.number_rows(capsules, "capsules", 7, _CAPSULE_FORM)
        for i in np.flatnonzero(sp[:, 3] < 0)[:1]:
            raise ValueError(
                f"spheres[{i}] is {sp[i].tolist()}: radius must be >= 0 (rows are {_SPHERE_FORM})"
            )
        for i in np.flatnonzero(ca[:, 6] < 0)[:1]:
            raise ValueError(
                f"capsules[{i}] is {ca[i].tolist()}: radius must be >= 0 (rows are {_CAPSULE_FORM})"
            )
        for i in np.flatnonzero(np.any(cu[:, 3:6] < 0, axis=1))[:1]:
            raise ValueError(
                f"cuboids[{i}] has half extents {cu[i, 3:6].tolist()}: they must "
                f"be >= 0 (rows are {_CUBOID_FORM})"
            )
        for i in range(cu.shape[0]):
            r = cu[i, 6:].reshape(3, 3)
            err = float(np.max(np.abs(r.T @ r - np.eye(3))))
            if err > ROTATION_TOL or np.linalg.det(r) <= 0:
                raise ValueError(
                    f"cuboids[{i}] has rotation {r.tolist()}: expected an orthonormal "
                    f"matrix (within {ROTATION_TOL:g}, max |R^T R - I| = {err:.3g}) "
                    f"with det +1 (det = {np.linalg.det(r):.4g})"
                )
            cu[i, 6:] = _nearest_rotation(r).ravel()
        return World3D(*(jnp.asarray(np.asarray(a, np.float32)) for a in (b, sp, cu, ca)))

    @property
    def num_spheres(self) -> int:
        return int(self.spheres.shape[0])

    @property
    def num_cuboids(self) -> int:
        return int(self.cuboids.shape[0])

    @property
    def num_capsules(self) -> int:
        return int(self.capsules.shape[0])

    @property
    def num_obstacles(self) -> int:
        return self.num_spheres + self.num_cuboids + self.num_capsules

    def to_json(self) -> dict[str, list]:
        """The JSON dict: every key of :data:`_KEYS` as a list of rows (cuboids as 15 numbers)."""
        return {k: np.asarray(getattr(self, k), np.float64).tolist() for k in _KEYS}

    @staticmethod
    def from_json(data: Any) -> "World3D":
        """The World3D of a JSON dict (see the module docstring for the cuboid forms).

        Raises:
            ValueError: one line naming the key (and row) at fault; unknown keys are refused.
        """
        if not isinstance(data, dict):
            raise ValueError(
                f"a World3D JSON must be a dict with keys {list(_KEYS)}, got {type(data).__name__}"
            )
        unknown = sorted(set(map(str, data)) - set(_KEYS))
        if unknown:
            raise ValueError(f"unknown World3D key(s) {unknown}: expected {list(_KEYS)}")
        if "bounds" not in data:
            raise ValueError(
                "a World3D JSON needs 'bounds' [[xmin, xmax], [ymin, ymax], [zmin, zmax]]"
            )
        cuboids = data.get("cuboids", [])
        if isinstance(cuboids, (list, tuple)):
            cuboids = [
                _cuboid_row(c, f"cuboids[{i}]") if isinstance(c, dict) else c
                for i, c in enumerate(cuboids)
            ]
        return World3D.create(
            data["bounds"], data.get("spheres", []), cuboids, data.get("capsules", [])
        )


def _cuboid_row(item: dict, key: str) -> list[float]:
    """A cuboid given as ``{"center", "half_extents", "quat_xyzw"}`` as its row of 15 numbers."""
    fields = ("center", "half_extents", "quat_xyzw")
    if sorted(item) != sorted(fields):
        raise ValueError(
            f"{key} has keys {sorted(map(str, item))}: expected exactly "
            f"{list(fields)} (or a row {_CUBOID_FORM})"
        )
    c = validation.number_list(item["center"], f"{key}.center", "[x, y, z]", 3)
    h = validation.number_list(item["half_extents"], f"{key}.half_extents", "[hx, hy, hz]", 3)
    q = validation.number_list(item["quat_xyzw"], f"{key}.quat_xyzw", "[x, y, z, w]", 4)
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_TOL:
        raise ValueError(
            f"{key}.quat_xyzw is {list(q)}: expected a unit quaternion (norm "
            f"within {QUAT_TOL:g} of 1, got {norm:.6g})"
        )
    return [*c, *h, *quat_to_matrix(q).ravel().tolist()]
