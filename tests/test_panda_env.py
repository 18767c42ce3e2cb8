"""The Panda among MotionBenchMaker's scenes through the public Env (small batches)."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

import ntq_jax as nj
from ntq_jax.robots import SerialArm


@pytest.fixture(scope="module")
def cage():
    return nj.make_env("panda/cage/1")


def test_make_env_names_a_problem_with_its_query(cage):
    assert cage.dim == 7 and cage.robot == SerialArm.panda() and cage.padding == 0.0
    assert cage.query.shape == (2, 7) and cage.query.dtype == np.float32
    assert np.asarray(cage.is_valid(cage.query)).all()  # the benchmark's start and goal
    from ntq_jax.scenes import mbm

    p = mbm.load_problem("cage", 1)
    np.testing.assert_array_equal(cage.query, np.stack([p.start, p.goal]))
    assert nj.make_env("panda/cage/2").content_hash() != cage.content_hash()


@pytest.mark.parametrize(
    "name, words",
    [
        ("panda/cage", "'panda/<scene>/<number>'"),
        ("panda/cage/x", "'panda/<scene>/<number>'"),
        ("panda/cage/0", "from 1 to 100"),
        ("panda/kitchen/1", "unknown MotionBenchMaker scene"),
    ],
)
def test_bad_panda_names_are_one_line(name, words):
    with pytest.raises(nj.EnvError, match=words) as e:
        nj.make_env(name)
    assert "\n" not in str(e.value)


def test_json_round_trip_and_the_3d_form(cage, tmp_path):
    spec = cage.to_json()
    assert set(spec) == {
        "name",
        "robot",
        "bounds",
        "spheres",
        "cuboids",
        "capsules",
        "padding",
        "query",
    }
    assert spec["robot"] == {"kind": "serial_arm", "preset": "panda", "resolution": 1 / 32}
    path = tmp_path / "cage.json"
    path.write_text(json.dumps(spec))
    back = nj.make_env(str(path))
    assert back.content_hash() == cage.content_hash()
    np.testing.assert_array_equal(back.query, cage.query)
    small = {
        "name": "one-box",
        "robot": {"kind": "serial_arm", "preset": "panda"},
        "bounds": [[-1, 1], [-1, 1], [0, 2]],
        "cuboids": [
            {"center": [0.5, 0, 0.3], "half_extents": [0.05, 0.3, 0.3], "quat_xyzw": [0, 0, 0, 1]}
        ],
    }
    env = nj.Env.from_json(small)
    assert env.world.num_cuboids == 1 and env.query is None


@pytest.mark.parametrize(
    "patch, words",
    [
        ({"robot": {"kind": "point"}}, "needs a 3-D robot"),
        ({"robot": {"kind": "serial_arm", "preset": "ur5"}}, "preset 'ur5' is unknown"),
        ({"robot": {"kind": "serial_arm"}}, "needs 'preset' or 'urdf'"),
        ({"spheres": [[0, 0, 1]]}, "spheres"),
        ({"query": [[0] * 7]}, "query must be two rows"),
        ({"query": [[0] * 6, [0] * 6]}, "query"),
        ({"boxes": []}, "unknown key"),
    ],
)
def test_bad_3d_json_is_one_line(patch, words):
    spec = {
        "name": "x",
        "robot": {"kind": "serial_arm", "preset": "panda"},
        "bounds": [[-1, 1], [-1, 1], [0, 2]],
        "spheres": [[0.5, 0, 0.5, 0.1]],
        **patch,
    }
    with pytest.raises(nj.EnvError, match=words) as e:
        nj.Env.from_json(spec)
    assert "\n" not in str(e.value)


def test_planar_only_calls_refuse_a_3d_world(cage):
    with pytest.raises(nj.EnvError, match="planar"):
        cage.rasterize(0.1)


def test_checks_match_the_robot_kernels(cage):
    """is_valid equals the one-state kernel; the discretised steer_to equals checking every
    state ``k / n`` (n = ceil(distance / resolution)) with it."""
    rng = np.random.default_rng(0)
    lo, hi = (np.asarray(v) for v in cage.robot.config_bounds(cage.world))
    raw = (lo + rng.random((1024, 7)) * (hi - lo)).astype(np.float32)
    valid = jax.jit(jax.vmap(cage.robot.is_valid, in_axes=(0, None, None)), static_argnums=2)
    ok = np.asarray(valid(raw, cage.world, 0.0))
    np.testing.assert_array_equal(np.asarray(cage.is_valid(raw)), ok)
    assert 0.2 < ok.mean() < 0.95
    s = raw[ok][:40]
    a, b = s[:20], s[20:] * 0.2 + s[:20] * 0.8  # short motions: some free, some blocked
    states, owner = [], []
    for i, (x, y) in enumerate(zip(a, b)):
        n = max(int(np.ceil(np.linalg.norm(y - x) / cage.robot.resolution)), 1)
        t = (np.arange(n + 1, dtype=np.float32) / np.float32(n))[:, None]
        states.append(x + t * (y - x))
        owner += [i] * (n + 1)
    states = np.concatenate(states)
    pad = np.repeat(states[:1], -len(states) % 1024, axis=0)  # one compiled shape per 1024
    ok = np.asarray(valid(np.concatenate([states, pad]), cage.world, 0.0))[: len(states)]
    want = [bool(ok[np.asarray(owner) == i].all()) for i in range(len(a))]
    got = np.asarray(cage.steer_to(a, b))
    np.testing.assert_array_equal(got, want)
    assert 0 < got.sum() < len(got)
