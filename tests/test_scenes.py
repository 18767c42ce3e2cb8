"""MoveIt scene/request import (``ntq_jax.scenes.moveit``) and MotionBenchMaker's problems.

A hand-written scene checks the pose composition (``pose @ primitive_pose``) and both
cylinder conventions against values worked out by hand; broken files must give one error
line naming the file, the object and the field. All 700 MotionBenchMaker problems are
loaded once (a module fixture) and their obstacle counts compared with a plain-text
count of the archive's files (no YAML parser).
"""

from __future__ import annotations

import math
import re
import tarfile

import numpy as np
import pytest

from ntq_jax.scenes import (
    JOINT_NAMES,
    SCENES,
    SceneFormatError,
    load_problem,
    load_scene,
    mbm,
    read_request,
    read_scene,
)

S = math.sqrt(0.5)

SCENE = """\
world:
  collision_objects:
    - id: shelf
      pose: {position: [1, 0, 0], orientation: [0, 0, %(s)r, %(s)r]}
      primitives:
        - type: box
          dimensions: [0.2, 0.4, 0.6]
      primitive_poses:
        - position: [0.5, 0, 0]
          orientation: [0, 0, 0, 1]
    - id: can
      primitives:
        - {type: cylinder, dimensions: [0.4, 0.05]}
      primitive_poses:
        - {position: [0, 0, 1], orientation: [%(s)r, 0, 0, %(s)r]}
    - id: ball
      pose:
        position: {x: 0, y: 0, z: 1}
        orientation: {x: 0, y: 0, z: 0, w: 1}
      primitives:
        - {type: sphere, dimensions: [0.1]}
      primitive_poses:
        - {position: [0, 0, 0.5], orientation: [0, 0, 0, 1]}
""" % {"s": S}

REQUEST = """\
start_state:
  joint_state:
    name: [j1, j2, j3, finger]
    position: [0.1, 0.2, 0.3, 0.04]
goal_constraints:
  - joint_constraints:
      - {joint_name: j3, position: -3}
      - {joint_name: j1, position: -1}
      - {joint_name: j2, position: -2}
workspace_parameters:
  min_corner: [-1, -2, -3]
  max_corner: [1, 2, 3]
"""


@pytest.fixture
def files(tmp_path):
    scene, request = tmp_path / "scene0001.yaml", tmp_path / "request0001.yaml"
    scene.write_text(SCENE)
    request.write_text(REQUEST)
    return scene, request


def test_hand_written_scene(files):
    sc = read_scene(files[0])
    w = sc.world
    assert (w.num_spheres, w.num_cuboids, w.num_capsules) == (1, 1, 1)
    assert sc.names == ("ball", "shelf", "can")  # spheres, cuboids, capsules
    np.testing.assert_allclose(w.spheres[0], [0, 0, 1.5, 0.1], atol=1e-7)
    # box: the pose turns 90 deg about z, then the primitive's offset +x becomes +y
    rz = [0, -1, 0, 1, 0, 0, 0, 0, 1]
    np.testing.assert_allclose(w.cuboids[0], [1, 0.5, 0, 0.1, 0.2, 0.3, *rz], atol=1e-6)
    # cylinder: turned 90 deg about x, its axis (local z) is world -y; capsule between caps
    np.testing.assert_allclose(w.capsules[0], [0, 0.2, 1, 0, -0.2, 1, 0.05], atol=1e-6)
    np.testing.assert_allclose(w.bounds, [[-1, 1]] * 3)


def test_box_convention_turns_cylinders_into_cuboids(files):
    sc = read_scene(files[0], cylinder_as="cuboid", bounds=[[0, 1], [0, 1], [0, 1]])
    w = sc.world
    assert (w.num_spheres, w.num_cuboids, w.num_capsules) == (1, 2, 0)
    assert sc.names == ("ball", "shelf", "can")
    rx = [1, 0, 0, 0, 0, -1, 0, 1, 0]
    np.testing.assert_allclose(w.cuboids[1], [0, 0, 1, 0.05, 0.05, 0.2, *rx], atol=1e-6)
    np.testing.assert_allclose(w.bounds, [[0, 1]] * 3)


def test_request_joints_in_the_callers_order(files):
    req = read_request(files[1], ["j2", "j1", "j3"])
    np.testing.assert_allclose(req.start, [0.2, 0.1, 0.3])
    np.testing.assert_allclose(req.goal, [-2, -1, -3])
    assert req.start.dtype == np.float32 and req.joint_names == ("j2", "j1", "j3")
    assert req.bounds == ((-1, 1), (-2, 2), (-3, 3))


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("type: sphere", "type: cone", "collision object 2 ('ball').primitives[0].type is 'cone'"),
        ("[0.2, 0.4, 0.6]", "[0.2, 0.4]", "collision object 0 ('shelf').primitives[0].dimensions"),
        ("[0.4, 0.05]", "[0.4, -0.05]", "('can').primitives[0].dimensions is [0.4, -0.05]"),
        (
            "      primitive_poses:\n        - position: [0.5, 0, 0]\n"
            "          orientation: [0, 0, 0, 1]\n",
            "",
            "('shelf'): missing field 'primitive_poses'",
        ),
        (
            "orientation: [0, 0, 0, 1]}",
            "orientation: [0, 0, 0, 2]}",
            "('ball').primitive_poses[0]"
            ".orientation is [0.0, 0.0, 0.0, 2.0]: expected a unit quaternion",
        ),
        ("position: {x: 0, y: 0, z: 1}", "position: {x: 0, y: 0}", "('ball').pose.position"),
        ("    - id: can\n", "    - idd: can\n", "collision object 1: missing field 'id'"),
        ("[0.1]}", "[0.1]", "not valid YAML"),
        ("world:", "wrld:", "missing field 'world'"),
    ],
)
def test_broken_scene_error_lines(files, old, new, message):
    assert old in SCENE
    files[0].write_text(SCENE.replace(old, new, 1))
    with pytest.raises(SceneFormatError) as e:
        read_scene(files[0])
    text = str(e.value)
    assert text.startswith(str(files[0])) and message in text and "\n" not in text, text


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            "name: [j1, j2, j3, finger]",
            "name: [j1, j2, j2, finger]",
            "start_state.joint_state: joint 'j2' appears 2 times",
        ),
        (
            "name: [j1, j2, j3, finger]",
            "name: [j1, j2, jx, finger]",
            "start_state.joint_state: joint 'j3' appears 0 times",
        ),
        (
            "{joint_name: j1, position: -1}",
            "{joint_name: j1, position: .nan}",
            "the goal position of 'j1' must be a finite number",
        ),
        (
            "{joint_name: j2, position: -2}",
            "{joint_name: j2}",
            "goal_constraints[0].joint_constraints[2]: missing field 'position'",
        ),
        ("max_corner: [1, 2, 3]", "max_corner: [1, 2, -3]", "workspace_parameters: min_corner"),
    ],
)
def test_broken_request_error_lines(files, old, new, message):
    files[1].write_text(REQUEST.replace(old, new, 1))
    with pytest.raises(SceneFormatError) as e:
        read_request(files[1], ["j1", "j2", "j3"])
    text = str(e.value)
    assert text.startswith(str(files[1])) and message in text and "\n" not in text, text


# ---------------------------------------------------------------------------
# MotionBenchMaker
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def problems():
    return {scene: load_scene(scene) for scene in SCENES}


@pytest.fixture(scope="module")
def raw_counts():
    """Per scene file: (objects, cylinders), counted in the archive's text without YAML."""
    out = {}
    with mbm.archive_path().open("rb") as raw, tarfile.open(fileobj=raw, mode="r:bz2") as tar:
        for m in tar:
            match = re.fullmatch(r"problems/(\w+)_panda/scene(\d+)\.yaml", m.name)
            if match:
                text = tar.extractfile(m).read().decode()
                out[(match.group(1), int(match.group(2)))] = (
                    len(re.findall(r"^\s*(?:- )?id: ", text, re.M)),
                    len(re.findall(r"type: cylinder", text)),
                )
    return out


def test_all_problems_load(problems, raw_counts):
    assert tuple(problems) == SCENES and len(raw_counts) == 700
    for scene, ps in problems.items():
        assert [p.number for p in ps] == list(range(1, 101))
        for p in ps:
            w = p.world
            objects, cylinders = raw_counts[(scene, p.number)]
            assert len(p.names) == w.num_obstacles == objects and 7 <= objects <= 21
            assert w.num_capsules == (0 if scene == "box" else cylinders)
            assert p.start.shape == p.goal.shape == (7,) and p.joint_names == JOINT_NAMES
            assert np.all(np.isfinite(p.start)) and np.all(np.isfinite(p.goal))
            np.testing.assert_array_equal(w.bounds, [[-1, 1]] * 3)
    # the "box" scene's can is a cuboid (the box convention); elsewhere cylinders are capsules
    box = problems["box"][0]
    assert box.names.count("Can1") == 1 and box.world.num_cuboids == 7
    assert sum(p.world.num_capsules for p in problems["bookshelf_thin"]) > 0


def test_one_request_against_its_text(problems):
    """Problem box/1's start and goal, read from the archive's text by hand."""
    ps = problems["box"][0]
    np.testing.assert_allclose(ps.start, [0, -0.785, 0, -2.356, 0, 1.571, 0.785], atol=1e-7)
    np.testing.assert_allclose(
        ps.goal,
        [
            0.4534448383669427,
            1.7628,
            0.1941262264518609,
            -0.8667848896139277,
            -0.3798524112731043,
            2.606927984171601,
            -0.1898611792470702,
        ],
        atol=1e-6,
    )


def test_load_problem_is_cached_and_checked(problems):
    assert load_problem("cage", 42) is problems["cage"][41]
    assert load_scene("cage")[0] is problems["cage"][0]
    with pytest.raises(ValueError, match="expected one of bookshelf_small, .*table_under_pick"):
        load_problem("shelf", 1)
    for bad in (0, 101, 1.0, True):
        with pytest.raises(ValueError, match="from 1 to 100"):
            load_problem("box", bad)
