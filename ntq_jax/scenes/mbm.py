"""MotionBenchMaker's Panda problems: 7 scenes x 100 start/goal problems, as :class:`MBMProblem`.

The problems of MotionBenchMaker (Chamzas et al. 2022, Kavraki Lab) for the Franka
Panda, as shipped with VAMP (``ntq_jax/assets/panda/problems.tar.bz2``, see the
``NOTICE.md`` beside it): the archive holds ``problems/<scene>_panda/sceneNNNN.yaml`` (a
MoveIt planning scene) and ``requestNNNN.yaml`` (a MoveIt motion-plan request), numbered
``0001`` to ``0100`` in every scene. Problem ``number`` ``n`` (1 to 100, the files'
numbering) is the pair ``scene{n:04d}`` / ``request{n:04d}``.

Each problem is read with :mod:`ntq_jax.scenes.moveit`: the world's bounds are the
request's workspace box (``[-1, 1]^3`` in every problem), cylinders become capsules
except in the scene ``box``, where they become their bounding cuboids (VAMP's
conventions, so that results compare with its published MotionBenchMaker figures),
start and goal are the 7 arm joints :data:`JOINT_NAMES` (the finger joints of the
requests are ignored).

:func:`load_scene` reads the archive once per process and parses each scene once (all
700 problems in about a second); the problems are immutable (JAX arrays, tuples) and
shared between calls.
"""

from __future__ import annotations

import functools
import importlib.resources
import numbers
import re
import tarfile
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ntq_jax.geometry.world3d import World3D
from ntq_jax.scenes import moveit

Array = jax.Array

#: The scenes, in MotionBenchMaker's (alphabetical) order.
SCENES = (
    "bookshelf_small",
    "bookshelf_tall",
    "bookshelf_thin",
    "box",
    "cage",
    "table_pick",
    "table_under_pick",
)
#: The problem numbers of every scene (those of the archive's files).
NUMBERS = range(1, 101)
#: The Panda's arm joints, the order of :attr:`MBMProblem.start` and ``goal``.
JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))
#: The scene whose cylinders are read as cuboids (``cylinder_as="cuboid"``).
BOX_CONVENTION_SCENES = ("box",)

_ARCHIVE = "assets/panda/problems.tar.bz2"
_MEMBER = re.compile(r"problems/(\w+)_panda/(scene|request)(\d{4})\.yaml")


class MBMProblem(NamedTuple):
    """One MotionBenchMaker problem: a world, its obstacles' names, a start and a goal.

    Attributes:
        scene: one of :data:`SCENES`.
        number: the problem's number in its scene (1 to 100).
        world: the obstacles (bounds: the request's workspace box).
        names: one name per obstacle row (spheres, then cuboids, then capsules).
        start, goal: ``(7,)`` float32 joint positions, in the order of ``joint_names``.
        joint_names: :data:`JOINT_NAMES`.
    """

    scene: str
    number: int
    world: World3D
    names: tuple[str, ...]
    start: Array
    goal: Array
    joint_names: tuple[str, ...]


def archive_path():
    """The path (a ``Traversable``) of the problems' archive inside the installed package."""
    return importlib.resources.files("ntq_jax").joinpath(_ARCHIVE)


@functools.lru_cache(maxsize=1)
def _members() -> dict[tuple[str, str, int], bytes]:
    """The archive's YAML files by ``(scene, "scene" | "request", number)``."""
    out = {}
    with archive_path().open("rb") as raw, tarfile.open(fileobj=raw, mode="r:bz2") as tar:
        for m in tar:
            match = _MEMBER.fullmatch(m.name)
            if m.isfile() and match:
                scene, kind, number = match.group(1), match.group(2), int(match.group(3))
                out[(scene, kind, number)] = tar.extractfile(m).read()
    return out


def _check_scene(scene: str) -> str:
    if scene not in SCENES:
        raise ValueError(
            f"unknown MotionBenchMaker scene {scene!r}: expected one of {', '.join(SCENES)}"
        )
    return scene


@functools.lru_cache(maxsize=None)
def _scene(scene: str) -> tuple[MBMProblem, ...]:
    members = _members()
    cylinder_as = "cuboid" if scene in BOX_CONVENTION_SCENES else "capsule"
    problems = []
    for n in NUMBERS:
        src = {
            k: f"{_ARCHIVE}:problems/{scene}_panda/{k}{n:04d}.yaml" for k in ("scene", "request")
        }
        for kind, name in src.items():
            if (scene, kind, n) not in members:
                raise moveit.SceneFormatError(f"{name}: missing from the archive")
        req = moveit.parse_request(
            moveit.load_yaml(members[(scene, "request", n)], src["request"]),
            JOINT_NAMES,
            src["request"],
        )
        bounds = req.bounds if req.bounds is not None else moveit.DEFAULT_BOUNDS
        sc = moveit.parse_scene(
            moveit.load_yaml(members[(scene, "scene", n)], src["scene"]),
            src["scene"],
            bounds=bounds,
            cylinder_as=cylinder_as,
        )
        problems.append(
            MBMProblem(
                scene,
                n,
                sc.world,
                sc.names,
                jnp.asarray(req.start),
                jnp.asarray(req.goal),
                JOINT_NAMES,
            )
        )
    return tuple(problems)


def load_scene(scene: str) -> list[MBMProblem]:
    """The 100 problems of ``scene`` in number order (``[k]`` is number ``k + 1``).

    Raises:
        ValueError: ``scene`` is not one of :data:`SCENES`.
    """
    return list(_scene(_check_scene(scene)))


def load_problem(scene: str, number: int) -> MBMProblem:
    """Problem ``number`` (1 to 100) of ``scene``.

    Raises:
        ValueError: an unknown scene or number (the message names the valid ones).
    """
    _check_scene(scene)
    if (
        isinstance(number, bool)
        or not isinstance(number, numbers.Integral)
        or int(number) not in NUMBERS
    ):
        raise ValueError(
            f"MotionBenchMaker problem number must be an int from {NUMBERS[0]} "
            f"to {NUMBERS[-1]}, got {number!r}"
        )
    return _scene(scene)[int(number) - NUMBERS[0]]
