"""Batched greedy shortcutting (lazy states contraction) against a plain-Python reference.

The reference (:func:`shortcut_reference`) applies the same rule one path at a
time in Python; its visibility oracle is an all-pairs matrix computed with
``env.steer_to`` (the same exact kernel, in the travelled direction). The
jitted batch must pick exactly the same waypoints. Properties checked on
A* grid paths: start and goal kept exactly, every kept segment free under the
exact kernel, cost never increases.
"""

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ntq_jax import Env, make_env, plan
from ntq_jax.planners import check_paths
from ntq_jax.planners.smoothing import shortcut, shortcut_paths, shortcut_reference
from ntq_jax.robots import batch as steer_batch

SET = settings(
    max_examples=8, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


def random_env(seed: int, n_boxes: int = 6, padding: float = 0.0) -> Env:
    rng = np.random.default_rng(seed)
    boxes = np.concatenate(
        [rng.uniform(2, 18, (n_boxes, 2)), rng.uniform(0.4, 2.5, (n_boxes, 2))], 1
    )
    return Env.from_json(
        {
            "name": f"rand{seed}",
            "robot": {"kind": "point"},
            "bounds": [[0, 20], [0, 20]],
            "boxes": boxes.round(3).tolist(),
            "padding": padding,
        }
    )


def reference_batch(env, paths, lengths, padding):
    """The greedy rule per path in plain Python; visibility from one batched steer_to call."""
    b, l, _ = paths.shape
    ii, jj = np.meshgrid(np.arange(l), np.arange(l), indexing="ij")
    a = np.nan_to_num(paths[:, ii.ravel()]).reshape(-1, 2)
    c = np.nan_to_num(paths[:, jj.ravel()]).reshape(-1, 2)
    vis = np.asarray(env.steer_to(a, c, padding=padding)).reshape(b, l, l)
    out = []
    for p, n, v in zip(paths, lengths, vis):
        table = {
            (p[i].tobytes(), p[j].tobytes()): bool(v[i, j]) for i in range(n) for j in range(n)
        }
        out.append(shortcut_reference(lambda x, y, t=table: t[(x.tobytes(), y.tobytes())], p[:n]))
    return out


def polyline_batch(rng, b, l, lo=0.5, hi=19.5):
    """Random NaN-padded polylines (distinct points, generally NOT collision-free)."""
    lengths = rng.integers(2, l + 1, b)
    paths = rng.uniform(lo, hi, (b, l, 2)).astype(np.float32)
    paths[np.arange(l)[None, :] >= lengths[:, None]] = np.nan
    return paths, lengths.astype(np.int32)


@SET
@given(seed=st.integers(0, 2**31 - 1), padding=st.sampled_from([0.0, 0.3]))
def test_matches_plain_python_reference_on_random_polylines(seed, padding):
    env = random_env(seed % 1000, padding=padding)
    rng = np.random.default_rng(seed)
    paths, lengths = polyline_batch(rng, 12, 9)
    out, n_out, ok = shortcut_paths(env.robot, env.world, paths, lengths, padding)
    ref = reference_batch(env, paths, lengths, padding)
    for i, (rp, rok) in enumerate(ref):
        assert n_out[i] == len(rp), (i, n_out[i], len(rp))
        np.testing.assert_array_equal(out[i, : n_out[i]], rp)
        assert ok[i] == rok
        assert np.isnan(out[i, n_out[i] :]).all()


def test_astar_paths_properties_and_reference():
    env = make_env("point/3")
    q, _ = env.sample_queries(jax.random.PRNGKey(3), 48, 0.5)
    q = np.asarray(q)
    raw = plan(env, q, "astar", smooth=False)
    assert raw.solved.all()
    paths, lengths, ok = shortcut_paths(env.robot, env.world, raw.paths, raw.lengths, env.padding)
    assert ok.all()
    # start and goal kept exactly
    np.testing.assert_array_equal(paths[:, 0], q[:, 0])
    np.testing.assert_array_equal(paths[np.arange(len(q)), lengths - 1], q[:, 1])
    # collision-free under the exact kernel, cost never increases
    free, costs = check_paths(env, paths, lengths, env.padding)
    assert free.all()
    assert np.all(costs <= raw.costs * (1 + 1e-9) + 1e-9)
    assert np.mean(costs < raw.costs - 1e-6) > 0.5  # it actually shortens grid paths
    assert lengths.max() < raw.lengths.max()
    # same waypoints as the plain-Python rule
    ref = reference_batch(env, raw.paths[:16], raw.lengths[:16], env.padding)
    for i, (rp, rok) in enumerate(ref):
        np.testing.assert_array_equal(paths[i, : lengths[i]], rp)
        assert rok


def test_blocked_input_is_flagged_and_trivial_paths_kept():
    env = random_env(0)
    box = np.asarray(env.world.boxes)[0]
    cx, cy, hw, hh = (float(v) for v in box)
    a = np.array([cx - hw - 1.0, cy], np.float32)
    b = np.array([cx + hw + 1.0, cy], np.float32)  # a -> b crosses the box
    paths = np.full((3, 4, 2), np.nan, np.float32)
    paths[0, :2] = [a, b]
    paths[1, :1] = [a]
    paths[2, :2] = [a, a]
    out, n, ok = shortcut_paths(env.robot, env.world, paths, np.array([2, 1, 2]), 0.0)
    assert n.tolist() == [2, 1, 2]
    assert ok.tolist() == [False, True, True]
    np.testing.assert_array_equal(out[0, :2], [a, b])


def test_shortcut_paths_compiles_nothing_of_its_own():
    """After one call, batches of other sizes and path widths, and another map with the
    same obstacle counts, reuse the motion check's one chunk program (steer_to_pairs)."""
    env = random_env(1)
    rng = np.random.default_rng(0)
    shortcut_paths(env.robot, env.world, *polyline_batch(rng, 9, 7), env.padding)
    before = (steer_batch._steer_masked._cache_size(), shortcut._cache_size())
    for b, l in [(10, 8), (16, 6), (200, 40), (5000, 3)]:
        shortcut_paths(env.robot, env.world, *polyline_batch(rng, b, l), env.padding)
    other = random_env(2)  # same obstacle count: world is traced, no recompilation
    shortcut_paths(other.robot, other.world, *polyline_batch(rng, 9, 7), other.padding)
    assert (steer_batch._steer_masked._cache_size(), shortcut._cache_size()) == before


@pytest.mark.parametrize("chunk", [1, 5, 4096])
def test_group_size_does_not_change_the_answer(chunk):
    env = random_env(3, padding=0.3)
    paths, lengths = polyline_batch(np.random.default_rng(1), 23, 9)
    ref = shortcut_paths(env.robot, env.world, paths, lengths, 0.3, chunk_size=7)
    got = shortcut_paths(env.robot, env.world, paths, lengths, 0.3, chunk_size=chunk)
    for r, g in zip(ref, got):
        np.testing.assert_array_equal(r, g)


def test_host_rounds_equal_the_traced_core():
    """shortcut_paths (host rounds) and the jitted shortcut (one while_loop) keep the same
    waypoints, lengths and flags."""
    env = random_env(4, padding=0.3)
    paths, lengths = polyline_batch(np.random.default_rng(2), 32, 16)
    out, n, ok = shortcut_paths(env.robot, env.world, paths, lengths, 0.3)
    o2, n2, ok2 = (np.asarray(x) for x in shortcut(env.robot, env.world, paths, lengths, 0.3))
    np.testing.assert_array_equal(n, n2)
    np.testing.assert_array_equal(ok, ok2)
    np.testing.assert_array_equal(out, o2[:, : out.shape[1]])
    assert np.isnan(o2[:, out.shape[1] :]).all()


def test_bad_shapes_rejected():
    env = random_env(1)
    with pytest.raises(ValueError, match="paths must be"):
        shortcut_paths(env.robot, env.world, np.zeros((2, 3, 3), np.float32), np.array([3, 3]), 0.0)
