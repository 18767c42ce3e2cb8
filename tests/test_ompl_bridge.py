"""OMPL BIT* bridge: the NumPy checker is the JAX kernel, and BIT* batches are robust.

The planning tests spawn worker processes (``spawn``, ~1-3 s each to import
JAX and OMPL) and use short budgets with ``stop_on_first`` where possible; the
whole file runs in well under 90 s on the 2-core development machine.
"""

import importlib.util
import warnings

import numpy as np
import pytest

import ntq_jax as nj
from ntq_jax.planners import ompl_bridge
from ntq_jax.planners.ompl_bridge import PLAN_STATUS, BridgeOutcome, plan_bitstar, query_seeds
from ntq_jax.planners.ompl_checker import NumpyChecker
from ntq_jax.robots.batch import CHECK_CHUNK
from ntq_jax.types import PlanStatus

#: Candidate queries per draw in ``_easy_queries`` (and the row count of the test's own jitted
#: checks: one compilation).
POOL = 256

needs_ompl = pytest.mark.skipif(
    importlib.util.find_spec("ompl") is None, reason="the PyPI package ompl is not installed"
)

# A user map with discs (the presets have only boxes), for every robot kind.
_OBSTACLES = {
    "bounds": [[-10, 10], [-10, 10]],
    "boxes": [[5, 4, 1, 1], [-4, 5, 1.5, 0.5], [2, -6, 0.5, 2]],
    "discs": [[-5, -4, 1.2], [6, -3, 0.7], [0, 8, 1.0]],
}
CUSTOM = {
    "disc-rigid": {
        "name": "disc-rigid",
        "padding": 0.3,
        **_OBSTACLES,
        "robot": {"kind": "rigid_body", "length": 1.5, "width": 0.5},
    },
    "disc-arm": {
        "name": "disc-arm",
        "padding": 0.5,
        **_OBSTACLES,
        "robot": {"kind": "nlink", "link_lengths": [3, 2.5, 2], "base": [0.5, -0.5]},
    },
    "disc-point": {"name": "disc-point", "padding": 0.4, **_OBSTACLES, "robot": {"kind": "point"}},
}


def _env(name):
    return nj.Env.from_json(CUSTOM[name]) if name in CUSTOM else nj.make_env(name)


def _uniform_states(env, n, seed):
    lo, hi = (np.asarray(v, np.float64) for v in env.robot.config_bounds(env.world))
    rng = np.random.default_rng(seed)
    # a little outside the configuration box too (out-of-bounds states must agree as well)
    span = hi - lo
    return (lo - 0.02 * span + 1.04 * span * rng.random((n, env.dim))).astype(np.float32)


def _valid_states(env, n, seed):
    """``n`` valid states (rejection sampling with the NumPy checker, tested below)."""
    states = _uniform_states(env, 20 * n, seed)
    return states[NumpyChecker.from_env(env).is_valid_many(states)][:n]


def _near_tangency(env, state, padding, delta=1e-5):
    """True when the float64 result flips within ``delta`` of the padding or of the state."""
    hi = NumpyChecker.from_env(env, padding + delta).is_valid(state)
    if padding >= delta:
        return NumpyChecker.from_env(env, padding - delta).is_valid(state) != hi
    ch = NumpyChecker.from_env(env, padding)
    ref = ch.is_valid(state)
    rng = np.random.default_rng(0)
    x = np.asarray(state, np.float64)
    return hi != ref or any(
        ch.is_valid(x + delta * rng.uniform(-1, 1, x.shape)) != ref for _ in range(64)
    )


@pytest.mark.parametrize("name", ["rigid/0", "nlink/4", "disc-rigid", "disc-arm", "disc-point"])
def test_numpy_checker_equals_jax_is_valid(name):
    env = _env(name)
    states = _uniform_states(env, 10_000, seed=len(name))
    for padding in (env.padding, 0.0):
        # env.is_valid in slices of CHECK_CHUNK states: each runs the shared chunk program
        # (valid_states', which the planners run too) instead of one 16384-row bucket
        # program per robot, map and padding; the same kernel per state
        ref = np.concatenate(
            [
                np.asarray(env.is_valid(states[i : i + CHECK_CHUNK], padding=padding))
                for i in range(0, len(states), CHECK_CHUNK)
            ]
        )
        assert 0.05 < ref.mean() < 0.98, "the sample must contain valid and invalid states"
        ch = NumpyChecker.from_env(env, padding)
        one = np.array([ch.is_valid(s) for s in states.astype(np.float64)])
        many = ch.is_valid_many(states)
        for got in (one, many):
            bad = np.flatnonzero(got != ref)
            assert len(bad) <= 3, f"{name} padding {padding}: {len(bad)} disagreements"
            for i in bad:
                assert _near_tangency(env, states[i], padding), (name, padding, states[i])


def test_a_worker_process_does_not_load_jax(tmp_path):
    """What a spawned BIT* worker unpickles (its entry point and the checker) imports NumPy,
    not JAX: the package ``__init__`` modules load their names lazily. The public API still
    loads on first use."""
    import pickle
    import subprocess
    import sys

    from ntq_jax.planners.ompl_worker import worker_main

    payload = tmp_path / "payload.pkl"
    payload.write_bytes(pickle.dumps((worker_main, NumpyChecker.from_env(_env("nlink/4")))))
    code = (
        f"import pickle, sys; fn, ch = pickle.loads(open({str(payload)!r}, 'rb').read()); "
        "print(sorted(m for m in sys.modules if m == 'jax' or m.startswith('jax.'))[:3]); "
        "assert ch.dim == 4 and callable(fn); "
        "import ntq_jax; env = ntq_jax.make_env('point/0'); print('jax' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["[]", "True"], out.stdout


def test_numpy_checker_rejects_non_finite_states():
    for name in ("rigid/0", "nlink/4", "point/0"):
        env = _env(name)
        ch = NumpyChecker.from_env(env)
        good = _valid_states(env, 1, seed=0)[0].astype(np.float64)
        assert ch.is_valid(good)
        for bad_value in (np.nan, np.inf):
            s = good.copy()
            s[-1] = bad_value
            assert not ch.is_valid(s)
            assert not ch.is_valid_many(s[None]).any()
            assert not ch.steer_to(good, s)


@pytest.mark.parametrize("name", ["rigid/0", "nlink/4", "disc-point"])
def test_numpy_steer_to_equals_jax_steer_to(name):
    """The motion validator's edge check is the package's discretised steer_to."""
    env = _env(name)
    rng = np.random.default_rng(7)
    a = _valid_states(env, 1000, seed=1)
    lo, hi = (np.asarray(v) for v in env.robot.config_bounds(env.world))
    # short and long edges, some ending exactly on the configuration bounds; for SE(2)
    # angle differences across +-pi too (shortest arc)
    b = np.concatenate(
        [
            a[:500] + rng.normal(size=(500, env.dim)) * 0.05 * (hi - lo),
            _valid_states(env, 500, seed=2),
        ]
    )
    a, b = np.asarray(a, np.float32), np.clip(b, lo, hi).astype(np.float32)
    ref = np.asarray(env.steer_to(a, b))
    assert 0.05 < ref.mean() < 0.95
    ch = NumpyChecker.from_env(env)
    got = np.array([ch.steer_to(x, y) for x, y in zip(a.astype(np.float64), b.astype(np.float64))])
    assert (got != ref).sum() <= 2, f"{name}: {(got != ref).sum()} disagreements of {len(a)}"
    d = np.array([ch.distance(x, y) for x, y in zip(a, b)])
    np.testing.assert_allclose(d, np.asarray(env.distance(a, b)), rtol=1e-5, atol=1e-5)


def test_query_seeds_are_deterministic_and_positive():
    s = query_seeds(3, 50)
    assert s.dtype == np.uint32 and (s >= 1).all() and len(set(s.tolist())) == 50
    np.testing.assert_array_equal(s, query_seeds(3, 50))
    assert not np.array_equal(s, query_seeds(4, 50))


# ---------------------------------------------------------------------------
# Planning (worker processes)
# ---------------------------------------------------------------------------


def _easy_queries(env, n_trivial, n_short, seed):
    """Random valid queries: ``n_trivial`` with a feasible straight connection, then the
    ``n_short`` shortest others (easy for BIT*, whatever the preset's obstacle layout)."""
    q = np.stack([_valid_states(env, POOL, seed), _valid_states(env, POOL, seed + 100)], axis=1)
    straight = np.asarray(env.steer_to(q[:, 0], q[:, 1]))
    dist = np.asarray(env.distance(q[:, 0], q[:, 1]))
    trivial = np.flatnonzero(straight)[:n_trivial]
    others = np.flatnonzero(~straight)
    short = others[np.argsort(dist[others])][:n_short]
    assert len(trivial) == n_trivial and len(short) == n_short
    return np.concatenate([q[trivial], q[short]])


def _check_result(env, queries, res, padding=None):
    """Statuses are the bridge's outcomes through PLAN_STATUS; paths start/end exactly at
    the query, every segment passes env.steer_to at the planning padding, costs are the
    sums of env.distance over the segments; unsolved rows have no path and cost inf."""
    pad = env.padding if padding is None else padding
    outcome = res.info["bitstar_status"]
    assert outcome.dtype == np.int8 and res.status.dtype == np.int8
    assert res.status.tolist() == [PLAN_STATUS[BridgeOutcome(o)] for o in outcome]
    solved = np.flatnonzero(res.status == PlanStatus.SOLVED)
    assert all(res.path(i) is None for i in range(len(queries)) if i not in solved)
    assert np.isnan(np.delete(res.paths, solved, axis=0)).all()
    assert (np.delete(res.lengths, solved) == 0).all()
    assert np.isinf(np.delete(res.costs, solved)).all()
    if not len(solved):
        return
    for i in solved:
        path = res.path(i)
        assert path.dtype == np.float32 and path.ndim == 2 and path.shape[1] == env.dim
        assert len(path) >= 2
        np.testing.assert_array_equal(path[0], queries[i, 0])
        np.testing.assert_array_equal(path[-1], queries[i, 1])
    a = np.concatenate([res.path(i)[:-1] for i in solved])
    b = np.concatenate([res.path(i)[1:] for i in solved])
    m = len(a)
    fill = np.repeat(a[:1], max(POOL, m) - m, 0)  # one compiled shape
    ok = np.asarray(
        env.steer_to(np.concatenate([a, fill]), np.concatenate([b, fill]), padding=pad)
    )[:m]
    assert ok.all()
    d = np.asarray(env.distance(np.concatenate([a, fill]), np.concatenate([b, fill])), np.float64)[
        :m
    ]
    lengths = [res.lengths[i] - 1 for i in solved]
    costs = np.add.reduceat(d, np.cumsum([0] + lengths[:-1]))
    # float32 distances (XLA may round differently for different batch shapes)
    np.testing.assert_allclose(res.costs[solved], costs, rtol=1e-6)
    # BIT*'s own float64 length in OMPL's metric: the same metric as env.distance
    np.testing.assert_allclose(res.info["planner_costs"][solved], costs, rtol=1e-5)
    # never shorter than the straight connection
    ch = NumpyChecker.from_env(env)
    direct = np.array([ch.distance(queries[i, 0], queries[i, 1]) for i in solved])
    assert (costs >= direct - 1e-4).all()


@pytest.fixture(scope="module")
def rigid_batch():
    """rigid/0: 3 queries with a straight connection, 3 short non-trivial ones, one invalid
    start and one invalid goal; planned once with 2 workers, ``stop_on_first``."""
    env = nj.make_env("rigid/0")
    q = _easy_queries(env, n_trivial=3, n_short=3, seed=11)
    states = _uniform_states(env, 400, seed=5)
    blocked = states[
        NumpyChecker.from_env(env, 0.0).is_valid_many(states)
        & ~NumpyChecker.from_env(env).is_valid_many(states)
    ][0]
    q = np.concatenate([q, [[blocked, q[0, 1]], [q[1, 0], [np.nan, 1.0, 0.0]]]])
    res = plan_bitstar(env, q, time_budget=1.0, workers=2, stop_on_first=True, seed=2)
    return env, q, res


@needs_ompl
def test_bitstar_solves_easy_rigid_queries_and_flags_invalid_ones(rigid_batch):
    env, q, res = rigid_batch
    assert res.status.dtype == np.int8 and res.costs.dtype == np.float64
    assert res.status.tolist() == [PlanStatus.SOLVED] * 6 + [PlanStatus.INVALID] * 2, res.info
    assert res.info["bitstar_status"].tolist() == (
        [BridgeOutcome.EXACT] * 6 + [BridgeOutcome.BAD_QUERY] * 2
    )
    assert res.path(6) is None and res.path(7) is None
    _check_result(env, q, res)
    assert res.lengths[:3].tolist() == [2, 2, 2]  # direct connections
    assert (res.info["solve_times"][3:6] < 0.9).all()  # stop_on_first returned before the budget
    assert res.info["rejected"] == 0


@needs_ompl
def test_bitstar_solves_easy_arm_queries(capfd):
    env = nj.make_env("nlink/2")
    q = _easy_queries(env, n_trivial=2, n_short=3, seed=3)
    res = plan_bitstar(env, q, time_budget=1.0, workers=2, stop_on_first=True, seed=1)
    assert res.status.tolist() == [PlanStatus.SOLVED] * 5, res.info
    _check_result(env, q, res)
    # the workers leave without nanobind's leak report, and OMPL's info logging is off
    out, err = capfd.readouterr()
    assert "leaked" not in err and "Info:" not in out


@needs_ompl
def test_full_budget_keeps_improving_the_first_solution(rigid_batch):
    """Default mode uses the whole budget and returns BIT*'s best solution."""
    env, q, first = rigid_batch
    hard = q[3:5]  # two non-trivial queries, same seeds as in the batch (indices 3, 4)
    full = plan_bitstar(env, np.concatenate([q[:3], hard]), time_budget=0.4, workers=2, seed=2)
    assert (full.status == PlanStatus.SOLVED).all()
    _check_result(env, np.concatenate([q[:3], hard]), full)
    # same seed: the same first solution, then only improvements
    full_costs, first_costs = full.info["planner_costs"], first.info["planner_costs"]
    assert (full_costs[3:] <= first_costs[3:5] + 1e-9).all()
    # not provably optimal: BIT* runs until the deadline (a direct connection returns at once)
    times = full.info["solve_times"]
    assert (times[3:] > 0.3).all() and (times[:3] < 0.3).all()


@needs_ompl
def test_a_killed_worker_does_not_lose_the_batch(rigid_batch):
    """The test hook makes the worker ``os._exit`` when it starts a query: query 1 on its
    first attempt only (retried in a fresh worker: solved), query 4 on every attempt
    (CRASHED after one retry: NO_PATH). Every other query is solved or flagged as before, and
    results are reproducible across runs, worker counts and retries (``stop_on_first``,
    seeded per query)."""
    env, q, ref = rigid_batch
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = plan_bitstar(
            env,
            q,
            time_budget=1.0,
            workers=2,
            stop_on_first=True,
            seed=2,
            chunk_size=2,
            _crash_on={1: 1, 4: 2},
        )
    assert not [w for w in caught if "plan_bitstar" in str(w.message)]
    expected = ref.info["bitstar_status"].copy()
    expected[4] = BridgeOutcome.CRASHED
    assert res.info["bitstar_status"].tolist() == expected.tolist(), res.info
    expected = ref.status.copy()
    expected[4] = PlanStatus.NO_PATH
    assert res.status.tolist() == expected.tolist(), res.info
    assert res.path(4) is None and res.costs[4] == np.inf and 4 in res.info["errors"]
    assert res.info["worker_deaths"] == 3  # query 1 once, query 4 twice
    _check_result(env, q, res)
    for i in (0, 1, 2, 3, 5):
        np.testing.assert_array_equal(res.path(i), ref.path(i))
        assert res.costs[i] == ref.costs[i]


@needs_ompl
def test_kept_workers_are_reused_with_the_same_results(rigid_batch):
    """``keep_workers`` (the Ray executor's tasks): the next call with the same settings
    reuses the idle worker instead of starting one; the results are those of fresh workers
    (``stop_on_first``, seeded per query); other settings stop the idle workers."""
    env, q, ref = rigid_batch
    try:
        calls = [
            plan_bitstar(
                env,
                q[:4],
                time_budget=1.0,
                workers=1,
                stop_on_first=True,
                seed=2,
                keep_workers=True,
            )
            for _ in range(2)
        ]
        assert calls[0].info["workers"] == 1 and "workers_reused" not in calls[0].info
        assert calls[1].info["workers"] == 0 and calls[1].info["workers_reused"] == 1
        for res in calls:
            for i in range(4):
                np.testing.assert_array_equal(res.path(i), ref.path(i))
        kept = [w for ws in ompl_bridge._IDLE.values() for w in ws]
        assert len(kept) == 1 and kept[0].proc.is_alive()
        other = plan_bitstar(
            env, q[:1], time_budget=0.5, workers=1, stop_on_first=True, keep_workers=True
        )
        assert other.info["workers"] == 1 and not kept[0].proc.is_alive()
    finally:
        for ws in ompl_bridge._IDLE.values():
            ompl_bridge._stop_workers(ws)
        ompl_bridge._IDLE.clear()


@needs_ompl
def test_no_path_is_a_status_not_an_exception():
    """A goal walled off from the start: no path after the budget (TIMEOUT: BIT* is anytime,
    so it proves nothing), nothing raised."""
    # rigid/0's robot, padding, bounds and obstacle counts (the wall three times: the same
    # free space), so the package's checks run rigid/0's compiled programs; the goal keeps
    # 0.5 of clearance from the wall and 0.6 from the bounds at this padding
    rigid0 = nj.make_env("rigid/0")
    spec = {
        "name": "sealed",
        "robot": rigid0.robot.to_json(),
        "bounds": [[0, 10], [0, 10]],
        "padding": rigid0.padding,
        "boxes": [[7.5, 5, 0.2, 5]] * 3,
        "discs": [],
    }
    env = nj.Env.from_json(spec)
    q = np.array([[[2, 5, 0], [8.8, 5, 0]], [[2, 2, 0], [4, 8, 1]]], np.float32)
    res = plan_bitstar(env, q, time_budget=0.3, workers=1, stop_on_first=True)
    assert res.status.tolist() == [PlanStatus.TIMEOUT, PlanStatus.SOLVED]
    assert res.info["bitstar_status"].tolist() == [BridgeOutcome.NOT_FOUND, BridgeOutcome.EXACT]
    assert res.path(0) is None and res.costs[0] == np.inf
    assert res.info["solve_times"][0] >= 0.25
    _check_result(env, q, res)


def test_bad_arguments_raise_value_errors():
    env = nj.make_env("rigid/0")
    with pytest.raises(ValueError, match="shape"):
        plan_bitstar(env, np.zeros((3, 2, 2)), time_budget=1.0)
    with pytest.raises(ValueError, match="time_budget"):
        plan_bitstar(env, np.zeros((3, 2, 3)), time_budget=0)
    empty = plan_bitstar(env, np.zeros((0, 2, 3)), time_budget=1.0)
    assert empty.status.shape == (0,) and empty.paths.shape[0] == 0 and empty.lengths.shape == (0,)


def test_a_found_path_that_fails_the_check_is_rejected_by_finalize():
    """BIT*'s paths are verified once, by verify.finalize: a found path through an obstacle
    becomes NO_PATH, counted in info["rejected"], with the bridge outcome REJECTED."""
    env = nj.make_env("rigid/0")
    good = _easy_queries(env, n_trivial=1, n_short=0, seed=11)[0]
    a, b = _valid_states(env, 2, seed=4)
    q = np.stack([good, [a, b], [a, b]]).astype(np.float32)
    blocked = NumpyChecker.from_env(env, 0.0).is_valid_many(_uniform_states(env, 400, seed=5))
    through = _uniform_states(env, 400, seed=5)[~blocked][0]  # a state inside an obstacle
    results = ompl_bridge._Results.empty(3)
    results.outcome[:] = [BridgeOutcome.EXACT, BridgeOutcome.EXACT, BridgeOutcome.CRASHED]
    results.paths[0] = q[0].astype(np.float64)
    results.planner_costs[0] = NumpyChecker.from_env(env).distance(*q[0])
    results.paths[1] = np.stack([a, through, b]).astype(np.float64)
    res = ompl_bridge._verified_result(env, q, env.padding, results, query_seeds(0, 3), 1.0)
    assert res.status.tolist() == [PlanStatus.SOLVED, PlanStatus.NO_PATH, PlanStatus.NO_PATH]
    assert res.info["bitstar_status"].tolist() == [
        BridgeOutcome.EXACT,
        BridgeOutcome.REJECTED,
        BridgeOutcome.CRASHED,
    ]
    assert res.info["rejected"] == 1 and res.lengths.tolist() == [2, 0, 0]
    _check_result(env, q, res)
