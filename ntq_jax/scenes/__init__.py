"""3-D planning scenes (re-exports only): MoveIt YAML import and MotionBenchMaker's problems.

* :mod:`~ntq_jax.scenes.moveit`: MoveIt planning scenes -> :class:`~ntq_jax.geometry.World3D`,
  motion-plan requests -> start and goal joint vectors;
* :mod:`~ntq_jax.scenes.mbm`: MotionBenchMaker's 7 Panda scenes x 100 problems.
"""

from ntq_jax.scenes.mbm import JOINT_NAMES, NUMBERS, SCENES, MBMProblem, load_problem, load_scene
from ntq_jax.scenes.moveit import (
    MoveItRequest,
    MoveItScene,
    SceneFormatError,
    parse_request,
    parse_scene,
    read_request,
    read_scene,
)

__all__ = [
    "SCENES",
    "NUMBERS",
    "JOINT_NAMES",
    "MBMProblem",
    "load_problem",
    "load_scene",
    "MoveItScene",
    "MoveItRequest",
    "SceneFormatError",
    "parse_scene",
    "parse_request",
    "read_scene",
    "read_request",
]
