"""PNet and Ensemble: normalisation, angles, dropout through explicit keys, member slicing."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx

from ntq_jax import make_env, models
from ntq_jax.models import ModelConfig

SMALL = ModelConfig(hidden=(16, 8), dropout=0.5, dropout_layers=1)


@pytest.fixture(scope="module")
def rigid():
    return make_env("rigid/0")


@pytest.fixture(scope="module")
def point():
    return make_env("point/0")


def _net(spec, seed=0) -> models.PNet:
    """One PNet (initialised by the jitted ensemble initialiser: op-by-op eager init is slow)."""
    return models.member(models.init_ensemble(spec, seed, num_members=1), 0)


def _jit(net: models.PNet, fn):
    """``fn(net)`` evaluated in one compiled call."""
    graphdef, state = nnx.split(net)
    return jax.jit(lambda s: fn(nnx.merge(graphdef, s)))(state)


def _constant_output(net: models.PNet, normalised_out):
    """Makes ``net`` output the normalised vector ``normalised_out`` whatever the input."""
    net.out.kernel[...] = jnp.zeros(net.out.kernel.shape)
    net.out.bias[...] = jnp.asarray(normalised_out, jnp.float32)
    return net


def test_periodic_dims():
    assert models.periodic_dims(make_env("point/0").robot) == (False, False)
    assert models.periodic_dims(make_env("rigid/0").robot) == (False, False, True)
    arm = make_env("nlink/2").robot
    assert models.periodic_dims(arm) == (False,) * arm.dim  # the paper's arm does not wrap


def test_normalisation_round_trip(rigid):
    spec = models.ModelSpec.from_env(rigid, SMALL)
    net = _net(spec)
    lo, hi = np.array(spec.lo), np.array(spec.hi)
    q = np.array([[1.0, 2.0, 0.5], [9.0, 0.1, -3.0]], np.float32)
    n_lo, n_hi, back = _jit(
        net, lambda n: (n.normalize(lo), n.normalize(hi), n.denormalize(n.normalize(q)))
    )
    np.testing.assert_allclose(n_lo, -1.0, atol=1e-6)
    np.testing.assert_allclose(n_hi, 1.0, atol=1e-6)
    np.testing.assert_allclose(back, q, atol=1e-5)


def test_rigid_prediction_wrapped_into_range(rigid):
    spec = models.ModelSpec.from_env(rigid, SMALL)
    net = _constant_output(_net(spec), [0.0, 0.0, 1.5])
    c = jnp.zeros((3, 3))
    out = np.asarray(_jit(net, lambda n: n(c, c, deterministic=True)))
    # normalised 1.5 is 1.5 pi rad, i.e. -0.5 pi after wrapping into [-pi, pi)
    np.testing.assert_allclose(out[:, 2], -0.5 * math.pi, atol=1e-5)
    assert np.all(out[:, 2] >= -math.pi) and np.all(out[:, 2] < math.pi)


def test_shortest_arc_loss_for_angles_only():
    """Predicting pi - 0.01 for a target of -pi + 0.01 costs 0.02 rad on the rigid body,
    while the same numbers on a (non-wrapping) arm joint cost the long way round."""
    rigid, arm = make_env("rigid/0"), make_env("nlink/2")
    for env, periodic in ((rigid, True), (arm, False)):
        spec = models.ModelSpec.from_env(env, SMALL)
        net = _net(spec, 1)
        d, k = spec.dim, spec.dim - 1  # the last coordinate: theta, or the 2nd joint
        target = np.zeros((1, d), np.float32)
        target[0, k] = -math.pi + 0.01
        pred = target.copy()
        pred[0, k] = math.pi - 0.01
        lo, hi = np.array(spec.lo), np.array(spec.hi)
        _constant_output(net, (2 * (pred - lo) / (hi - lo) - 1)[0])
        inputs = jnp.zeros((1, 2 * d))
        loss = float(
            _jit(net, lambda n: n.loss(inputs, target, jnp.ones(1), None, deterministic=True))
        )
        short, long = 0.02 / math.pi, 2.0 - 0.02 / math.pi  # normalised errors
        expect = (short if periodic else long) ** 2 / d
        assert loss == pytest.approx(expect, rel=1e-3), env.name


def test_masked_loss_ignores_padding(point):
    spec = models.ModelSpec.from_env(point, SMALL)
    net = _net(spec, 2)
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 20, (6, 4)).astype(np.float32)
    y = rng.uniform(0, 20, (6, 2)).astype(np.float32)
    garbage_y = y.copy()
    garbage_y[4:] = 1e6
    a, b = _jit(
        net,
        lambda n: (
            n.loss(x[:4], y[:4], jnp.ones(4), None, deterministic=True),
            n.loss(x, garbage_y, jnp.array([1, 1, 1, 1, 0, 0.0]), None, deterministic=True),
        ),
    )
    np.testing.assert_allclose(a, b, rtol=1e-6)


def test_architecture_matches_config(point):
    cfg = ModelConfig(hidden=(1280, 1024, 896, 768, 512, 384, 256, 256, 128, 64, 32))
    spec = models.ModelSpec.from_env(point, cfg)
    net = nnx.eval_shape(lambda: models.PNet(spec, rngs=nnx.Rngs(0)))
    widths = [lin.kernel.shape for lin in net.layers]
    assert widths[0] == (4, 1280) and widths[-1] == (64, 32) and len(widths) == 11
    assert net.out.kernel.shape == (32, 2)
    assert all(act.negative_slope.shape == () for act in net.acts)  # one PReLU slope per layer


def test_ensemble_stacks_members(point):
    spec = models.ModelSpec.from_env(point, SMALL)
    ens = models.init_ensemble(spec, 0)
    assert ens.num_members == 4
    assert all(leaf.shape[0] == 4 for leaf in jax.tree.leaves(ens.params))
    k0, k1 = np.asarray(ens.params["layers"][0]["kernel"][...])[:2]
    assert not np.allclose(k0, k1)  # members start from different weights
    # keyed by member id, not by M: member 2 alone starts where it does in the ensemble
    alone = models.init_ensemble(spec, 0, member_ids=[2])
    for a, b in zip(jax.tree.leaves(ens.params), jax.tree.leaves(alone.params)):
        np.testing.assert_array_equal(a[2], b[0])


def test_predictor_dropout_active_and_members_consistent(point):
    spec = models.ModelSpec.from_env(point, SMALL)
    ens = models.init_ensemble(spec, 0)
    rng = np.random.default_rng(1)
    cur = rng.uniform(0, 20, (32, 2)).astype(np.float32)
    goal = rng.uniform(0, 20, (32, 2)).astype(np.float32)

    @jax.jit  # one compilation for all the variants
    def run(key, other_key):
        out = models.predictor(ens)(key, cur, goal)
        det = models.predictor(ens, 1, deterministic=True)
        return (
            out,
            models.predictor(ens)(other_key, cur, goal),
            models.predictor(ens, 3)(key, cur, goal),
            det(key, cur, goal),
            det(other_key, cur, goal),
        )

    out, other, one, det_a, det_b = run(jax.random.key(7), jax.random.key(8))
    assert out.shape == (4, 32, 2)
    np.testing.assert_array_equal(out, run(jax.random.key(7), jax.random.key(8))[0])  # pure
    assert not np.allclose(out, other)  # dropout is on at planning time
    np.testing.assert_allclose(one, out[3], rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(det_a, det_b)
    with pytest.raises(ValueError, match="member"):
        models.predictor(ens, 4)


def test_no_dropout_layers_is_deterministic(point):
    spec = models.ModelSpec.from_env(
        point, ModelConfig(hidden=(8, 8), dropout=0.5, dropout_layers=0)
    )
    ens = models.init_ensemble(spec, 0, num_members=2)
    fn = jax.jit(models.predictor(ens))
    c = jnp.ones((3, 2))
    np.testing.assert_array_equal(fn(jax.random.key(0), c, c), fn(jax.random.key(1), c, c))
