"""make_env: an environment by name (a preset, a Panda problem) or from a map file.

* ``make_env("point/0")``: a planar preset (:mod:`ntq_jax.presets`);
* ``make_env("panda/cage/1")``: MotionBenchMaker's problem 1 of the cage scene with the
  Panda (:func:`panda_env`);
* ``make_env("my_map.json")``: a JSON map (:meth:`Env.from_json`, planar or 3-D form);
* ``make_env("office.yaml", robot=..., padding=...)``: an occupancy grid (a ROS
  ``map_server`` YAML or a MovingAI ``.map``; :meth:`Env.from_grid`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ntq_jax.envs.env import PANDA_PREFIX, Env, EnvError
from ntq_jax.presets import PRESETS
from ntq_jax.robots import Robot

__all__ = ["make_env", "panda_env"]


def panda_env(name: str) -> Env:
    """``panda/<scene>/<number>``: MotionBenchMaker's problem ``number`` (1..100) of ``scene``
    (:data:`ntq_jax.scenes.mbm.SCENES`) with the Panda (:meth:`SerialArm.panda`), padding 0,
    the problem's start and goal as :attr:`Env.query`."""
    from ntq_jax.robots import SerialArm
    from ntq_jax.scenes import mbm

    parts = name[len(PANDA_PREFIX) :].split("/")
    if len(parts) != 2 or not parts[1].isdigit():
        raise EnvError(
            f"unknown environment {name!r}: a Panda problem is "
            f"'panda/<scene>/<number>', e.g. 'panda/cage/1' (scenes: "
            f"{', '.join(mbm.SCENES)}; numbers {mbm.NUMBERS[0]}..{mbm.NUMBERS[-1]})"
        )
    try:
        problem = mbm.load_problem(parts[0], int(parts[1]))
    except ValueError as e:
        raise EnvError(f"{name!r}: {e}") from None
    query = np.stack([np.asarray(problem.start), np.asarray(problem.goal)]).astype(np.float32)
    return Env(name, SerialArm.panda(), problem.world, 0.0, query=query)


def make_env(
    name_or_path: str | os.PathLike,
    *,
    robot: str | dict | Robot | None = None,
    padding: float | None = None,
    unknown: str = "occupied",
    scale: float | None = None,
) -> Env:
    """A preset by name (``point/0..3``, ``rigid/0..3``, ``nlink/2|4|6``), a JSON map file,
    or a grid map file (a ROS map ``.yaml``/``.yml`` or a MovingAI ``.map``).

    ``robot`` (a kind such as ``"rigid_body"``, a robot JSON dict or a Robot),
    ``padding``, ``unknown`` (ROS maps) and ``scale`` are for grid map files
    (default: the point robot, padding 0, unknown cells occupied, one unit per
    MovingAI cell); a JSON file that names a grid (``{"grid": ...}``) carries them
    itself. See :mod:`ntq_jax.grid_maps`.

    Raises:
        EnvError: unknown preset (listing the presets), unreadable or invalid file.
    """
    name = str(name_or_path)
    path = Path(name)
    grid_file = path.suffix.lower() in (".yaml", ".yml", ".map")
    if not grid_file and (
        robot is not None or padding is not None or scale is not None or unknown != "occupied"
    ):
        raise EnvError(
            f"{name!r}: robot, padding, unknown and scale are for grid map files "
            "(.yaml, .map); a preset or a JSON map carries its own"
        )
    if name in PRESETS:
        return Env.from_json(PRESETS[name], where=f"preset {name}")
    if name.startswith(PANDA_PREFIX) and not path.exists():
        return panda_env(name)
    if grid_file:
        if path.is_dir() or not path.is_file():
            raise EnvError(f"grid map file {name!r} does not exist")
        if isinstance(robot, str):  # a robot kind, as the command line takes it
            robot = {"kind": robot}
        if robot is not None and not isinstance(robot, dict) and not hasattr(robot, "is_valid"):
            raise EnvError(
                f"{name!r}: robot must be a kind (point, rigid_body, nlink), a robot "
                f"JSON dict or a Robot, got {type(robot).__name__}"
            )
        if path.suffix.lower() == ".map" and unknown != "occupied":
            raise EnvError(
                f"{name!r}: unknown={unknown!r} is for ROS maps; a MovingAI map has "
                "no unknown cells (its passable and blocked characters are fixed)"
            )
        return Env.from_grid(
            path, robot, 0.0 if padding is None else padding, unknown=unknown, scale=scale
        )
    if path.suffix.lower() == ".json" or path.exists():
        if path.is_dir():
            raise EnvError(f"environment file {name!r} is a directory, not a JSON map file")
        if not path.is_file():
            raise EnvError(f"environment file {name!r} does not exist")
        try:
            spec = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise EnvError(f"environment file {name!r} is not valid JSON: {e}") from None
        return Env.from_json(spec, where=f"environment file {name!r}", base_dir=path.parent)
    raise EnvError(
        f"unknown environment {name!r}: use a preset ({', '.join(PRESETS)}), "
        "a Panda problem ('panda/<scene>/<number>', e.g. 'panda/cage/1'), "
        "the path of a JSON map file, or a grid map (.yaml, .map)"
    )
