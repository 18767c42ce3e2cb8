"""The ensemble rows: the ensemble neural planner (PNet_ens) and best-of-N (PNet_best-of-4).

* Four identical members plan exactly like the single member on the same queries
  and key (success, paths, lengths, costs, causes, replans bit for bit; only
  ``pnet_calls`` counts the four members' predictions), with stochastic
  (dropout-like) stand-ins and with real PNets, through replanning and the
  bidirectional coarse plan.
* The rule (:func:`ntq_jax.neural.proposals.choose`) on hand-made candidates, and the
  ensemble of a useless and a good member planning like the good one.
* Best-of-N (:func:`ntq_jax.experiment.metrics.best_of`): never costlier than any member's
  successful path on a query, succeeds iff some member succeeds.
* The rows and files in a tiny pipeline run (the fixture of tests/test_train_all.py).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_neural_planner import OPTS, ORACLE, SEEKER, STAY, make, optimum, pnet, shapely_free

from ntq_jax import make_env, models
from ntq_jax.experiment import metrics as M
from ntq_jax.models import ModelConfig
from ntq_jax.neural import PlannerOptions, choose, plan_batch
from ntq_jax.types import PlanCause

FIELDS = ("paths", "lengths", "success", "costs", "cause", "replans")

# The real PNets' tests share one map, query set, ensemble per dropout rate and planner
# settings: their single members' compiled stages are built once. chunk=16 and
# repair_width=4 give several coarse chunks and several repair calls per member.
PNET_OPTS = PlannerOptions(n_plan=15, replan_rounds=3, replan_steps=6)
PNET_PLAN = {"chunk": 16, "repair_width": 4}
# The stand-ins' tests plan BATCH = 4 rows per call with OPTS (as test_neural_planner.py),
# so the single stand-in's stages are compiled once here too.
STAND_IN_PLAN = {"chunk": 4, "repair_width": 4}


@functools.cache
def _point2():
    env = make_env("point/2")
    q = np.asarray(env.sample_queries(jax.random.key(5), 40, 1.0, padding=0.0)[0], np.float32)
    return env, q


@functools.cache
def _ensemble(dropout):
    """Four members with random weights (cached: built once per dropout rate)."""
    spec = models.ModelSpec.from_env(_point2()[0], ModelConfig(hidden=(32, 32), dropout=dropout))
    return models.init_ensemble(spec, 0, 4)


def _assert_same(a, b, calls_factor):
    """Bit for bit. Exact by construction, not by luck: both programs are compiled in
    this process for this CPU, and a member's rows go through the same per-row
    arithmetic in both (elementwise stages per row; a member's dot over its own rows is
    the same dot whether members are looped or vmapped into a batched dot, whose slices
    use the unbatched kernel). Checked with XLA told 128- and 512-bit vectors
    (``XLA_FLAGS=--xla_cpu_prefer_vector_width=...``); XLA's fast math (non-IEEE
    reassociation, never on by default) does break it."""
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    np.testing.assert_array_equal(a.pnet_calls * calls_factor, b.pnet_calls)


@pytest.mark.parametrize(
    "opts",
    [OPTS, PlannerOptions(n_plan=12, replan_rounds=2, replan_steps=8, bidirectional=True)],
    ids=["forward", "bidirectional"],
)
def test_identical_members_equal_the_single_member_stand_in(opts):
    # a noisy seeker walks through the wall: coarse plans, infeasible paths, replanning
    q = np.asarray(
        [[[2, 5], [8, 5]], [[1, 1], [9, 6]], [[4, 9], [6, 1]], [[2, 2], [8, 8]]], np.float32
    )
    env, net = make("wall"), pnet("wall", SEEKER, sigma=0.7)
    one = plan_batch(env, net, q, jax.random.key(3), opts)
    ens = plan_batch(env, [net] * 4, q, jax.random.key(3), opts)
    assert one.replans.max() >= 1  # replanning ran
    _assert_same(one, ens, 4)


def test_identical_members_equal_the_single_member_pnet():
    """Real PNets (random weights, dropout on) through models.member_pnets.

    A member's dropout key is ``fold_in(step key, m)`` (``member_pnets``, as in
    its own evaluation), so "identical members" means the same parameters *and*
    the same member index: four copies of member 1's PNet plan exactly like
    member 1. An ensemble of four copies of one member's parameters under the
    indices 0..3 draws four different dropout masks (four different candidates):
    only without dropout is it again the single member.
    """
    env, q = _point2()
    for dropout in (0.5, 0.0):
        ens = _ensemble(dropout)
        p1 = models.member_pnets(ens)[1]
        one = plan_batch(env, p1, q, jax.random.key(7), PNET_OPTS, **PNET_PLAN)
        _assert_same(
            one, plan_batch(env, [p1] * 4, q, jax.random.key(7), PNET_OPTS, **PNET_PLAN), 4
        )
        if dropout == 0.0:  # four members with one member's parameters
            same = models.Ensemble(
                ens.graphdef,
                models.stack_states([models.unstack_state(ens.params, 1)] * 4),
                ens.spec,
            )
            _assert_same(
                one,
                plan_batch(
                    env, models.member_pnets(same), q, jax.random.key(7), PNET_OPTS, **PNET_PLAN
                ),
                4,
            )


def test_a_useless_member_does_not_hurt_the_ensemble():
    q = np.asarray(
        [[[2, 5], [8, 5]], [[1, 1], [9, 6]], [[4, 9], [6, 1]], [[2, 2], [8, 8]]], np.float32
    )
    env = make("wall")
    ens = plan_batch(
        env,
        [pnet("wall", STAY), pnet("wall", SEEKER), pnet("wall", ORACLE)],
        q,
        jax.random.key(0),
        OPTS,
    )
    assert np.all(ens.success)
    np.testing.assert_allclose(ens.costs, optimum("wall", q), rtol=1e-4)
    for i in range(len(q)):
        assert shapely_free("wall", ens.path(i))
    # alone, the stay-put member never leaves the start
    alone = plan_batch(env, pnet("wall", STAY), q, jax.random.key(0), OPTS)
    assert not alone.success[0] and alone.cause[0] == PlanCause.NO_PATH


def test_choose_rule_by_hand():
    env = make("wall")  # wall x 4.5..5.5, y 2..8
    cur = jnp.asarray([[2.0, 5.0]])
    tgt = jnp.asarray([[8.0, 5.0]])
    # jitted: one program per candidate count and steer, not every op compiled op by op
    rule = jax.jit(choose, static_argnames=("robot", "padding", "steer"))

    def pick(cands, steer=True):
        c = jnp.asarray(cands, jnp.float32)[:, None, :]
        return int(
            rule(env.robot, env.world, c, cur, tgt, jnp.ones(1, bool), padding=0.0, steer=steer)[0]
        )

    # tier 0 (cur -> c -> goal free) beats a closer cost-to-go; cheapest path among tier 0
    assert pick([[4.0, 5.0], [5.0, 9.0], [5.0, 9.5]]) == 1
    # tier 1 (c sees the goal, cur does not see c) beats tier 2
    assert pick([[4.0, 5.0], [7.0, 5.0]]) == 1
    # tier 2: the free candidate with the lowest cost-to-go, not a closer blocked one
    assert pick([[3.0, 5.0], [4.0, 5.0]]) == 1  # both free from cur, 4 is closer to the goal
    assert pick([[5.0, 5.0], [3.0, 5.0]]) == 1  # (5, 5) is inside the wall
    # tier 3: nothing free, lowest cost-to-go; NaN never wins
    assert pick([[5.0, 5.0], [5.0, 4.0], [np.nan, np.nan]]) == 0
    # ties: the first member; without steerTo only the cost-to-go counts
    assert pick([[3.0, 5.0], [3.0, 5.0]]) == 0
    assert pick([[5.0, 9.5], [7.5, 5.0]], steer=False) == 1


def _saved(success, costs, cause, paths, calls):
    k = len(success)
    return dict(
        queries=np.zeros((k, 2, 2), np.float32),
        paths=np.asarray(paths, np.float32),
        lengths=np.full(k, paths.shape[1], np.int32),
        success=np.asarray(success),
        costs=np.asarray(costs, np.float64),
        cause=np.asarray(cause, np.int8),
        pnet_calls=np.asarray(calls, np.int32),
        replans=np.zeros(k, np.int32),
        ref_costs=np.ones(k),
        ref_status=np.zeros(k, np.int8),
        seconds=1.5,
        compile_seconds=0.5,
    )


def test_best_of_never_costlier_than_a_member_and_succeeds_iff_one_does():
    rng = np.random.default_rng(0)
    k, m = 200, 4
    members = []
    for j in range(m):
        success = rng.random(k) < 0.5
        costs = np.where(success, rng.uniform(1, 3, k), np.inf)
        costs[:3] = [2.0, 2.0, np.inf]  # query 0/1: ties; query 2: every member fails
        success[:3] = [True, True, False]
        cause = np.where(success, 0, rng.choice([1, 2, 3], k))
        length = 3 + j  # members' path buffers of different lengths
        paths = np.full((k, length, 2), float(j), np.float32)
        members.append(_saved(success, costs, cause, paths, np.full(k, j + 1)))
        members[-1]["lengths"] = np.full(k, length, np.int32)
    cause2 = np.array([members[j]["cause"][2] for j in range(m)])
    best = M.best_of(members)
    succ = np.stack([z["success"] for z in members])
    cost = np.stack([np.where(z["success"], z["costs"], np.inf) for z in members])
    np.testing.assert_array_equal(best["success"], succ.any(axis=0))
    assert np.all(best["costs"][:, None] <= cost.T)  # never costlier than any member's success
    np.testing.assert_array_equal(best["costs"], cost.min(axis=0))
    assert np.all(np.isinf(best["costs"][~best["success"]]))
    np.testing.assert_array_equal(best["cause"] == PlanCause.SUCCESS, best["success"])
    # the kept path is the chosen member's; ties go to the first member
    j = best["member"]
    assert j[0] == 0 and j[1] == 0
    for i in range(k):
        n = best["lengths"][i]
        assert n == members[j[i]]["lengths"][i]
        assert np.all(best["paths"][i, :n] == j[i]) and np.all(np.isnan(best["paths"][i, n:]))
        if best["success"][i]:
            assert members[j[i]]["success"][i] and best["costs"][i] == members[j[i]]["costs"][i]
    # every member fails on query 2: the failure closest to a success is kept
    rank = {0: 0, 2: 1, 1: 2, 3: 3}
    assert best["cause"][2] == min(cause2, key=lambda c: rank[int(c)])
    # the work of every member: calls and seconds summed
    np.testing.assert_array_equal(best["pnet_calls"], np.full(k, 1 + 2 + 3 + 4))
    assert best["seconds"] == pytest.approx(6.0) and best["compile_seconds"] == pytest.approx(2.0)
    with pytest.raises(ValueError):
        M.best_of([])


def test_eval_ensemble_option():
    from ntq_jax.experiment.config import ConfigError
    from ntq_jax.experiment.pipeline import load_config

    default = load_config(None, [])
    assert default.eval.ensemble is None and default.eval.ensemble_rows == (
        "ens",
        "best",
        "cascade",
    )
    assert "ensemble" not in default.to_dict()["eval"]  # the default config hashes as before
    assert load_config(None, ["eval.ensemble=[best]"]).eval.ensemble_rows == ("best",)
    off = load_config(None, ["eval.ensemble=[]"])
    assert off.eval.ensemble_rows == () and off.hash() != default.hash()
    for bad in ("[foo]", "[ens,ens]", "ens"):
        with pytest.raises(ConfigError, match="eval.ensemble"):
            load_config(None, [f"eval.ensemble={bad}"])


# ---------------------------------------------------------------------------
# Members side by side (plan_members) and as fallbacks (plan_cascade)
# ---------------------------------------------------------------------------


def _assert_equal_results(a, b):
    """Bit for bit, for the reason :func:`_assert_same` gives."""
    for f in FIELDS + ("pnet_calls",):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


def test_group_chunks_of_one_group_are_padded_chunks():
    from ntq_jax.batching import group_chunks, padded_chunks

    rows = np.arange(11) * 3
    got = list(group_chunks([rows], 4))
    want = list(padded_chunks([rows], 4))
    assert len(got) == len(want) == 3
    for (lo, idx, mask), (lo2, _, (pad,), mask2) in zip(got, want):
        assert lo == lo2
        np.testing.assert_array_equal(idx, pad)
        np.testing.assert_array_equal(mask, mask2)
    # several groups: the longest sets the number of chunks, shorter blocks are padding
    ((lo, idx, mask),) = group_chunks([np.array([5, 6]), np.array([], int), np.array([9])], 2)
    np.testing.assert_array_equal(idx, [5, 6, 0, 0, 9, 0])
    np.testing.assert_array_equal(mask, [1, 1, 0, 0, 1, 0])


@pytest.mark.parametrize("real", [False, True], ids=["stand-ins", "pnets"])
def test_plan_members_equals_each_member_alone(real):
    """Members side by side in one batch plan exactly like each member alone, with its key
    (stand-ins: the per-member loop; real PNets of one ensemble: the vmapped members)."""
    from ntq_jax.neural import plan_members

    if real:
        env, q = _point2()
        nets = models.member_pnets(_ensemble(0.5))[:3]
        opts, plan = PNET_OPTS, PNET_PLAN
    else:
        env = make("wall")
        q = np.asarray(
            [
                [[2, 5], [8, 5]],
                [[1, 1], [9, 6]],
                [[4, 9], [6, 1]],
                [[2, 2], [8, 8]],
                [[1, 5], [9, 5]],
            ],
            np.float32,
        )
        nets = [pnet("wall", SEEKER, sigma=0.7), pnet("wall", STAY), pnet("wall", ORACLE)]
        opts, plan = OPTS, STAND_IN_PLAN
    keys = jnp.stack([jax.random.key(m + 10) for m in range(3)])
    together = plan_members(env, nets, q, keys, opts, **plan)
    alone = [plan_batch(env, n, q, keys[m], opts, **plan) for m, n in enumerate(nets)]
    assert sum(int(r.replans.max()) for r in alone) >= 1  # replanning ran
    for a, b in zip(alone, together):
        _assert_equal_results(a, b)
    # one key for all: each member with that key
    one = plan_members(env, nets, q, jax.random.key(4), opts, **plan)
    _assert_equal_results(plan_batch(env, nets[1], q, jax.random.key(4), opts, **plan), one[1])
    with pytest.raises(ValueError, match="keys"):
        plan_members(env, nets, q, keys[:2], opts)


def test_cascade_keeps_the_first_success_and_replans_only_the_failures():
    from ntq_jax.neural import plan_cascade

    env = make("wall")
    q = np.asarray(
        [
            [[2, 5], [8, 5]],
            [[1, 1], [9, 6]],
            [[4, 9], [6, 1]],
            [[2, 2], [8, 8]],
            [[3, 3], [3.5, 3.5]],
        ],
        np.float32,
    )
    nets = [pnet("wall", STAY), pnet("wall", SEEKER, sigma=0.7), pnet("wall", ORACLE)]
    key = jax.random.key(2)
    plan = STAND_IN_PLAN  # 5 queries: two chunks of BATCH rows
    res = plan_cascade(env, nets, q, key, OPTS, order=[0, 1, 2], **plan)
    # attempt by attempt, by hand
    a0 = plan_batch(env, nets[0], q, jax.random.fold_in(key, 0), OPTS, **plan)
    left = np.flatnonzero(~a0.success)
    assert a0.success[4] and len(left) == 4  # the stay-put member solves only the free query
    a1 = plan_batch(env, nets[1], q[left], jax.random.fold_in(key, 1), OPTS, rows=len(q), **plan)
    left2 = left[~a1.success]
    assert res.success.all() and res.member[4] == 0
    np.testing.assert_array_equal(res.member[left[a1.success]], 1)
    np.testing.assert_array_equal(res.member[left2], 2)
    np.testing.assert_allclose(res.costs[left2], optimum("wall", q[left2]), rtol=1e-4)
    np.testing.assert_array_equal(res.costs[left[a1.success]], a1.costs[a1.success])
    np.testing.assert_array_equal(res.costs[4], a0.costs[4])
    # the work: attempt 0 on every query, attempt 1 on its 4 failures
    assert res.pnet_calls[4] == a0.pnet_calls[4]
    for i, j in enumerate(left):
        assert res.pnet_calls[j] >= a0.pnet_calls[j] + a1.pnet_calls[i]
    for i in range(len(q)):
        assert shapely_free("wall", res.path(i))
    # a useless member alone: failures keep the closest cause; the order is checked
    alone = plan_cascade(env, nets[:1], q, key, OPTS, **plan)
    np.testing.assert_array_equal(alone.cause, a0.cause)
    for bad in ([], [0, 0], [3]):
        with pytest.raises(ValueError, match="order"):
            plan_cascade(env, nets, q, key, OPTS, order=bad)


def test_cascade_compiles_nothing_beyond_its_members_programs():
    """Each attempt plans its (smaller) batch with the whole batch's shapes: once every
    member planned the K queries on its own, the cascade adds no compiled stage."""
    from ntq_jax.neural import plan_cascade, steps

    env = make("wall")
    q = np.asarray(
        [
            [[2, 5], [8, 5]],
            [[1, 1], [9, 6]],
            [[4, 9], [6, 1]],
            [[2, 2], [8, 8]],
            [[3, 3], [3.5, 3.5]],
            [[1, 8], [9, 2]],
            [[2, 6], [8, 4]],
            [[7, 2], [7.5, 2.5]],
            [[2, 8], [2.5, 8.5]],
            [[7, 7], [7.5, 7.5]],
        ],
        np.float32,
    )
    nets = [pnet("wall", SEEKER, sigma=s) for s in (0.05, 0.7, 1.5)]  # 10 queries, then 8 or fewer
    key = jax.random.key(4)
    for net in nets:
        plan_batch(env, net, q, key, OPTS)
    before = set(steps._COMPILED)
    res = plan_cascade(env, nets, q, key, OPTS)
    assert set(steps._COMPILED) <= before
    assert len(np.unique(res.member)) > 1  # later members did plan smaller batches
    with pytest.raises(ValueError, match="rows"):
        plan_batch(env, nets[0], q, key, OPTS, rows=0)
