"""MoveIt planning scenes and motion-plan requests (YAML, MotionBenchMaker's format) as arrays.

Scenes (:func:`parse_scene`, :func:`read_scene`): ``world.collision_objects`` is a list
of objects, each with an ``id``, an optional ``pose`` and lists ``primitives`` and
``primitive_poses`` of the same length (one or more; every primitive becomes one
obstacle named by the object's ``id``). A pose is ``{position: [x, y, z], orientation:
[x, y, z, w]}`` (the ``{x: .., y: ..}`` mapping form is read too); the quaternion must
have norm within :data:`~ntq_jax.geometry.world3d.QUAT_TOL` of 1 and is normalised.
A primitive's world pose is ``pose @ primitive_pose`` (``pose`` absent: identity).
Primitive ``type`` and ``dimensions`` (all ``>= 0``):

* ``sphere`` ``[radius]``: a sphere;
* ``box`` ``[x, y, z]`` (full sizes): a cuboid with half extents ``[x, y, z] / 2``;
* ``cylinder`` ``[height, radius]`` (axis along the local z axis): with
  ``cylinder_as="capsule"`` (the default, VAMP's convention for MotionBenchMaker) the
  capsule around it, whose segment is the axis between the two cap centres and whose
  radius is the cylinder's; with ``cylinder_as="cuboid"`` its bounding cuboid, half
  extents ``[radius, radius, height / 2]`` in the cylinder's frame (VAMP's convention for
  MotionBenchMaker's ``box`` scene, where the capsule's rounded caps would block the
  top-down grasp of the can).

Anything else is refused: other primitive types (``cone``), non-empty ``meshes`` or
``planes``, an ``operation`` other than ADD, missing or malformed fields. Frames are
not resolved: every pose is taken in the planning frame (MotionBenchMaker's
``fixed_frame_transforms`` are the identity). The obstacles' names come back in the
:class:`~ntq_jax.geometry.World3D` row order: spheres, then cuboids, then capsules.

Requests (:func:`parse_request`, :func:`read_request`): the start is
``start_state.joint_state.{name, position}``, the goal
``goal_constraints[0].joint_constraints[*].{joint_name, position}`` (exactly one goal
constraint), both read for the joints the caller names, in the caller's order (other
joints, e.g. a gripper's fingers, are ignored). ``workspace_parameters.{min_corner,
max_corner}`` are the request's workspace bounds when present.

Every error is a :class:`SceneFormatError` (a ``ValueError``) of one line naming the
file, the object and the field.
"""

from __future__ import annotations

import os
from typing import Any, Literal, NamedTuple, Sequence

import numpy as np
import yaml

from ntq_jax import validation
from ntq_jax.geometry.world3d import QUAT_TOL, World3D, quat_to_matrix

try:  # the C loader is ~10x faster (700 MotionBenchMaker files in ~1 s instead of ~10 s)
    from yaml import CSafeLoader as _Loader
except ImportError:  # pragma: no cover - PyYAML without libyaml
    from yaml import SafeLoader as _Loader

#: The workspace box of a scene read without one: MotionBenchMaker's requests' ``[-1, 1]^3``.
DEFAULT_BOUNDS = ((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))

_DIMENSIONS = {
    "sphere": ("[radius]", 1),
    "box": ("[x, y, z]", 3),
    "cylinder": ("[height, radius]", 2),
}


class SceneFormatError(ValueError):
    """A MoveIt scene or request that cannot be read (one line: file, object, field)."""


class MoveItScene(NamedTuple):
    """A planning scene as arrays: ``world`` and one name per obstacle row.

    ``names`` follows the rows of ``world.spheres``, then ``world.cuboids``, then
    ``world.capsules``.
    """

    world: World3D
    names: tuple[str, ...]


class MoveItRequest(NamedTuple):
    """A motion-plan request: ``start`` and ``goal`` ``(n,)`` float32 for the caller's joints.

    ``bounds`` is the request's workspace box ``((xmin, xmax), ...)`` or None.
    """

    start: np.ndarray
    goal: np.ndarray
    joint_names: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...] | None


def load_yaml(text: str | bytes, source: str) -> Any:
    """The YAML document ``text`` (safe loader); a syntax error names ``source``."""
    try:
        return yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as e:
        raise SceneFormatError(f"{source}: not valid YAML ({' '.join(str(e).split())})") from None


def _read(path: str | os.PathLike) -> Any:
    with open(path, "rb") as f:
        return load_yaml(f.read(), os.fspath(path))


def _field(data: Any, key: str, where: str, kind: type | tuple[type, ...]) -> Any:
    if not isinstance(data, dict) or key not in data:
        raise SceneFormatError(f"{where}: missing field '{key}'")
    value = data[key]
    if not isinstance(value, kind):
        names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        raise SceneFormatError(
            f"{where}.{key} is {validation.short_repr(value)}: expected a {names}"
        )
    return value


def _vector(value: Any, where: str, names: str) -> tuple[float, ...]:
    """``[x, y, z(, w)]`` from a list or a ``{x: .., y: ..}`` mapping."""
    keys = names.strip("[]").split(", ")
    if isinstance(value, dict) and sorted(value) == sorted(keys):
        value = [value[k] for k in keys]
    try:
        return validation.number_list(value, where, names, len(keys))
    except ValueError as e:
        raise SceneFormatError(str(e)) from None


def _pose(value: Any, where: str) -> np.ndarray:
    """The ``(4, 4)`` float64 transform of a pose ``{position, orientation}``."""
    if not isinstance(value, dict):
        raise SceneFormatError(
            f"{where} is {validation.short_repr(value)}: expected a mapping "
            "{position: [x, y, z], orientation: [x, y, z, w]}"
        )
    p = _vector(_field(value, "position", where, (list, dict)), f"{where}.position", "[x, y, z]")
    q = _vector(
        _field(value, "orientation", where, (list, dict)), f"{where}.orientation", "[x, y, z, w]"
    )
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_TOL:
        raise SceneFormatError(
            f"{where}.orientation is {list(q)}: expected a unit quaternion "
            f"[x, y, z, w] (norm within {QUAT_TOL:g} of 1, got {norm:.6g})"
        )
    t = np.eye(4)
    t[:3, :3] = quat_to_matrix(q)
    t[:3, 3] = p
    return t


def _primitive(prim: Any, where: str) -> tuple[str, tuple[float, ...]]:
    kind = _field(prim, "type", where, str)
    if kind not in _DIMENSIONS:
        raise SceneFormatError(
            f"{where}.type is {kind!r}: expected one of "
            f"{sorted(_DIMENSIONS)} (other primitives are not supported)"
        )
    form, n = _DIMENSIONS[kind]
    dims = prim.get("dimensions")
    try:
        dims = validation.number_list(dims, f"{where}.dimensions", form, n)
    except ValueError as e:
        raise SceneFormatError(f"{e} for a {kind}") from None
    if min(dims) < 0:
        raise SceneFormatError(
            f"{where}.dimensions is {list(dims)}: expected {form} >= 0 for a {kind}"
        )
    return kind, dims


def parse_scene(
    data: Any,
    source: str = "<scene>",
    *,
    bounds: Sequence[Sequence[float]] = DEFAULT_BOUNDS,
    cylinder_as: Literal["capsule", "cuboid"] = "capsule",
) -> MoveItScene:
    """The :class:`MoveItScene` of a loaded MoveIt planning-scene YAML document.

    ``source`` names the file in error messages; ``bounds`` is the world's workspace box;
    ``cylinder_as`` is the cylinder convention (module docstring).

    Raises:
        SceneFormatError: one line naming ``source``, the object and the field.
        ValueError: ``cylinder_as`` or ``bounds`` is not valid.
    """
    if cylinder_as not in ("capsule", "cuboid"):
        raise ValueError(f"cylinder_as must be 'capsule' or 'cuboid', got {cylinder_as!r}")
    world = _field(data, "world", source, dict)
    objects = world.get("collision_objects", [])
    if objects is None:
        objects = []
    if not isinstance(objects, list):
        raise SceneFormatError(
            f"{source}: world.collision_objects is "
            f"{validation.short_repr(objects)}: expected a list"
        )
    rows = {"spheres": [], "cuboids": [], "capsules": []}
    names = {k: [] for k in rows}
    for i, obj in enumerate(objects):
        where = f"{source}: collision object {i}"
        if not isinstance(obj, dict):
            raise SceneFormatError(f"{where} is {validation.short_repr(obj)}: expected a mapping")
        name = obj.get("id")
        if not isinstance(name, str) or not name:
            raise SceneFormatError(f"{where}: missing field 'id' (a non-empty string)")
        where = f"{source}: collision object {i} ({name!r})"
        if obj.get("operation", 0) not in (0, "ADD", "add"):
            raise SceneFormatError(
                f"{where}.operation is {obj['operation']!r}: only ADD (0) is supported"
            )
        for key in ("meshes", "planes"):
            if obj.get(key):
                raise SceneFormatError(
                    f"{where}.{key} is not empty: only primitives (sphere, "
                    "box, cylinder) are supported"
                )
        base = _pose(obj["pose"], f"{where}.pose") if "pose" in obj else np.eye(4)
        prims = _field(obj, "primitives", where, list)
        poses = _field(obj, "primitive_poses", where, list)
        if not prims or len(poses) != len(prims):
            raise SceneFormatError(
                f"{where}: {len(prims)} primitives and {len(poses)} "
                "primitive_poses: expected the same number, at least one"
            )
        for j, (prim, pose) in enumerate(zip(prims, poses)):
            kind, dims = _primitive(prim, f"{where}.primitives[{j}]")
            t = base @ _pose(pose, f"{where}.primitive_poses[{j}]")
            c, r = t[:3, 3], t[:3, :3]
            if kind == "sphere":
                key, row = "spheres", [*c, dims[0]]
            elif kind == "box":
                key, row = "cuboids", [*c, *(0.5 * np.asarray(dims)), *r.ravel()]
            elif cylinder_as == "cuboid":
                key, row = "cuboids", [*c, dims[1], dims[1], 0.5 * dims[0], *r.ravel()]
            else:
                half_axis = 0.5 * dims[0] * r[:, 2]
                key, row = "capsules", [*(c - half_axis), *(c + half_axis), dims[1]]
            rows[key].append(row)
            names[key].append(name)
    try:
        w = World3D.create(bounds, rows["spheres"], rows["cuboids"], rows["capsules"])
    except ValueError as e:  # a rotation out of tolerance cannot happen; bounds can be wrong
        raise ValueError(f"{source}: {e}") from None
    return MoveItScene(w, tuple(names["spheres"] + names["cuboids"] + names["capsules"]))


def read_scene(
    path: str | os.PathLike,
    *,
    bounds: Sequence[Sequence[float]] = DEFAULT_BOUNDS,
    cylinder_as: Literal["capsule", "cuboid"] = "capsule",
) -> MoveItScene:
    """:func:`parse_scene` of the YAML file ``path``."""
    return parse_scene(_read(path), os.fspath(path), bounds=bounds, cylinder_as=cylinder_as)


def _joint_values(
    names: list, values: list, joint_names: Sequence[str], where: str, what: str
) -> np.ndarray:
    out = []
    for j in joint_names:
        hits = [k for k, n in enumerate(names) if n == j]
        if len(hits) != 1:
            raise SceneFormatError(
                f"{where}: joint {j!r} appears {len(hits)} times in the {what} (expected once)"
            )
        try:
            out.append(validation.number(values[hits[0]], f"{where}: the {what} position of {j!r}"))
        except ValueError as e:
            raise SceneFormatError(str(e)) from None
    return np.asarray(out, np.float32)


def parse_request(
    data: Any, joint_names: Sequence[str], source: str = "<request>"
) -> MoveItRequest:
    """The :class:`MoveItRequest` of a loaded MoveIt motion-plan request YAML document.

    Raises:
        SceneFormatError: one line naming ``source`` and the field (or the missing joint).
    """
    joint_names = tuple(joint_names)
    if not joint_names or not all(isinstance(j, str) for j in joint_names):
        raise ValueError(f"joint_names must be a non-empty list of strings, got {joint_names!r}")
    js = _field(
        _field(data, "start_state", source, dict), "joint_state", f"{source}: start_state", dict
    )
    where = f"{source}: start_state.joint_state"
    names, positions = _field(js, "name", where, list), _field(js, "position", where, list)
    if len(names) != len(positions):
        raise SceneFormatError(f"{where}: {len(names)} names and {len(positions)} positions")
    start = _joint_values(names, positions, joint_names, where, "start state")
    goals = _field(data, "goal_constraints", source, list)
    if len(goals) != 1:
        raise SceneFormatError(
            f"{source}: goal_constraints has {len(goals)} entries: expected exactly one"
        )
    where = f"{source}: goal_constraints[0]"
    constraints = _field(goals[0], "joint_constraints", where, list)
    gn, gp = [], []
    for k, c in enumerate(constraints):
        gn.append(_field(c, "joint_name", f"{where}.joint_constraints[{k}]", str))
        gp.append(_field(c, "position", f"{where}.joint_constraints[{k}]", (int, float)))
    goal = _joint_values(gn, gp, joint_names, f"{where}.joint_constraints", "goal")
    bounds = None
    ws = data.get("workspace_parameters")
    if ws is not None:
        where = f"{source}: workspace_parameters"
        lo = _vector(
            _field(ws, "min_corner", where, (list, dict)), f"{where}.min_corner", "[x, y, z]"
        )
        hi = _vector(
            _field(ws, "max_corner", where, (list, dict)), f"{where}.max_corner", "[x, y, z]"
        )
        if not all(a < b for a, b in zip(lo, hi)):
            raise SceneFormatError(
                f"{where}: min_corner {list(lo)} must be below max_corner {list(hi)} on every axis"
            )
        bounds = tuple(zip(lo, hi))
    return MoveItRequest(start, goal, joint_names, bounds)


def read_request(path: str | os.PathLike, joint_names: Sequence[str]) -> MoveItRequest:
    """:func:`parse_request` of the YAML file ``path``."""
    return parse_request(_read(path), joint_names, os.fspath(path))
