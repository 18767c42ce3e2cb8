"""Probabilistic pruning (the paper's Sec. VI; issue 14 item 2): ``prune`` = a probability or ``gamma``.

One run on point/2 with grid A* (deterministic) lists datasets that all share the
non-trivial pool (p_nt = 1): Alg. 4 without and with pruning, probabilistic
pruning at 0, 1, 0.5 and ``gamma``. p = 0 must equal no pruning and p = 1 Alg. 4's
pruning, bit for bit, in every array.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ntq_jax import Env, data, make_env
from ntq_jax.data.include import prune_rng
from ntq_jax.experiment import config as C
from ntq_jax.experiment.config import ConfigError

K = 150
ARRAYS = (
    "inputs",
    "targets",
    "path_index",
    "paths",
    "path_lengths",
    "queries",
    "query_kind",
    "solved",
)
SPECS = [
    {"p_nt": 1.0},
    {"p_nt": 1.0, "prune": True},
    {"p_nt": 1.0, "prune": 0.0},
    {"p_nt": 1.0, "prune": 1},
    {"p_nt": 1.0, "prune": 0.5},
    {"name": "D5", "p_nt": 1.0, "prune": "gamma"},
    {"name": "D6", "p_nt": 1.0, "prune": "keep_last"},
]


def _config(chunk=64, seed=0):
    sets = {
        "seed": seed,
        "data.k_train": K,
        "data.chunk": chunk,
        "data.gamma_queries": 20_000,
        "data.gamma_eval": False,
        "planner.name": "astar",
        "data.datasets": SPECS,
    }
    return C.load(None, [f"{k}={json.dumps(v)}" for k, v in sets.items()])


def _generate(out, **kw):
    env = make_env("point/2")
    data.generate_datasets(
        env,
        C.data_options(_config(**kw), "point/2"),
        out,
        env_name="point/2",
        progress=False,
        figure=False,
    )
    return env, data.load_datasets(out / "point_2")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return _generate(tmp_path_factory.mktemp("prune"))


def _arrays(d):
    return {a: np.asarray(getattr(d, a)) for a in ARRAYS}


def _same(a, b):
    for name in ARRAYS:
        x, y = a[name], b[name]
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert x.tobytes() == y.tobytes(), name


def test_probability_zero_is_no_pruning_and_one_is_pruning_bit_for_bit(run):
    _, ds = run
    _same(_arrays(ds[2]), _arrays(ds[0]))  # prune: 0.0 == prune: false (D2)
    _same(_arrays(ds[3]), _arrays(ds[1]))  # prune: 1 == prune: true (D3)
    assert len(ds[1].inputs) < len(ds[0].inputs)  # the map has trivial remainders to prune
    assert ds[2].meta["p_prune"] == 0.0 and ds[3].meta["p_prune"] == 1.0
    assert ds[0].meta["p_prune"] == 0.0 and ds[1].meta["p_prune"] == 1.0


def _free(env, d):
    inp = np.asarray(d.inputs)
    return np.asarray(env.steer_to(inp[:, :2], inp[:, 2:], padding=d.meta["prune_padding"]))


def _check_partial(env, full, part, p):
    """``part`` = ``full`` minus some free samples; returns the kept fraction of free ones."""
    a, b = np.asarray(full.inputs), np.asarray(part.inputs)
    rows_a = {
        r.tobytes(): i
        for i, r in enumerate(
            np.concatenate([a, np.asarray(full.targets), np.asarray(full.path_index)[:, None]], 1)
        )
    }
    rows_b = np.concatenate([b, np.asarray(part.targets), np.asarray(part.path_index)[:, None]], 1)
    kept = np.array([rows_a[r.tobytes()] for r in rows_b])  # every kept sample is one of D2's
    assert np.all(np.diff(kept) > 0)  # in D2's order
    free = _free(env, full)
    mask = np.zeros(len(a), bool)
    mask[kept] = True
    assert np.all(mask[~free])  # non-trivial samples are never pruned
    for name in ("paths", "path_lengths", "queries", "query_kind", "solved"):
        assert np.array_equal(
            np.asarray(getattr(full, name)),
            np.asarray(getattr(part, name)),
            equal_nan=name == "paths",
        )
    return mask[free].mean(), int(free.sum())


def test_half_keeps_about_half_of_the_trivial_remainder(run):
    env, ds = run
    frac, n_free = _check_partial(env, ds[0], ds[4], 0.5)
    sd = np.sqrt(0.25 / n_free)
    assert n_free > 100 and abs(frac - 0.5) < 4 * sd, (frac, n_free)
    assert ds[4].meta["prune"] == 0.5 and ds[4].meta["p_prune"] == 0.5
    st = ds[4].meta["stats"]
    assert st["pruned"] == len(ds[0].inputs) - len(ds[4].inputs) > 0


def test_gamma_uses_the_maps_gamma_at_the_data_padding(run):
    env, ds = run
    m = ds[5].meta
    g = m["gamma_nt"]["gamma"]
    assert m["prune"] == "gamma" and m["gamma_nt"]["padding"] == env.padding
    assert 0 < g < 1 and m["p_prune"] == g
    frac, n_free = _check_partial(env, ds[0], ds[5], g)
    assert abs(frac - (1 - g)) < 4 * np.sqrt(g * (1 - g) / n_free)


def test_keep_last_is_pruning_plus_each_paths_step_into_the_goal(run):
    """D6 (prune: keep_last) keeps exactly D2's samples that are blocked or the last of their
    path, in D2's order; everything but the samples is D2's."""
    env, ds = run
    full, part = ds[0], ds[6]
    pidx = np.asarray(full.path_index)
    last = np.r_[pidx[1:] != pidx[:-1], True]  # samples are in path order: a path's last row
    want = ~_free(env, full) | last
    for name in ("inputs", "targets", "path_index"):
        assert np.array_equal(
            np.asarray(getattr(part, name)), np.asarray(getattr(full, name))[want]
        )
    assert np.array_equal(np.asarray(part.paths), np.asarray(full.paths), equal_nan=True)
    assert last.sum() == len(np.unique(pidx)) and (last & _free(env, full)).sum() > 0
    # D3 (prune: true) is D6 without the free last steps
    d3 = np.asarray(ds[1].inputs)
    assert len(d3) == len(part.inputs) - int((last & _free(env, full)).sum())
    assert part.meta["prune"] == "keep_last" and part.meta["p_prune"] == 1.0


def test_keep_last_on_a_hand_made_path():
    """A path of 4 waypoints on an empty map: every waypoint sees the goal, so pruning keeps
    nothing and keep_last keeps the one step into the goal."""
    env = Env.from_json(
        {
            "name": "empty",
            "robot": {"kind": "point"},
            "bounds": [[0, 10], [0, 10]],
            "boxes": [],
            "discs": [],
            "padding": 0.0,
        }
    )
    path = np.array([[[1, 1], [2, 2], [3, 3], [4, 4]]], np.float32)
    i0, t0, _ = data.include_data(env, path, [4], prune=True)
    i1, t1, p1 = data.include_data(env, path, [4], prune=True, keep_last=True)
    i2, _, _ = data.include_data(env, path, [4], prune=False, keep_last=True)
    assert len(i0) == 0 and len(i2) == 3  # without pruning keep_last changes nothing
    assert i1.tolist() == [[3, 3, 4, 4]] and t1.tolist() == [[4, 4]] and p1.tolist() == [0]


def test_the_draws_depend_on_seed_env_and_name_only():
    u = prune_rng(0, "point_2", "D4").random(1000)
    assert np.array_equal(u, prune_rng(0, "point_2", "D4").random(1000))
    # a prefix of the samples gets a prefix of the draws
    assert np.array_equal(u[:300], prune_rng(0, "point_2", "D4").random(300))
    for other in (
        prune_rng(1, "point_2", "D4"),
        prune_rng(0, "point_3", "D4"),
        prune_rng(0, "point_2", "D5"),
    ):
        assert not np.array_equal(u, other.random(1000))


def test_deterministic_and_independent_of_chunking(run, tmp_path):
    _, ds = run
    _, again = _generate(tmp_path / "a", chunk=37)
    for j in range(len(SPECS)):
        _same(_arrays(again[j]), _arrays(ds[j]))


def test_include_data_needs_rng_for_a_probability():
    env = make_env("point/2")
    paths = np.zeros((1, 2, 2), np.float32)
    with pytest.raises(ValueError, match="rng"):
        data.include_data(env, paths, [2], prune=0.5)
    with pytest.raises(ValueError, match="probability"):
        data.include_data(env, paths, [2], prune=1.5)


@pytest.mark.parametrize(
    "value, msg",
    [
        ("1.5", "must be in [0, 1]"),
        ("-0.2", "must be in [0, 1]"),
        ("gama", "'gamma'"),
        ("keep_first", "'keep_last'"),
        ("null", "got null"),
        ("[0.5]", "expected bool or float or str"),
    ],
)
def test_bad_prune_values_name_the_key(value, msg):
    with pytest.raises(ConfigError) as e:
        C.load(None, [f"data.datasets=[{{p_nt: 1.0, prune: {value}}}]"])
    assert "data.datasets[0].prune" in str(e.value) and msg in str(e.value)


def test_config_syntax_and_name_check():
    cfg = C.load(
        None,
        [
            "data.datasets=[{p_nt: 0.0}, {p_nt: 0.5}, {p_nt: 1.0}, "
            "{p_nt: 1.0, prune: true}, {name: D4, p_nt: 1.0, prune: gamma}]"
        ],
    )
    assert [d.prune for d in cfg.data.datasets] == [False, False, False, True, "gamma"]
    assert C.load(None, ["data.datasets=[{p_nt: 1, prune: 0.3}]"]).data.datasets[0].prune == 0.3
    with pytest.raises(ConfigError, match=r"datasets\[1\].name.*entry 1 is D1"):
        C.load(None, ["data.datasets=[{p_nt: 0.0}, {name: D4, p_nt: 1.0, prune: gamma}]"])
    # the default config (and its hash) is the paper's four datasets, unchanged
    d = C.load().to_dict()["data"]["datasets"]
    assert d == [
        {"p_nt": 0.0, "prune": False},
        {"p_nt": 0.5, "prune": False},
        {"p_nt": 1.0, "prune": False},
        {"p_nt": 1.0, "prune": True},
    ]
