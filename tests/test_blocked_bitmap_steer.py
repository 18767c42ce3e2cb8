"""The point robot's indexed steer_to against the unindexed exact kernel (issue 18), continued
from test_blocked_bitmap.py (split off so that the test runner's two workers, which take whole
files, share the work more evenly): the benchmark maze through Env (with a mask), and arbitrary
overlapping, unaligned boxes where the blocked-cell bitmap is only conservative."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import ntq_jax as nj
from ntq_jax import broadphase, geometry, grid_maps
from ntq_jax.geometry import World
from ntq_jax.robots import PointRobot

MAX_K = 24  # an index cell's candidate rows are padded to 2 * MAX_K (test_blocked_bitmap.py's)

_exact = jax.jit(lambda a, b, world, padding: jax.vmap(geometry.segment_free, in_axes=(1, 1, None, None))(
    a, b, world, padding), static_argnums=3)
_indexed = jax.jit(lambda a, b, world, padding: PointRobot().steer_to_batch(a, b, world, padding),
                   static_argnums=3)


@pytest.mark.parametrize("pad", [0.0, 0.2])
def test_maze_steer_equals_exact(tmp_path, pad):
    """The 256 x 256 benchmark maze through Env (the bitmap path, queue tail included): random
    pairs, short pairs and grid-vertex pairs against the unindexed exact kernel."""
    path = grid_maps.write_movingai(tmp_path / "maze.map", grid_maps.maze_grid(64, seed=4))
    env = nj.make_env(path, padding=0.2)
    assert env.world.index is not None and env.world.index.blocked is not None
    rng = np.random.default_rng(1)
    n = 6000
    a = rng.uniform(0, 64, (n, 2))
    b = np.where(rng.random((n, 1)) < 0.5, a + rng.normal(0, 1.5, a.shape), rng.uniform(0, 64, (n, 2)))
    v = rng.integers(0, 65, (n // 2, 2)).astype(np.float64)
    a = np.concatenate([a, v]).astype(np.float32)
    b = np.concatenate([b, v + rng.integers(-3, 4, v.shape)]).astype(np.float32)
    # non-finite and out-of-bounds ends: blocked, unchecked
    a[:4] = [[np.nan, 3.0], [np.inf, 5.0], [-1.0, 5.5], [30.5, 70.0]]
    got = np.asarray(env.steer_to(a, b, padding=pad))
    ref = np.asarray(_exact(jnp.asarray(a.T), jnp.asarray(b.T),
                            dataclasses.replace(env.world, index=None), pad))
    np.testing.assert_array_equal(got, ref)
    assert 0 < got.sum() < len(got)
    # a mask (as the planners pass it): the masked-out motions are blocked, the others unchanged
    mask = jnp.asarray(rng.random(len(a)) < 0.7)
    masked = jax.jit(lambda a, b, w, m: PointRobot().steer_to_batch(a, b, w, pad, m))(
        jnp.asarray(a.T), jnp.asarray(b.T), env.world, mask)
    np.testing.assert_array_equal(np.asarray(masked), ref & np.asarray(mask))


@given(seed=st.integers(0, 10 ** 6), cell=st.sampled_from([0.5, 1.0]), pad=st.sampled_from([0.0, 0.1, 0.3]))
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_indexed_steer_equals_exact_on_random_boxes(seed, cell, pad):
    """Arbitrary (overlapping, unaligned) boxes: the bitmap is only conservative there;
    segments uniform, short, and from box corners and edges."""
    rng = np.random.default_rng(seed)
    n = 100
    # centres in [2, 18], half sizes in [0.3, 2] with one of exactly 0.3: the bitmap's cell and
    # margin, hence the compiled program, depend only on the index cell
    boxes = np.c_[rng.uniform(2, 18, (n, 2)), rng.uniform(0.3, 2.0, (n, 2))].astype(np.float32)
    boxes[0, 2:] = 0.3
    world = World.create([[0, 20], [0, 20]], boxes)
    index = broadphase.build_index(world.bounds, world.boxes, pad + 0.5 * cell, cell)
    k = index.capacity
    if k > 2 * MAX_K or index.blocked is None:
        return
    sentinel = jnp.asarray(broadphase.SENTINEL_BOX, jnp.float32)
    table = jnp.concatenate([index.boxes, jnp.broadcast_to(sentinel, (index.boxes.shape[0], 2 * MAX_K - k, 4))],
                            axis=1)
    world = dataclasses.replace(world, index=dataclasses.replace(index, boxes=table))
    assert world.index.blocked is not None
    m = 3000
    a = rng.uniform(0, 20, (m, 2))
    b = np.where(rng.random((m, 1)) < 0.5, a + rng.normal(0, 1.5, a.shape), rng.uniform(0, 20, (m, 2)))
    # box corners and points on box edges as endpoints
    j = rng.integers(0, n, m // 3)
    corner = boxes[j, :2] + boxes[j, 2:] * rng.choice([-1.0, 1.0], (m // 3, 2))
    a[: m // 3] = corner
    edge = boxes[j, :2] + boxes[j, 2:] * np.c_[rng.uniform(-1, 1, m // 3), rng.choice([-1.0, 1.0], m // 3)]
    b[m // 3: 2 * (m // 3)] = edge
    a, b = (jnp.asarray(np.clip(v, 0, 20).T, jnp.float32) for v in (a, b))
    got = np.asarray(_indexed(a, b, world, pad))
    ref = np.asarray(_exact(a, b, dataclasses.replace(world, index=None), pad))
    np.testing.assert_array_equal(got, ref)
