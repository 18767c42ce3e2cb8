"""Neural planner (Alg. 1) on hand-made maps with known answers, using stand-in PNets.

The stand-ins share one jittable function (a traced ``mode`` picks the behaviour),
so the planner compiles once per option set:

* ``ORACLE``: the first waypoint of the exact shortest path from ``current`` to
  ``goal`` (visibility graph of the padding-0 map), or the goal when visible.
* ``SEEKER``: a unit step straight at the goal, through obstacles (plus optional noise).
* ``CAUTIOUS``: the seeker, but it stays put when that step is blocked.
* ``BROKEN``: the oracle, except from the query start towards the query goal it
  jumps straight through the wall (a deliberately broken coarse path).
* ``STAY``: returns ``current`` (a model that never moves).

Every path counted as a success is re-checked by shapely (float64 segment
against the closed boxes, and the bounds), never by the planner's own flag.
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.tree_util import Partial
from shapely.geometry import LineString, Point
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

from ntq_jax import Env
from ntq_jax.neural import PlannerOptions, plan_batch
from ntq_jax.neural.repair import repair_windows, splice
from ntq_jax.neural.steps import contract
from ntq_jax.planners.visgraph import VisGraph
from ntq_jax.robots.batch import steer_to_cm
from ntq_jax.types import PlanCause

ORACLE, SEEKER, CAUTIOUS, BROKEN, STAY = range(5)
BOUNDS = [[0.0, 10.0], [0.0, 10.0]]
DUMMY = [[0.3, 9.7, 0.1, 0.1], [9.7, 0.3, 0.1, 0.1]]  # tiny corner boxes: every map has 3 boxes
MAPS = {
    "straight": [[0.3, 0.3, 0.1, 0.1]] + DUMMY,
    "wall": [[5.0, 5.0, 0.5, 3.0]] + DUMMY,  # x 4.5..5.5, y 2..8
    # a cup open downwards around (5, 4): top wall y 6..6.5, sides x 3..3.5 and 6.5..7
    "twowalls": [[3.0, 5.0, 0.25, 3.0], [7.0, 5.0, 0.25, 3.0], [0.3, 0.3, 0.1, 0.1]],
    "deadend": [[5.0, 6.25, 2.0, 0.25], [3.25, 4.25, 0.25, 2.25], [6.75, 4.25, 0.25, 2.25]],
}
V_PAD = 32
BATCH = 4
OPTS = PlannerOptions(n_plan=12, replan_rounds=2, replan_steps=8)
# the variant without steerTo: one option set (without repairs the replanning settings
# are unused) and, like ``run``, BATCH queries per compiled call, so the tests share programs
NOSTEER = PlannerOptions(n_plan=12, steer=False, delta=1.0)


def make(name):
    return Env.from_json(
        {
            "name": name,
            "robot": {"kind": "point"},
            "bounds": BOUNDS,
            "boxes": MAPS[name],
            "padding": 0.0,
        }
    )


def _fmix(x):
    """murmur3's 32-bit finaliser (a bijective integer mix)."""
    x = x ^ (x >> 16)
    x = x * np.uint32(0x85EBCA6B)
    x = x ^ (x >> 13)
    x = x * np.uint32(0xC2B2AE35)
    return x ^ (x >> 16)


def _normal(key, shape):
    """Standard normal noise, a deterministic function of ``key``: a counter hashed with the
    key's words, then Box-Muller. Used instead of ``jax.random.normal``, whose threefry
    kernel alone adds about half a second to every compiled stage holding a stand-in."""
    words = jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key
    h = jnp.uint32(0x9E3779B9)
    for w in words.astype(jnp.uint32).reshape(-1):
        h = _fmix(h ^ _fmix(w + np.uint32(0x7F4A7C15)))
    size = int(np.prod(shape))
    x = _fmix(jnp.arange(2 * size, dtype=jnp.uint32) * np.uint32(0x9E3779B1) + h)
    u = ((x >> 8).astype(jnp.float32) + 0.5) * np.float32(2.0**-24)  # in (0, 1)
    z = jnp.sqrt(-2.0 * jnp.log(u[:size])) * jnp.cos(np.float32(2 * np.pi) * u[size:])
    return z.reshape(shape)


def _stand_in(mode, nodes, dist, world, jump, sigma, key, cur, goal):
    robot = ENV_ROBOT
    n, v = cur.shape[0], nodes.shape[0]
    tile = jnp.tile(nodes, (n, 1))
    d = goal - cur
    dn = jnp.linalg.norm(d, axis=1, keepdims=True)
    seek = cur + d / jnp.maximum(dn, 1e-9) * jnp.minimum(dn, 1.0)
    # one steerTo call for the four kinds of segment (current -> node, node -> goal,
    # current -> goal, current -> seek): one motion check in every compiled stage, not four
    a = jnp.concatenate([jnp.repeat(cur, v, 0), tile, cur, cur])
    b = jnp.concatenate([tile, jnp.repeat(goal, v, 0), goal, seek])
    vis_c, vis_g, direct, ok = jnp.split(
        steer_to_cm(robot, world, a.T, b.T, 0.0), [n * v, 2 * n * v, 2 * n * v + n]
    )
    vis_c, vis_g = vis_c.reshape(n, v), vis_g.reshape(n, v)
    dg = jnp.where(vis_g, jnp.linalg.norm(nodes[None] - goal[:, None], axis=-1), jnp.inf)
    h = jnp.min(dist[None] + dg[:, None, :], axis=-1)
    dc = jnp.linalg.norm(nodes[None] - cur[:, None], axis=-1)
    score = jnp.where(vis_c & (dc > 1e-6), dc + h, jnp.inf)
    oracle = jnp.where(direct[:, None], goal, nodes[jnp.argmin(score, axis=1)])
    seek_noisy = seek + sigma * _normal(key, cur.shape)
    cautious = jnp.where(ok[:, None], seek, cur)
    broken = oracle
    for (
        rule
    ) in jump:  # (from, towards, to): jump straight to ``to`` from ``from`` towards ``towards``
        hit = (jnp.linalg.norm(cur - rule[0], axis=1) < 1e-6) & (
            jnp.linalg.norm(goal - rule[1], axis=1) < 1e-6
        )
        broken = jnp.where(hit[:, None], rule[2], broken)
    return jnp.select(
        [mode == ORACLE, mode == SEEKER, mode == CAUTIOUS, mode == BROKEN],
        [oracle, seek_noisy, cautious, broken],
        cur,
    )


ENV_ROBOT = make("straight").robot
_GRAPHS = {}


NO_JUMP = ((-99, -99), (-99, -99), (0, 0))


@functools.cache
def pnet(name, mode, jump=(NO_JUMP, NO_JUMP), sigma=0.0):
    """The stand-in ``mode`` on map ``name`` (cached: equal arguments, one object; every
    stand-in is a ``Partial`` of ``_stand_in`` with arguments of one shape, so all of them
    share the planner's compiled stages)."""
    env = make(name)
    if name not in _GRAPHS:
        g = VisGraph.build(env, 0.0)
        nodes = np.full((V_PAD, 2), np.nan, np.float32)
        dist = np.full((V_PAD, V_PAD), np.inf, np.float32)
        nodes[: g.num_nodes], dist[: g.num_nodes, : g.num_nodes] = g.nodes, g.dist
        _GRAPHS[name] = (g, jnp.asarray(nodes), jnp.asarray(dist))
    _, nodes, dist = _GRAPHS[name]
    return Partial(
        _stand_in,
        jnp.int32(mode),
        nodes,
        dist,
        env.world,
        jnp.asarray(jump, jnp.float32),
        jnp.float32(sigma),
    )


def optimum(name, queries):
    make(name)
    pnet(name, ORACLE)
    return _GRAPHS[name][0].plan(np.asarray(queries, np.float32)).costs


def shapely_free(name, path):
    """Independent float64 check: in bounds and no segment touches a (closed) box."""
    obst = unary_union(
        [shapely_box(cx - hw, cy - hh, cx + hw, cy + hh) for cx, cy, hw, hh in MAPS[name]]
    )
    p = np.asarray(path, np.float64)
    if not (np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 10))):
        return False
    for a, b in zip(p[:-1], p[1:]):
        geom = Point(a) if np.allclose(a, b) else LineString([a, b])
        if geom.intersects(obst):
            return False
    return True


def run(name, mode, queries, opts=OPTS, key=0, **kw):
    q = np.asarray(queries, np.float32)
    reps = -(-BATCH // len(q))
    q = np.concatenate([q] * reps)[:BATCH]
    res = plan_batch(make(name), pnet(name, mode, **kw), q, jax.random.key(key), opts)
    for i in np.flatnonzero(res.success):  # every success re-checked independently
        p = res.path(i)
        assert shapely_free(name, p), (name, i, p)
        np.testing.assert_allclose(p[0], q[i, 0], atol=1e-6)
        if opts.steer:
            np.testing.assert_allclose(p[-1], q[i, 1], atol=1e-6)
        seg = np.linalg.norm(np.diff(p.astype(np.float64), axis=0), axis=1).sum()
        assert res.costs[i] == pytest.approx(seg, rel=1e-4)
    assert np.all(np.isinf(res.costs[~res.success]))
    return q, res


def test_straight_shot_needs_no_pnet():
    q, res = run("straight", STAY, [[[1, 2], [9, 8]], [[2, 8], [8, 2]]])
    assert np.all(res.success) and np.all(res.cause == PlanCause.SUCCESS)
    assert np.all(res.lengths == 2) and np.all(res.pnet_calls == 0)
    np.testing.assert_allclose(res.costs, np.linalg.norm(q[:, 1] - q[:, 0], axis=1), rtol=1e-5)


def test_one_wall_oracle_finds_the_optimum():
    q, res = run("wall", ORACLE, [[[2, 5], [8, 5]], [[1, 1], [9, 6]], [[4, 9], [6, 1]]])
    assert np.all(res.success)
    np.testing.assert_allclose(res.costs, optimum("wall", q), rtol=1e-4)
    assert res.pnet_calls[0] == 2 and res.lengths[0] == 4  # around the top or bottom corners


def test_one_wall_seeker_walks_through_and_is_infeasible():
    q, res = run("wall", SEEKER, [[[2, 5], [8, 5]]])
    assert not np.any(res.success)
    assert np.all(
        res.cause == PlanCause.INFEASIBLE
    )  # reached the goal, through the wall; no repair
    assert np.all(res.replans == OPTS.replan_rounds)


def test_dead_end():
    queries = [[[5, 4], [5, 9]], [[4, 3], [6, 8]]]
    _, res = run("deadend", CAUTIOUS, queries)
    assert np.all(res.cause == PlanCause.NO_PATH) and not np.any(res.success)
    assert np.all(res.pnet_calls == OPTS.n_plan)
    q, res = run("deadend", ORACLE, queries)
    assert np.all(res.success)
    np.testing.assert_allclose(res.costs, optimum("deadend", q), rtol=1e-4)


def test_replanning_repairs_a_broken_path():
    s, g, jump = (2.0, 5.0), (8.0, 5.0), (7.0, 5.0)  # s -> jump crosses the wall
    kw = dict(jump=((s, g, jump), NO_JUMP))
    no_replan = PlannerOptions(n_plan=12, replan_rounds=0, replan_steps=8)
    _, res = run("wall", BROKEN, [[s, g]], opts=no_replan, **kw)
    assert np.all(res.cause == PlanCause.INFEASIBLE)
    np.testing.assert_allclose(res.paths[0, :3], [s, jump, g])  # the broken coarse path
    q, res = run("wall", BROKEN, [[s, g]], **kw)
    assert np.all(res.success) and np.all(res.replans == 1)
    np.testing.assert_allclose(res.costs, optimum("wall", q), rtol=1e-4)  # contracted to optimum


def test_one_round_repairs_every_blocked_segment():
    s, g, j1, j2 = (1.0, 5.0), (9.0, 5.0), (5.0, 5.0), (8.5, 5.0)  # s -> j1 -> j2 cross both walls
    kw = dict(jump=((s, g, j1), (j1, g, j2)))
    q, res = run(
        "twowalls",
        BROKEN,
        [[s, g]],
        opts=PlannerOptions(n_plan=12, replan_rounds=0, replan_steps=8),
        **kw,
    )
    assert np.all(res.cause == PlanCause.INFEASIBLE)
    np.testing.assert_allclose(res.paths[0, :4], [s, j1, j2, g])
    q, res = run("twowalls", BROKEN, [[s, g]], **kw)
    assert np.all(res.success) and np.all(res.replans == 1)
    assert np.all(res.costs >= optimum("twowalls", q) * (1 - 1e-4))


def test_without_steer_to():
    nosteer = NOSTEER
    _, res = run("straight", SEEKER, [[[1, 1], [9, 1]]], opts=nosteer)
    assert np.all(res.success) and np.all(res.lengths == 8)  # 1, 2, ..., 8: within delta of 9
    np.testing.assert_allclose(res.costs, 7.0, rtol=1e-5)
    np.testing.assert_allclose(res.paths[0, 7], [8, 1], atol=1e-5)
    # a trivial query a non-moving model cannot solve without steerTo (the paper's Fig. 5)
    _, res = run("straight", STAY, [[[1, 1], [9, 1]]], opts=nosteer)
    assert np.all(res.cause == PlanCause.NO_PATH) and np.all(res.pnet_calls == 12)
    # reaching the goal through a wall is not a success
    _, res = run("wall", SEEKER, [[[2, 5], [8, 5]]], opts=nosteer)
    assert np.all(res.cause == PlanCause.INFEASIBLE)


def _flip_to_pi(key, current, goal):
    """Jumps onto the goal's position with theta = +pi (the goal's -pi, the same heading)."""
    return goal.at[:, 2].set(jnp.pi)


# the rigid body's options without steerTo: the same path buffer (and so the same compiled
# check stage) as NOSTEER, whose other fields that stage does not read
RIGID_NOSTEER = PlannerOptions(n_plan=12, steer=False, delta=0.1)


def _rigid_env():
    return Env.from_json(
        {
            "name": "rigid-open",
            "robot": {"kind": "rigid_body"},
            "bounds": BOUNDS,
            "boxes": [[5.0, 5.0, 0.5, 0.5]] + DUMMY,
            "padding": 0.0,
        }
    )


def test_without_steer_to_delta_is_in_the_robots_metric():
    """theta = pi and -pi are one heading: a prediction there is at distance 0, not 2 pi."""
    env = _rigid_env()
    q = np.asarray([[[2, 2, 0], [8, 2, -np.pi]]], np.float32)
    res = plan_batch(env, _flip_to_pi, q, jax.random.key(0), RIGID_NOSTEER)
    assert res.success[0] and res.cause[0] == PlanCause.SUCCESS
    assert res.lengths[0] == 2 and res.pnet_calls[0] == 1
    np.testing.assert_allclose(res.path(0), [[2, 2, 0], [8, 2, np.pi]], atol=1e-6)
    # the cost is that of the path's own segment (6 + 0.5 * pi), without the zero gap
    np.testing.assert_allclose(res.costs[0], 6 + 0.5 * np.pi, rtol=1e-5)
    # Euclidean in raw coordinates the same prediction would be 2 pi away: never reached
    assert np.linalg.norm(res.path(0)[-1] - q[0, 1]) > 6


def test_without_steer_to_the_papers_goal_test_and_unchecked_paths():
    """delta_norm="l2" is the paper's ||pi_end - x_g||_2 on the raw vector (angles not
    wrapped); nosteer_check=False is its "lines 8 and 9 only" (segments not checked)."""
    from ntq_jax.experiment import config

    env = _rigid_env()
    q = np.asarray([[[2, 2, 0], [8, 2, -np.pi]]], np.float32)
    l2 = dataclasses.replace(RIGID_NOSTEER, delta_norm="l2")
    res = plan_batch(env, _flip_to_pi, q, jax.random.key(0), l2)
    assert not res.success[0] and res.cause[0] == PlanCause.NO_PATH and res.pnet_calls[0] == 12
    wall = np.asarray([[[2, 5], [8, 5]]], np.float32)
    net = pnet("wall", SEEKER)
    checked = plan_batch(make("wall"), net, wall, jax.random.key(0), NOSTEER, rows=BATCH)
    loose = plan_batch(
        make("wall"),
        net,
        wall,
        jax.random.key(0),
        PlannerOptions(n_plan=12, steer=False, delta=1.0, nosteer_check=False),
        rows=BATCH,
    )
    assert checked.cause[0] == PlanCause.INFEASIBLE and not checked.success[0]
    assert loose.cause[0] == PlanCause.SUCCESS and loose.success[0]
    np.testing.assert_array_equal(loose.path(0), checked.paths[0, : checked.lengths[0]])
    assert not shapely_free("wall", loose.path(0))  # through the wall, as the option says
    # from the config (null: ours, left out of the hash)
    cfg = config.load(None, ["eval.delta_norm=l2", "eval.nosteer_check=false"])
    o = config.neural_options(cfg.eval, steer=False)
    assert (o.delta_norm, o.nosteer_check) == ("l2", False)
    base = config.load(None, [])
    o = config.neural_options(base.eval, steer=False)
    assert (o.delta_norm, o.nosteer_check) == ("robot", True)
    assert "delta_norm" not in base.to_dict()["eval"] and cfg.hash() != base.hash()
    with pytest.raises(ValueError, match="delta_norm"):
        PlannerOptions(delta_norm="l1")


def test_without_steer_to_replan_runs_lines_10_to_14():
    """nosteer_check="replan": the goal test replaces only line 4's steerTo; a path that passes
    it gets the goal appended and is then contracted, checked and repaired as with steerTo
    (the broken jump through the wall lands within delta of the goal)."""
    from ntq_jax.experiment import config

    s, g, jump = (2.0, 5.0), (8.0, 5.0), (7.3, 5.0)
    kw = dict(jump=((s, g, jump), NO_JUMP))

    def nosteer(check, rounds=2):
        return PlannerOptions(
            n_plan=12,
            steer=False,
            delta=1.0,
            nosteer_check=check,
            replan_rounds=rounds,
            replan_steps=8,
        )

    # nosteer(True) but for its replanning settings, unused without repairs
    _, checked = run("wall", BROKEN, [[s, g]], opts=NOSTEER, **kw)
    assert np.all(checked.cause == PlanCause.INFEASIBLE) and np.all(checked.replans == 0)
    np.testing.assert_allclose(checked.path(0), [s, jump])  # ends within delta, no goal, no repair
    _, broken = run("wall", BROKEN, [[s, g]], opts=nosteer("replan", rounds=0), **kw)
    assert np.all(broken.cause == PlanCause.INFEASIBLE)
    np.testing.assert_allclose(broken.path(0), [s, jump, g])  # the goal appended
    q, res = run("wall", BROKEN, [[s, g]], opts=nosteer("replan"), **kw)
    assert np.all(res.success) and np.all(res.replans == 1)
    np.testing.assert_allclose(res.path(0)[-1], g)
    np.testing.assert_allclose(res.costs, optimum("wall", q), rtol=1e-4)  # repaired, contracted
    assert nosteer("replan").max_len == nosteer(True).max_len + 2 * 8 == NOSTEER.max_len + 2 * 8
    # a start within delta of the goal: the goal appended, as steerTo would
    _, near = run("straight", STAY, [[[1, 1], [1.5, 1.5]]], opts=nosteer("replan"))
    assert np.all(near.success) and np.all(near.lengths == 2) and np.all(near.pnet_calls == 0)
    cfg = config.load(None, ["eval.nosteer_check=replan"])
    assert config.neural_options(cfg.eval, steer=False).nosteer_check == "replan"


def test_without_steer_to_states_checks_the_waypoints_only():
    """nosteer_check="states": success needs every state of the path valid, not its segments:
    the seeker's waypoints 1 apart step over both thin walls (success), and on the thick wall
    one lands inside it (infeasible), where the unchecked variant calls both a success."""
    from ntq_jax.experiment import config

    net, env = pnet("twowalls", SEEKER), make("twowalls")
    q = np.asarray([[[2.5, 5], [8.5, 5]]], np.float32)
    run = {
        c: plan_batch(
            env,
            net,
            q,
            jax.random.key(0),
            PlannerOptions(n_plan=12, steer=False, delta=1.0, nosteer_check=c),
            rows=BATCH,
        )
        for c in ("states", True, False)
    }
    path = run["states"].path(0)
    assert np.asarray(env.is_valid(path)).all() and not shapely_free("twowalls", path)
    assert run["states"].success[0] and run[False].success[0]
    assert run[True].cause[0] == PlanCause.INFEASIBLE
    wall = np.asarray([[[2, 5], [8, 5]]], np.float32)
    inside = plan_batch(
        make("wall"),
        pnet("wall", SEEKER),
        wall,
        jax.random.key(0),
        PlannerOptions(n_plan=12, steer=False, delta=1.0, nosteer_check="states"),
        rows=BATCH,
    )
    assert not np.asarray(make("wall").is_valid(inside.path(0))).all()
    assert inside.cause[0] == PlanCause.INFEASIBLE and not inside.success[0]
    cfg = config.load(None, ["eval.nosteer_check=states"])
    assert config.neural_options(cfg.eval, steer=False).nosteer_check == "states"
    with pytest.raises(config.ConfigError, match="nosteer_check"):
        config.load(None, ["eval.nosteer_check=segments"])
    with pytest.raises(ValueError, match="nosteer_check"):
        PlannerOptions(nosteer_check="segments")


def test_without_steer_to_a_start_within_delta_is_solved():
    """A start already within delta of the goal is reached like a last prediction would be."""
    nosteer = NOSTEER
    q, res = run("straight", STAY, [[[1, 1], [1.5, 1.5]], [[8, 8], [8, 9]]], opts=nosteer)
    assert np.all(res.success) and np.all(res.cause == PlanCause.SUCCESS)
    assert np.all(res.lengths == 1) and np.all(res.pnet_calls == 0)
    np.testing.assert_array_equal(res.paths[:, 0], q[:, 0])
    np.testing.assert_array_equal(res.costs, 0.0)
    # the same in the rigid body's metric: theta pi and -pi at one position
    env = _rigid_env()
    rq = np.asarray(
        [[[2, 2, np.pi], [2, 2, -np.pi]], [[2, 8, 0.1], [2.2, 8, -0.1]], [[5, 5, 0], [5.3, 5, 0]]],
        np.float32,
    )
    res = plan_batch(env, _stay, rq, jax.random.key(0), nosteer)
    assert res.success[:2].all() and np.all(res.lengths[:2] == 1)
    # a start inside the box stays an invalid query, however close the goal
    assert res.cause[2] == PlanCause.INVALID_QUERY and not res.success[2]
    # with steerTo the same start gets the goal appended: two states
    res = plan_batch(
        env, _stay, rq[:2], jax.random.key(0), PlannerOptions(n_plan=12, replan_rounds=0)
    )
    assert res.success.all() and np.all(res.lengths == 2)


def test_bidirectional_and_invalid_queries():
    bi = PlannerOptions(n_plan=12, replan_rounds=2, replan_steps=8, bidirectional=True)
    q, res = run(
        "deadend", ORACLE, [[[5, 4], [5, 9]], [[4, 3], [6, 8]], [[5, 6.2], [1, 1]]], opts=bi
    )
    assert res.success[0] and res.success[1]
    assert np.all(res.costs[:2] >= optimum("deadend", q[:2]) * (1 - 1e-4))
    assert res.cause[2] == PlanCause.INVALID_QUERY  # the start is inside the cup's top wall


def test_batched_equals_one_by_one_and_noise_is_keyed():
    queries = [[[5, 4], [5, 9]], [[2, 5], [8, 2]], [[9, 9], [1, 1]], [[4, 3], [6, 8]]]
    env = make("deadend")
    net = pnet("deadend", ORACLE)
    full = plan_batch(env, net, np.asarray(queries, np.float32), jax.random.key(0), OPTS)
    single = plan_batch(env, net, np.asarray(queries, np.float32), jax.random.key(0), OPTS, chunk=1)
    np.testing.assert_array_equal(full.success, single.success)
    np.testing.assert_allclose(full.costs, single.costs, rtol=1e-6)
    # a noisy model: same key -> same paths, another key -> different paths
    noisy = [[[5, 4], [5, 9]]] * BATCH
    _, a = run("deadend", SEEKER, noisy, key=1, sigma=0.5)
    _, b = run("deadend", SEEKER, noisy, key=1, sigma=0.5)
    _, c = run("deadend", SEEKER, noisy, key=2, sigma=0.5)
    np.testing.assert_array_equal(a.paths, b.paths)
    assert a.paths.shape != c.paths.shape or not np.array_equal(a.paths, c.paths, equal_nan=True)


def test_host_stages_plan_as_the_fused_stages(monkeypatch):
    """A robot whose checks are costly to compile (``shared_check_programs``, the 3-D arm)
    runs the planner's checks on the host through the shared batched programs
    (:mod:`ntq_jax.neural.host_stages`: the ends' validity, contraction, feasibility, the
    path states' validity before replanning). The point robot given that flag plans every
    query as with its fused stages, array for array: with steerTo (blocked coarse paths
    contracted, repaired by replanning; an invalid start; a noisy PNet), without it
    (the waypoints' validity checked), and with replanning without steerTo."""
    s, g = (2.0, 5.0), (8.0, 5.0)
    cases = [
        (
            "wall",
            BROKEN,
            [[s, g], [[1, 1], [9, 6]]],
            OPTS,
            dict(jump=((s, g, (7.0, 5.0)), NO_JUMP)),
        ),
        (
            "deadend",
            SEEKER,
            [[[5, 4], [5, 9]], [[4, 3], [6, 8]], [[5, 6.2], [1, 1]]],
            OPTS,
            dict(sigma=0.5),
        ),
        (
            "twowalls",
            SEEKER,
            [[[2.5, 5], [8.5, 5]], [[1, 1], [9, 9]]],
            PlannerOptions(n_plan=12, steer=False, delta=1.0, nosteer_check="states"),
            {},
        ),
        (
            "wall",
            SEEKER,
            [[[2, 5], [8, 5]], [[1, 2], [9, 2]]],
            PlannerOptions(
                n_plan=12,
                steer=False,
                delta=1.0,
                nosteer_check="replan",
                replan_rounds=2,
                replan_steps=8,
            ),
            dict(sigma=0.3),
        ),
    ]
    robot_type = type(ENV_ROBOT)
    causes = set()
    for name, mode, queries, opts, kw in cases:
        got = {}
        for shared in (False, True):
            monkeypatch.setattr(robot_type, "shared_check_programs", shared, raising=False)
            q = np.asarray(queries, np.float32)
            got[shared] = plan_batch(
                make(name), pnet(name, mode, **kw), q, jax.random.key(1), opts, rows=BATCH
            )
        for field in ("paths", "lengths", "success", "costs", "cause", "pnet_calls", "replans"):
            a, b = getattr(got[True], field), getattr(got[False], field)
            np.testing.assert_array_equal(a, b, f"{name}: {field}")
        causes |= set(got[True].cause.tolist())
        assert got[True].replans.any() or not got[True].success.all(), name
    assert {PlanCause.SUCCESS, PlanCause.INVALID_QUERY, PlanCause.INFEASIBLE} <= causes


def test_lazy_states_contraction():
    env = make("wall")
    p = np.full((2, 8, 2), np.nan, np.float32)
    zig = [[1, 1], [2, 3], [3, 1], [4, 1.5], [3, 0.5], [9, 1]]  # all below the wall: one segment
    p[0, :6] = zig
    # around the wall's top with redundant states: the corners must survive
    top = [[2, 5], [3, 8.5], [4, 8.6], [4.4, 8.2], [5.6, 8.2], [7, 7], [8, 5]]
    p[1, :7] = top
    n = np.array([6, 7], np.int32)
    fn = jax.jit(contract, static_argnames=("robot", "padding"))
    q, m = fn(env.robot, env.world, jnp.asarray(p), jnp.asarray(n), 0.0, jnp.ones(2, bool))
    q, m = np.asarray(q), np.asarray(m)
    assert m[0] == 2
    np.testing.assert_allclose(q[0, :2], [[1, 1], [9, 1]])
    assert 3 <= m[1] < 7 and shapely_free("wall", q[1, : m[1]])
    np.testing.assert_allclose(q[1, [0, m[1] - 1]], [[2, 5], [8, 5]])


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_repair_windows_cover_every_blocked_segment_without_overlap(data):
    """Random validity / blocked patterns: every blocked segment lies inside a window;
    a window's ends are valid states (or the path's ends) and all states strictly inside
    it are in collision; windows are listed last first and never overlap, so splicing
    them in that order never moves one still to splice."""
    length = data.draw(st.integers(2, 24))
    n = data.draw(st.integers(2, length))
    ok = np.array(data.draw(st.lists(st.booleans(), min_size=length, max_size=length)))
    ok[0] = ok[n - 1] = True  # the planner only repairs paths between valid start and goal
    ok[n:] = False
    blocked = np.array(data.draw(st.lists(st.booleans(), min_size=length - 1, max_size=length - 1)))
    blocked[n - 1 :] = False
    blocked |= ~ok[:-1] | ~ok[1:]  # a segment touching a state in collision is blocked
    blocked[n - 1 :] = False
    wins = repair_windows(blocked, ok, n)
    for k in np.flatnonzero(blocked):
        assert any(ia <= k < ib for ia, ib in wins), (k, wins)
    for ia, ib in wins:
        assert 0 <= ia < ib <= n - 1 and ok[ia] and ok[ib]
        assert not ok[ia + 1 : ib].any()
    for (ia1, _), (_, ib2) in zip(wins, wins[1:]):
        assert ib2 <= ia1


def test_splice_replaces_a_window_and_refuses_to_overflow():
    path = np.full((6, 2), np.nan, np.float32)
    path[:4] = [[0, 0], [1, 1], [2, 2], [3, 3]]
    sub = np.array([[1, 1], [1.5, 0], [2.5, 0], [3, 3]], np.float32)  # runs from path[1] to path[3]
    out, n = splice(path, 4, 1, 3, sub)
    assert n == 5
    np.testing.assert_array_equal(out[:5], [[0, 0], [1, 1], [1.5, 0], [2.5, 0], [3, 3]])
    assert np.all(np.isnan(out[5:]))
    assert not np.shares_memory(out, path) and np.isnan(path[4:]).all()  # the input is kept
    assert splice(path, 4, 1, 2, np.zeros((5, 2), np.float32)) is None  # 1 + 5 + 1 > 6 rows


def _stay(key, current, goal):
    return current


def test_compiled_stages_are_bounded(monkeypatch):
    from ntq_jax.neural import steps

    monkeypatch.setattr(steps, "COMPILED_CACHE_SIZE", 2)
    env = make("straight")
    q = np.asarray([[[1, 2], [9, 8]]], np.float32)
    # three option sets the tests above compile too (stand-ins, BATCH rows): the bound is
    # checked on the cache's entries, whichever the options, without compiling anything new
    sets = (
        PlannerOptions(n_plan=12, replan_rounds=0, replan_steps=8),
        OPTS,
        PlannerOptions(n_plan=12, replan_rounds=2, replan_steps=8, bidirectional=True),
    )
    # their check stage reads none of the fields they differ in: one program for the three
    assert len({o.for_stage("check") for o in sets}) == 1
    assert len({o.for_stage("coarse") for o in sets}) == 3
    for opts in sets:  # the coarse stage, then the shared check stage
        res = plan_batch(env, pnet("straight", STAY), q, jax.random.key(0), opts, rows=BATCH)
        assert res.success[0] and len(steps._COMPILED) <= 2
    # the least recently used went first: the first two coarse stages
    assert [s[:3] for s in steps._COMPILED] == [
        ("coarse", env.robot, sets[2].for_stage("coarse")),
        ("check", env.robot, sets[0].for_stage("check")),
    ]


def test_check_stage_compiles_once_for_every_batch_size():
    """The contraction and feasibility check run on CHECK_ROWS paths per call, so batches of
    other sizes (the cascade's fallbacks) reuse its one compilation; results are per row."""
    from ntq_jax.neural import steps

    env = make("wall")
    opts = PlannerOptions(n_plan=12, replan_rounds=0, replan_steps=8)  # as the tests above
    rng = np.random.default_rng(3)
    q = rng.uniform(0.5, 9.5, (300, 2, 2)).astype(np.float32)
    steps._COMPILED.clear()
    big = plan_batch(env, _stay, q, jax.random.key(0), opts)
    small = plan_batch(env, _stay, q[:5], jax.random.key(0), opts)
    checks = [s for s in steps._COMPILED if s[0] == "check"]
    coarse = [s for s in steps._COMPILED if s[0] == "coarse"]
    assert len(checks) == 1 and len(coarse) == 2
    assert (steps.CHECK_ROWS,) in [shape for shape, _ in checks[0][-1]]  # the mask
    assert 0 < big.success.sum() < len(q)  # both kinds of rows
    np.testing.assert_array_equal(small.success, big.success[:5])
    np.testing.assert_array_equal(small.lengths, big.lengths[:5])


class _Reads:
    """Planner options that record which of their fields a traced stage reads (properties
    such as ``max_len`` run on the proxy, so the fields behind them count)."""

    def __init__(self, opts):
        self.opts, self.read = opts, set()

    def __getattr__(self, name):
        attr = getattr(type(self.opts), name)
        if isinstance(attr, property):
            return attr.fget(self)
        self.read.add(name)
        return getattr(self.opts, name)


def test_each_stage_reads_only_the_options_in_its_compile_key(monkeypatch):
    """Every stage, traced with options that record their reads, reads only the fields of
    ``STAGE_FIELDS`` (the rest are left out of its compile key), on every path through the
    planner: steerTo, each nosteer_check, bidirectional, the l2 goal test, no contraction;
    ``coarse_plan`` (the coarse stage without the ends' validity) traced beside ``coarse``."""
    from ntq_jax.neural import steps
    from ntq_jax.neural.options import STAGE_FIELDS

    cores = {
        "coarse": steps.coarse_core,
        "coarse_plan": steps.coarse_plan_core,
        "valid": steps.valid_core,
        "connect": steps.connect_core,
        "check": steps.check_core,
    }
    for_stage, compiled = PlannerOptions.for_stage, steps._compiled
    reads = {name: set() for name in cores}

    def trace(name, robot, proxy, args):
        jax.make_jaxpr(functools.partial(cores[name], robot, proxy))(*args)
        reads[name] |= proxy.read

    def spy(name, args):
        proxy = args[1]
        trace(name, args[0], proxy, args[2:])
        if name == "coarse":  # the coarse plan a robot with shared check programs compiles
            trace("coarse_plan", args[0], _Reads(proxy.opts), args[2:])
        return compiled(name, (args[0], for_stage(proxy.opts, name)) + args[2:])

    monkeypatch.setattr(PlannerOptions, "for_stage", lambda self, stage: _Reads(self))
    monkeypatch.setattr(steps, "_compiled", spy)
    s, g = (2.0, 5.0), (8.0, 5.0)
    kw = dict(jump=((s, g, (7.3, 5.0)), NO_JUMP))
    nosteer = dict(n_plan=12, steer=False, delta=1.0)
    for opts in (
        OPTS,
        NOSTEER,
        PlannerOptions(**nosteer, nosteer_check="states"),
        PlannerOptions(**nosteer, nosteer_check="replan", replan_rounds=2, replan_steps=8),
        PlannerOptions(**nosteer, nosteer_check=False, delta_norm="l2"),
        PlannerOptions(n_plan=12, replan_rounds=2, replan_steps=8, bidirectional=True),
        PlannerOptions(n_plan=12, replan_rounds=2, replan_steps=8, contract=False),
    ):
        plan_batch(
            make("wall"),
            pnet("wall", BROKEN, **kw),
            np.asarray([[s, g]] * BATCH, np.float32),
            jax.random.key(0),
            opts,
        )
    assert all(reads.values()), reads  # every stage ran
    for name, fields in reads.items():
        assert fields <= set(STAGE_FIELDS[name]), (name, fields - set(STAGE_FIELDS[name]))
