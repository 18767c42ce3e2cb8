"""Planning for the Panda: the roadmap and bitree planners, the OMPL peer, the VAMP adapter.

Tiny on purpose (one MotionBenchMaker scene, a few queries); the figures are in
benchmarks/bench_panda_plan.py. Every SOLVED path must start and end exactly at its
query and pass the package's certified check segment by segment.
"""

import importlib.util

import jax
import numpy as np
import pytest

import ntq_jax as nj
from ntq_jax.planners import vamp_bridge
from ntq_jax.planners.verify import check_paths, finalize
from ntq_jax.types import PlanStatus

SCENE = "box"  # cuboids only: the cheapest programs to compile


@pytest.fixture(scope="module")
def box():
    return nj.make_env(f"panda/{SCENE}/1")


def _assert_paths(env, q, res, check):
    """Solved paths: the queries' exact ends, every segment free by ``check``, the costs."""
    for i in np.flatnonzero(res.solved):
        p = res.path(i)
        np.testing.assert_array_equal(p[0], q[i, 0])
        np.testing.assert_array_equal(p[-1], q[i, 1])
        assert np.asarray(env.steer_to(p[:-1], p[1:], check=check)).all()
        assert res.costs[i] == pytest.approx(
            float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()), rel=1e-5
        )


def test_roadmap_plans_panda_queries_with_certified_segments(box):
    q, _ = box.sample_queries(jax.random.key(3), 3, p_nt=1.0)
    q = np.concatenate([box.query[None], q]).astype(np.float32)
    res = nj.plan(box, q, "roadmap", check="certified", milestones=300, grow_rounds=0)
    assert res.info["edge_check"] == "discretized" and res.info["k"] == 10  # the arm's defaults
    assert res.solved.sum() >= 3
    _assert_paths(box, q, res, "certified")


def test_bitree_solves_the_problem_with_certified_segments(box):
    res = nj.plan(box, box.query[None], "bitree", check="certified")
    assert res.solved[0]
    _assert_paths(box, box.query[None], res, "certified")
    again = nj.plan(box, box.query[None], "bitree", check="certified")
    np.testing.assert_array_equal(again.paths, res.paths)  # same seed, same path


@pytest.mark.skipif(importlib.util.find_spec("ompl") is None, reason="needs ompl")
def test_ompl_rrtconnect_peer_on_two_problems():
    for number in (1, 2):
        env = nj.make_env(f"panda/{SCENE}/{number}")
        res = nj.plan(env, env.query[None], "rrtconnect", time_budget=20.0)
        assert res.solved[0], res.info
        assert res.info["range"] == 1.0 and res.info["n_motion_calls"] > 0
        _assert_paths(env, env.query[None], res, "discretized")


@pytest.mark.skipif(importlib.util.find_spec("ompl") is None, reason="needs ompl")
def test_bitstar_runs_in_process_on_the_serial_arm(box):
    q = box.query[None]
    res = nj.plan(box, q, "bitstar", time_budget=0.5)  # the arm's "bitstar" is "bitstar_jax"
    assert res.solved[0], res.info
    assert res.info["planner"] == "bitstar_jax" and res.info["n_motion_per_query"][0] > 0
    _assert_paths(box, q, res, "discretized")


def test_finalize_fallback_puts_back_what_a_failed_shortcut_skipped():
    env = nj.make_env("point/0")
    lo, hi = (np.asarray(v) for v in env.robot.config_bounds(env.world))
    rng = np.random.default_rng(0)
    pts = (lo + rng.random((3, 4096, 2)) * (hi - lo)).astype(np.float32)
    a, m, b = pts
    blocked = ~np.asarray(env.steer_to(a, b))
    detour = np.asarray(env.steer_to(a, m)) & np.asarray(env.steer_to(m, b))
    i = np.flatnonzero(blocked & detour)[0]  # a -> b blocked, a -> m -> b free
    j = np.flatnonzero(~blocked)[0]  # a free segment: nothing to repair
    q = np.stack([[a[i], b[i]], [a[j], b[j]]]).astype(np.float32)
    raw = np.stack([[a[i], m[i], b[i]], [a[j], b[j], [np.nan, np.nan]]]).astype(np.float32)
    status = np.full(2, PlanStatus.SOLVED, np.int8)
    info = {}
    res = finalize(
        q,
        q.copy(),
        np.array([2, 2]),
        status,
        info,
        env,
        env.padding,
        fallback=(raw, np.array([3, 2]), np.array([[0, 2], [0, 1]])),
    )
    assert res.solved.all() and info["repaired"] == 1 and info["rejected"] == 0
    np.testing.assert_array_equal(res.path(0), raw[0])
    np.testing.assert_array_equal(res.path(1), q[1])
    ok, _ = check_paths(env, res.paths, res.lengths, env.padding)
    assert ok.all()
    plain = finalize(q, q.copy(), np.array([2, 2]), status, {}, env, env.padding)
    assert not plain.solved[0] and plain.solved[1]


def test_cuboid_euler_xyz_rebuilds_the_rotation():
    def rot(axis, t):
        c, s = np.cos(t), np.sin(t)
        m = {
            "x": [[1, 0, 0], [0, c, -s], [0, s, c]],
            "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
            "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]],
        }[axis]
        return np.array(m)

    rng = np.random.default_rng(0)
    angles = list(rng.uniform(-np.pi, np.pi, (20, 3))) + [np.array([0.3, np.pi / 2, -0.2])]
    for rx, ry, rz in angles:
        r = rot("z", rz) @ rot("y", ry) @ rot("x", rx)
        ex, ey, ez = vamp_bridge.cuboid_euler_xyz(r)
        np.testing.assert_allclose(rot("z", ez) @ rot("y", ey) @ rot("x", ex), r, atol=1e-9)


def test_capsule_center_form_puts_the_ends_back():
    """VAMP's Cylinder(center, euler_xyz, r, length) has its ends at center +- length / 2
    R e_z, R = Rz Ry Rx: the form computed for a segment gives back its two ends."""
    rng = np.random.default_rng(1)
    ends = list(rng.normal(size=(20, 2, 3))) + [np.array([[0, 0, 0], [0, 0.0, -1]])]
    ends += [np.array([[0, 0, 0], [0, 1.0, 0]]), np.array([[1, 2, 3], [1, 2, 3.5]])]
    for a, b in ends:
        center, (rx, ry, rz), length = vamp_bridge.capsule_center_form(a, b)
        cx, sx, cy, sy = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry)
        axis = np.array([cx * sy, -sx, cx * cy])  # Rz(0) Ry(ry) Rx(rx) e_z
        assert rz == 0.0
        np.testing.assert_allclose(np.asarray(center) - length / 2 * axis, a, atol=1e-12)
        np.testing.assert_allclose(np.asarray(center) + length / 2 * axis, b, atol=1e-12)


@pytest.mark.skipif(
    importlib.util.find_spec("vamp") is None,
    reason="vamp is not installed (its build fetches sources from GitHub)",
)
def test_vamp_plans_the_problem_and_the_package_checks_it(box):
    res = nj.plan(box, box.query[None], "vamp")
    assert res.solved[0]
    _assert_paths(box, box.query[None], res, "discretized")


def test_vamp_missing_is_one_import_error_naming_the_build(box):
    if importlib.util.find_spec("vamp") is not None:
        pytest.skip("vamp is installed")
    with pytest.raises(ImportError, match="pip install vamp-planner"):
        nj.plan(box, box.query[None], "vamp")


@pytest.mark.skipif(
    importlib.util.find_spec("vamp") is None,
    reason="vamp is not installed (its build fetches sources from GitHub)",
)
def test_vamp_environment_has_the_worlds_geometry():
    """VAMP's validity of states in the world vamp_environment builds (cuboids and capsules:
    table_pick) is the package's: the same spheres, the same obstacles."""
    import vamp

    env = nj.make_env("panda/table_pick/1")
    assert env.world.capsules.shape[0] > 0 and env.world.cuboids.shape[0] > 0
    venv = vamp_bridge.vamp_environment(env.world, vamp)
    lo, hi = (np.asarray(x) for x in env.robot.config_bounds())
    q = np.random.default_rng(2).uniform(lo, hi, (2000, 7)).astype(np.float32)
    ours = np.asarray(env.is_valid(q))
    theirs = np.array([vamp.panda.validate(x, venv) for x in q])
    assert 0.1 < ours.mean() < 0.9
    np.testing.assert_array_equal(theirs, ours)
