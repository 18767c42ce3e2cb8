"""The roadmap planner: verified paths, near-optimal costs, bounded failure, caching, determinism.

Independent references: the exact visibility graph (point robot, padding 0) for
costs, shapely for collision-freedom of point paths, and the package's
``steer_to`` for the other robots.
"""

import time

import jax
import numpy as np
import pytest
from shapely.geometry import LineString
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

import ntq_jax as nj
from ntq_jax.planners import roadmap as R
from ntq_jax.planners import roadmap_build as RB
from ntq_jax.types import PlanStatus

M = 3000  # milestones: small roadmaps keep the tests fast


def _queries(env, n, seed=0, padding=None, p_nt=1.0):
    q, _ = env.sample_queries(jax.random.key(seed), n, p_nt=p_nt, padding=padding)
    return np.asarray(q)


def test_point_costs_near_the_visibility_graph_optimum_and_paths_collision_free():
    env = nj.make_env("point/3")
    q = _queries(env, 200, padding=0.0)
    res = nj.plan(env, q, "roadmap", padding=0.0, milestones=M)
    opt = nj.plan(env, q, "visgraph", padding=0.0)
    assert res.solved.mean() >= 0.98 and opt.solved.all()
    both = res.solved & opt.solved
    ratio = res.costs[both] / opt.costs[both]
    assert ratio.min() >= 1.0 - 1e-5  # never shorter than the optimum
    assert np.median(ratio) <= 1.03
    spec = env.to_json()
    obst = unary_union(
        [shapely_box(cx - hw, cy - hh, cx + hw, cy + hh) for cx, cy, hw, hh in spec["boxes"]]
    )
    for i in np.flatnonzero(res.solved)[:60]:
        p = res.path(i).astype(np.float64)
        assert np.array_equal(res.path(i)[0], q[i, 0]) and np.array_equal(res.path(i)[-1], q[i, 1])
        assert not LineString(p).intersects(obst)
        assert res.costs[i] == pytest.approx(
            np.linalg.norm(np.diff(p, axis=0), axis=1).sum(), rel=1e-6
        )


@pytest.mark.parametrize("name", ["rigid/0", "nlink/4"])
def test_every_path_passes_steer_to_at_the_planning_padding(name):
    env = nj.make_env(name)
    q = _queries(env, 40)
    res = nj.plan(env, q, "roadmap", milestones=M)
    assert res.solved.mean() >= 0.9
    for i in np.flatnonzero(res.solved):
        p = res.path(i)
        assert np.asarray(env.steer_to(p[:-1], p[1:])).all()
        cost = float(np.sum(np.asarray(env.distance(p[:-1], p[1:]), np.float64)))
        assert res.costs[i] == pytest.approx(cost, rel=1e-5)


def _walled_env():
    return nj.envs.Env.from_json(
        {
            "name": "split",
            "robot": {"kind": "point"},
            "bounds": [[0, 10], [0, 10]],
            "boxes": [[5, 5, 0.3, 5.5]],
            "discs": [],
            "padding": 0.2,
        }
    )


def test_split_map_crossing_queries_are_no_path_in_bounded_time():
    env = _walled_env()
    q = np.array([[[1, 5], [9, 5]], [[1, 1], [2, 9]], [[8, 2], [9, 9]]], np.float32)
    t0 = time.perf_counter()
    res = nj.plan(env, q, "roadmap", milestones=500, grow_rounds=2)
    assert time.perf_counter() - t0 < 120
    assert res.status.tolist() == [PlanStatus.NO_PATH, PlanStatus.SOLVED, PlanStatus.SOLVED]
    assert res.info["rounds"] == 3  # the crossing query went through every growth round


def test_invalid_queries_are_reported():
    env = nj.make_env("point/0")
    q = _queries(env, 3)
    q[1, 0] = np.nan
    q[2, 1] = env.to_json()["boxes"][0][:2]  # inside an obstacle
    res = nj.plan(env, q, "roadmap", milestones=500)
    assert res.status[1] == PlanStatus.INVALID and res.status[2] == PlanStatus.INVALID


def test_same_seed_same_paths_and_independent_of_the_batch():
    env = nj.make_env("rigid/1")
    q = _queries(env, 30, seed=3)
    a = nj.plan(env, q, "roadmap", milestones=M)
    RB._MEMORY.clear()
    b = nj.plan(env, q[::-1], "roadmap", milestones=M)  # rebuilt, other batch order
    c = nj.plan(env, q[:7], "roadmap", milestones=M)
    np.testing.assert_array_equal(a.status, b.status[::-1])
    np.testing.assert_array_equal(a.lengths, b.lengths[::-1])
    np.testing.assert_array_equal(a.paths[:, : a.lengths.max()], b.paths[::-1, : a.lengths.max()])
    np.testing.assert_array_equal(a.costs[:7], c.costs)
    d = nj.plan(env, q, "roadmap", milestones=M, roadmap_seed=1)
    assert not np.array_equal(np.nan_to_num(a.paths[:, :3]), np.nan_to_num(d.paths[:, :3]))


def test_roadmap_cache_reused_and_invalidated_when_the_map_changes(tmp_path):
    env = nj.make_env("point/2")
    q = _queries(env, 20)
    RB._MEMORY.clear()
    a = nj.plan(env, q, "roadmap", milestones=800, cache_dir=tmp_path)
    files = sorted(tmp_path.glob("roadmap_*.npz"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    RB._MEMORY.clear()
    b = nj.plan(env, q, "roadmap", milestones=800, cache_dir=tmp_path)  # read from disk
    assert files[0].stat().st_mtime_ns == stamp and len(list(tmp_path.glob("roadmap_*"))) == 1
    np.testing.assert_array_equal(a.costs, b.costs)
    spec = env.to_json()
    spec["boxes"][0][0] += 0.5  # another map: another roadmap
    moved = nj.envs.Env.from_json(spec)
    nj.plan(moved, q[:2], "roadmap", milestones=800, cache_dir=tmp_path)
    assert len(list(tmp_path.glob("roadmap_*.npz"))) == 2
    nj.plan(env, q[:2], "roadmap", milestones=800, padding=0.3, cache_dir=tmp_path)  # padding
    assert len(list(tmp_path.glob("roadmap_*.npz"))) == 3


def test_metric_index_matches_brute_force_under_the_rigid_metric():
    env = nj.make_env("rigid/0")
    pts = env.sample_states(jax.random.key(0), 400)
    x = env.sample_states(jax.random.key(1), 50)
    idx, dist = R.MetricIndex(env.robot, env.world, pts, oversample=4).query(x, 5)
    for i in range(len(x)):
        d = np.asarray(env.distance(np.repeat(x[i : i + 1], len(pts), 0), pts), np.float64)
        np.testing.assert_allclose(np.sort(d)[:5], dist[i], rtol=1e-6)


def test_bad_options_are_one_clear_error():
    env = nj.make_env("point/0")
    with pytest.raises(ValueError, match="roadmap: milestones must be an int >= 2"):
        nj.plan(env, _queries(env, 2), "roadmap", milestones=1)


def test_prm_star_k():
    assert R.prm_star_k(20_000, 3) == 36 and R.prm_star_k(20_000, 6) == 32


@pytest.mark.parametrize("n, per_node", [(1, 1), (2, 3), (7, 6), (500, 40)])
def test_undirected_pairs_equal_numpys_unique_rows(n, per_node):
    """The roadmap's edge list: NumPy's row-wise unique of the (min, max) pairs, self-loops
    dropped, in the same order and dtype."""
    rng = np.random.default_rng(n)
    i = np.repeat(np.arange(n), per_node)
    j = rng.integers(0, n, i.size)
    ref = np.unique(np.stack([np.minimum(i, j), np.maximum(i, j)], 1), axis=0)
    ref = ref[ref[:, 0] != ref[:, 1]]
    got = RB.undirected_pairs(i, j, n)
    assert got.dtype == ref.dtype and got.shape[1] == 2
    np.testing.assert_array_equal(got, ref)
