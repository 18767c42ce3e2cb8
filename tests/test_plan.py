"""The public entry point ``ntq_jax.plan``: contract, statuses, and A* quality vs the exact optimum.

Every returned path is re-checked here with ``env.steer_to`` (segment by
segment, in the travelled direction, at the planning padding), independently
of the planners' own verification.
"""

import math

import jax
import numpy as np
import pytest

import ntq_jax
from ntq_jax import Env, PlanResult, make_env, plan, register_planner
from ntq_jax.envs import BUCKET_MIN_ROWS
from ntq_jax.planners import PlanStatus, available_planners
from ntq_jax.planners.astar import _search_batch


@pytest.fixture(scope="module")
def point3():
    return make_env("point/3")


@pytest.fixture(scope="module")
def queries(point3):
    q, kind = point3.sample_queries(jax.random.PRNGKey(7), 96, 0.5)
    return np.asarray(q)


def assert_contract(env, q, res: PlanResult, padding):
    """Shapes, dtypes, exact endpoints, NaN padding, costs, and collision-freeness."""
    k, d = q.shape[0], env.dim
    assert isinstance(res, PlanResult)
    assert res.paths.dtype == np.float32 and res.paths.ndim == 3 and res.paths.shape[0] == k
    assert res.paths.shape[2] == d
    assert res.lengths.dtype == np.int32 and res.lengths.shape == (k,)
    assert res.costs.dtype == np.float64 and res.status.dtype == np.int8
    solved = res.status == PlanStatus.SOLVED
    assert np.all(res.lengths[solved] >= 2) and np.all(res.lengths[~solved] == 0)
    assert np.all(np.isinf(res.costs[~solved])) and np.all(np.isfinite(res.costs[solved]))
    assert np.all(np.isnan(res.paths[~solved]))
    idx = np.flatnonzero(solved)
    np.testing.assert_array_equal(res.paths[idx, 0], q[idx, 0])
    np.testing.assert_array_equal(res.paths[idx, res.lengths[idx] - 1], q[idx, 1])
    pad_mask = np.arange(res.paths.shape[1])[None, :] >= res.lengths[:, None]
    assert np.all(np.isnan(res.paths[pad_mask]))
    assert np.all(np.isfinite(res.paths[~pad_mask]))
    # independent re-check of every segment with the exact kernel, and of the costs
    a, b, owner = [], [], []
    for i in idx:
        p = res.paths[i, : res.lengths[i]]
        a.append(p[:-1]), b.append(p[1:]), owner.append(np.full(len(p) - 1, i))
    if idx.size:
        a, b, owner = np.concatenate(a), np.concatenate(b), np.concatenate(owner)
        # at least BUCKET_MIN_ROWS + 1 pairs (padded with a[0] -> a[0], answers dropped):
        # env.steer_to then runs its shared chunk program (steer_to_pairs'), already compiled
        # by the planners, instead of compiling a small-batch program per robot and map;
        # the same kernel per pair, and the answers do not depend on the route
        m = len(a)
        fill = np.repeat(a[:1], max(0, BUCKET_MIN_ROWS + 1 - m), axis=0)
        free = np.asarray(
            env.steer_to(np.concatenate([a, fill]), np.concatenate([b, fill]), padding=padding)
        )[:m]
        assert free.all(), f"blocked segments in queries {np.unique(owner[~free])}"
        seg = np.asarray(env.distance(a, b), np.float64)
        cost = np.bincount(owner, seg, minlength=k)[idx]
        np.testing.assert_allclose(res.costs[idx], cost, rtol=1e-5)


@pytest.mark.parametrize("planner", ["astar", "visgraph"])
@pytest.mark.parametrize("padding", [None, 0.0])
def test_paths_collision_free_with_exact_endpoints(point3, queries, planner, padding):
    res = plan(point3, queries, planner, padding=padding)
    assert_contract(point3, queries, res, point3.resolve_padding(padding))
    # every preset query is valid at the data-generation padding (so also at 0) and solvable
    assert res.solved.mean() >= 0.98, np.bincount(res.status, minlength=4)


def test_smoothed_astar_vs_exact_optimum(point3, queries):
    """At padding 0 the visibility graph is the optimum: A* + smoothing never beats it, and is close."""
    vis = plan(point3, queries, "visgraph", padding=0.0)
    ast = plan(point3, queries, "astar", padding=0.0)
    both = vis.solved & ast.solved
    assert both.mean() > 0.95
    eps_bound = 2 * math.sqrt(2) * 1e-3 * (vis.lengths[both] - 2)  # visgraph's documented slack
    ratio = ast.costs[both] / vis.costs[both]
    assert np.all(ast.costs[both] >= vis.costs[both] - eps_bound - 1e-6)
    assert np.mean(ratio) < 1.02 and np.percentile(ratio, 90) < 1.05 and ratio.max() < 1.12, (
        np.mean(ratio),
        np.percentile(ratio, 90),
        ratio.max(),
    )
    # straight queries (visible start -> goal) come back as the straight segment
    direct = both & (vis.lengths == 2)
    np.testing.assert_array_equal(ast.lengths[direct], 2)


def wall_env():
    """point/3-sized map (9 boxes, so compiled kernels are shared) with a wall splitting it."""
    boxes = (
        [[10.0, 10.0, 0.5, 10.5]]
        + [[1.5 + 2 * i, 1.0, 0.2, 0.2] for i in range(4)]
        + [[12.5 + 2 * i, 19.0, 0.2, 0.2] for i in range(4)]
    )
    return Env.from_json(
        {
            "name": "wall",
            "robot": {"kind": "point"},
            "bounds": [[0, 20], [0, 20]],
            "boxes": boxes,
            "padding": 0.8,
        }
    )


@pytest.mark.parametrize("planner", ["astar", "visgraph"])
def test_invalid_and_unreachable_queries_are_statuses_not_exceptions(planner):
    env = wall_env()
    q = np.array(
        [
            [[5, 10], [15, 10]],  # across the wall: no path
            [[10, 10], [15, 10]],  # start inside the wall
            [[5, 10], [np.nan, 3]],  # NaN goal
            [[-1, 10], [5, 12]],  # start out of bounds
            [[5, 10], [9.2, 5]],  # goal within the padding (0.8) of the wall
            [[3, 5], [6, 15]],  # solvable
            [[4, 4], [4, 4]],
        ],  # start == goal
        np.float32,
    )
    res = plan(env, q, planner)
    S, N, I = PlanStatus.SOLVED, PlanStatus.NO_PATH, PlanStatus.INVALID
    assert res.status.tolist() == [N, I, I, I, I, S, S]
    assert_contract(env, q, res, env.padding)
    assert res.costs[6] == 0.0
    np.testing.assert_allclose(res.costs[5], np.hypot(3, 10), rtol=1e-6)


def test_bitstar_adapter_statuses():
    env = make_env("point/3")
    q = np.array([[[1, 1], [19, 19]], [[10, 10], [1, 1]]], np.float32)
    bad = ~np.asarray(env.is_valid(q.reshape(-1, 2))).reshape(2, 2).all(1)
    q = q[np.argsort(~bad)]  # the invalid one first if there is one
    res = plan(env, q, "bitstar", time_budget=0.5, workers=1, stop_on_first=True)
    assert_contract(env, q, res, env.padding)
    assert set(res.status.tolist()) <= {PlanStatus.SOLVED, PlanStatus.TIMEOUT, PlanStatus.INVALID}
    assert "bitstar_status" in res.info
    if bad.any():
        assert res.status[0] == PlanStatus.INVALID


def test_bitstar_all_invalid_starts_no_worker():
    env = wall_env()
    q = np.array([[[10, 10], [3, 3]]], np.float32)
    res = plan(env, q, "bitstar", time_budget=0.2)
    assert res.status.tolist() == [PlanStatus.INVALID] and res.info["workers"] == 0


def test_two_link_arm_configuration_space_astar():
    env = make_env("nlink/2")
    q, _ = env.sample_queries(jax.random.PRNGKey(2), 24, 0.5)
    q = np.asarray(q)
    res = plan(env, q, "astar", resolution=0.1)
    assert_contract(env, q, res, env.padding)
    assert res.info["grid_shape"] == (63, 63)
    assert res.solved.mean() >= 0.75, np.bincount(res.status, minlength=4)


def test_unknown_planner_and_unsupported_robots():
    env = make_env("rigid/0")
    q = np.zeros((1, 2, 3), np.float32)
    with pytest.raises(ValueError, match="available: .*astar.*bitstar.*visgraph"):
        plan(env, q, "rrt_magic")
    with pytest.raises(ValueError, match="point robot only"):
        plan(env, q, "visgraph")
    with pytest.raises(ValueError, match="2-D configuration space"):
        plan(env, q, "astar")
    with pytest.raises(ValueError, match=r"queries must have shape \(K, 2, 3\)"):
        plan(env, np.zeros((4, 3)), "astar")


def test_register_custom_planner(point3):
    calls = {}

    def straight(env, q, *, padding, seed, scale=1.0):
        calls.update(padding=padding, seed=seed, scale=scale)
        k = len(q)
        return PlanResult(
            q.copy(),
            np.full(k, 2, np.int32),
            np.linalg.norm(q[:, 1] - q[:, 0], axis=1).astype(np.float64),
            np.zeros(k, np.int8),
            {},
        )

    register_planner("straight_test", straight)
    assert "straight_test" in available_planners()
    res = ntq_jax.plan(point3, np.zeros((3, 2, 2)), "straight_test", padding=0, seed=5, scale=2.0)
    assert calls == {"padding": 0.0, "seed": 5, "scale": 2.0}
    assert res.paths.shape == (3, 2, 2)
    with pytest.raises(TypeError):
        register_planner("bad", 3)


def test_no_recompilation_across_batch_sizes(point3, queries):
    from ntq_jax.planners.smoothing import shortcut
    from ntq_jax.robots.batch import _steer_masked, _steer_to_batch, is_valid_batch

    plan(point3, queries, "astar")
    fns = (_search_batch, _steer_masked, _steer_to_batch, is_valid_batch, shortcut)
    before = [f._cache_size() for f in fns]
    longest = int(np.argmax(plan(point3, queries, "astar", smooth=False).lengths))
    for k in (1, 17, 96):
        plan(point3, np.concatenate([queries[longest : longest + 1], queries[:k]]), "astar")
    assert [f._cache_size() for f in fns] == before


def test_planner_caches_are_bounded_and_do_not_keep_environments_alive():
    import gc
    import weakref

    from ntq_jax.planners import config_grid
    from ntq_jax.planners.env_cache import EnvCache

    env = wall_env()
    grid = config_grid(env, 0.1, 0.8)
    assert config_grid(env, 0.1, 0.8) is grid  # built once per (env, settings)
    q = np.array([[[3, 5], [6, 15]]], np.float32)
    assert plan(env, q, "astar").solved.all() and plan(env, q, "visgraph").solved.all()
    alive = weakref.ref(env)
    del env, grid
    gc.collect()
    assert alive() is None

    cache, built = EnvCache(per_env=2), []
    other = wall_env()
    for key in (1, 2, 1, 3, 1, 2):
        cache.get(other, key, lambda k=key: built.append(k) or k)
    assert built == [1, 2, 3, 2]  # at most 2 settings per env, least recently used dropped


@pytest.mark.parametrize(
    "name, planners",
    [("point/0", ["astar", "visgraph", "roadmap", "bitstar"]), ("rigid/0", ["roadmap", "bitstar"])],
)
def test_no_queries_give_an_empty_result_on_every_planner(name, planners):
    env = make_env(name)
    for p in planners:
        r = plan(
            env,
            np.zeros((0, 2, env.dim), np.float32),
            p,
            **({"milestones": 300} if p == "roadmap" else {}),
        )
        assert r.paths.shape[0] == r.lengths.shape[0] == r.costs.shape[0] == 0, p
        assert r.status.shape == (0,) and r.paths.shape[2] == env.dim, p
