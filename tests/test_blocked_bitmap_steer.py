"""The point robot's indexed steer_to against the unindexed exact kernel (issue 18), continued
from test_blocked_bitmap.py (split off so that the test runner's two workers, which take whole
files, share the work more evenly): the benchmark maze through Env (with a mask), and arbitrary
overlapping, unaligned boxes where the blocked-cell bitmap is only conservative."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ntq_jax as nj
from ntq_jax import broadphase, geometry, grid_maps
from ntq_jax.geometry import World
from ntq_jax.robots import PointRobot

MAX_K = 24  # an index cell's candidate rows are padded to 2 * MAX_K (test_blocked_bitmap.py's)


def _exact(a, b, world, padding):
    """The unindexed exact kernel (the reference)."""
    return jax.vmap(geometry.segment_free, in_axes=(1, 1, None, None))(
        a, b, dataclasses.replace(world, index=None), padding
    )


MAZE_PADS = (0.0, 0.2)


@functools.partial(jax.jit, static_argnums=3)
def _indexed_and_exact(a, b, worlds, paddings):
    """``[(indexed, exact), ...]`` at each padding (static) on its world (its own index, the
    same boxes): one compiled program for all the cases, as :func:`_exact_and_masked` (the
    exact kernel, which does not use the index, once per padding)."""
    exact = {p: _exact(a, b, worlds[paddings.index(p)], p) for p in paddings}
    return [(PointRobot().steer_to_batch(a, b, w, p), exact[p]) for w, p in zip(worlds, paddings)]


@functools.partial(jax.jit, static_argnums=3)
def _exact_and_masked(a, b, worlds, paddings, mask):
    """``[(exact, masked indexed), ...]`` at each padding (static) on its world: one compiled
    program for all of a test's paddings (they are static, and one program compiles in about
    60% of the CPU time of the separate ones)."""
    return [
        (_exact(a, b, w, p), PointRobot().steer_to_batch(a, b, w, p, mask))
        for w, p in zip(worlds, paddings)
    ]


@pytest.fixture(scope="module")
def maze(tmp_path_factory):
    """The benchmark maze's Env, its test pairs and mask, and the exact and masked answers
    at each of :data:`MAZE_PADS` (computed once, for both paddings' tests)."""
    path = grid_maps.write_movingai(
        tmp_path_factory.mktemp("maze") / "maze.map", grid_maps.maze_grid(64, seed=4)
    )
    env = nj.make_env(path, padding=0.2)
    rng = np.random.default_rng(1)
    n = 6000
    a = rng.uniform(0, 64, (n, 2))
    b = np.where(
        rng.random((n, 1)) < 0.5, a + rng.normal(0, 1.5, a.shape), rng.uniform(0, 64, (n, 2))
    )
    v = rng.integers(0, 65, (n // 2, 2)).astype(np.float64)
    a = np.concatenate([a, v]).astype(np.float32)
    b = np.concatenate([b, v + rng.integers(-3, 4, v.shape)]).astype(np.float32)
    # non-finite and out-of-bounds ends: blocked, unchecked
    a[:4] = [[np.nan, 3.0], [np.inf, 5.0], [-1.0, 5.5], [30.5, 70.0]]
    # a mask (as the planners pass it)
    mask = rng.random(len(a)) < 0.7
    out = _exact_and_masked(
        jnp.asarray(a.T),
        jnp.asarray(b.T),
        [env.world] * len(MAZE_PADS),
        MAZE_PADS,
        jnp.asarray(mask),
    )
    answers = {p: tuple(np.asarray(x) for x in r) for p, r in zip(MAZE_PADS, out)}
    return env, a, b, mask, answers


@pytest.mark.parametrize("pad", MAZE_PADS)
def test_maze_steer_equals_exact(maze, pad):
    """The 256 x 256 benchmark maze through Env (the bitmap path, queue tail included): random
    pairs, short pairs and grid-vertex pairs against the unindexed exact kernel."""
    env, a, b, mask, answers = maze
    assert env.world.index is not None and env.world.index.blocked is not None
    ref, masked = answers[pad]
    got = np.asarray(env.steer_to(a, b, padding=pad))
    np.testing.assert_array_equal(got, ref)
    assert 0 < got.sum() < len(got)
    # with the mask: the masked-out motions are blocked, the others unchanged
    np.testing.assert_array_equal(masked, ref & mask)


BOX_CELLS = (0.5, 1.0)  # the index cells
BOX_PADS = (0.0, 0.1, 0.3)


@given(seed=st.integers(0, 10**6))
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_indexed_steer_equals_exact_on_random_boxes(seed):
    """Arbitrary (overlapping, unaligned) boxes: the bitmap is only conservative there;
    segments uniform, short, and from box corners and edges; every map with each index cell
    of :data:`BOX_CELLS` at each padding of :data:`BOX_PADS` (one compiled program)."""
    rng = np.random.default_rng(seed)
    n = 100
    # centres in [2, 18], half sizes in [0.3, 2] with one of exactly 0.3: the bitmap's cell and
    # margin, hence the compiled program, depend only on the index cell
    boxes = np.c_[rng.uniform(2, 18, (n, 2)), rng.uniform(0.3, 2.0, (n, 2))].astype(np.float32)
    boxes[0, 2:] = 0.3
    world = World.create([[0, 20], [0, 20]], boxes)
    sentinel = np.asarray(broadphase.SENTINEL_BOX, np.float32)
    worlds, cases = [], []
    for cell in BOX_CELLS:
        for pad in BOX_PADS:
            index = broadphase.build_index(world.bounds, world.boxes, pad + 0.5 * cell, cell)
            k = index.capacity
            if k > 2 * MAX_K or index.blocked is None:
                return
            table = np.asarray(index.boxes)  # padded in NumPy: no small program compiled per map
            table = np.concatenate(
                [table, np.broadcast_to(sentinel, (table.shape[0], 2 * MAX_K - k, 4))], axis=1
            )
            worlds.append(
                dataclasses.replace(
                    world, index=dataclasses.replace(index, boxes=jnp.asarray(table))
                )
            )
            assert worlds[-1].index.blocked is not None
            cases.append((cell, pad))
    m = 3000
    a = rng.uniform(0, 20, (m, 2))
    b = np.where(
        rng.random((m, 1)) < 0.5, a + rng.normal(0, 1.5, a.shape), rng.uniform(0, 20, (m, 2))
    )
    # box corners and points on box edges as endpoints
    j = rng.integers(0, n, m // 3)
    corner = boxes[j, :2] + boxes[j, 2:] * rng.choice([-1.0, 1.0], (m // 3, 2))
    a[: m // 3] = corner
    edge = (
        boxes[j, :2]
        + boxes[j, 2:] * np.c_[rng.uniform(-1, 1, m // 3), rng.choice([-1.0, 1.0], m // 3)]
    )
    b[m // 3 : 2 * (m // 3)] = edge
    a, b = (jnp.asarray(np.clip(v, 0, 20).T.astype(np.float32)) for v in (a, b))
    pads = tuple(pad for _, pad in cases)
    for (cell, pad), (got, ref) in zip(cases, _indexed_and_exact(a, b, worlds, pads)):
        np.testing.assert_array_equal(
            np.asarray(got), np.asarray(ref), err_msg=f"cell {cell}, padding {pad}"
        )
