"""The Panda's checks against independent references, at small size (one scene).

The comparisons of ``benchmarks/bench_panda.py check`` (protocols in
``benchmarks/panda_reference.py``; the full runs, 10^5 configurations and 10^4 motions
in each of the 7 scenes, are committed in ``results/panda_checks/``): ``Env.is_valid``,
obstacle collision and self-collision against coal on configurations half uniform and
half near the boundary of the valid set, and the certified ``steer_to`` against a dense
discretised check (1/640 rad) on short, long and grazing motions.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import ntq_jax as nj

pytest.importorskip("coal")

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def ref():
    spec = importlib.util.spec_from_file_location(
        "panda_reference", REPO / "benchmarks" / "panda_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def cage():
    return nj.make_env("panda/cage/1")


def test_validity_matches_coal(ref, cage):
    q = ref.sample_configs(cage, 0, 400)
    out = ref.compare_validity(cage, q)
    for name in ("valid", "obstacle_free", "self_free"):
        assert out[name]["disagree"] == 0, (name, out[name], out["disagreeing_configs"])
        assert 0 < out[name]["reference_true"] < len(q), (name, out[name])  # both answers drawn
    assert out["coal_calls"]["obstacle"] > 0 and out["coal_calls"]["self"] > 0
    assert out["margin_below"]["0.001"] > 50  # many configurations close to the boundary


def test_certified_never_frees_a_blocked_motion(ref, cage):
    a, b, kind = ref.sample_motions(cage, 1, 150)
    out = ref.compare_certified(cage, a, b, kind, discretized=False)
    assert out["all"]["certified_false_free"] == 0, out
    assert out["all"]["certified_free"] > 50 and out["all"]["dense_free"] < len(a), out


def test_dense_states_stay_on_the_segment(ref, cage):
    """The dense check's states: ``k / n`` of the way, the last one ``b`` itself (the float32
    ``a + 1 * (b - a)`` can round past a joint limit that ``b`` lies on)."""
    lo, hi = (np.asarray(v) for v in cage.robot.config_bounds(cage.world))
    rng = np.random.default_rng(3)
    a = (lo + rng.random((64, 7)) * (hi - lo)).astype(np.float32)
    b = np.where(rng.random((64, 7)) < 0.5, hi, lo).astype(np.float32)
    steps = ref.dense_steps(a, b)
    states = ref.dense_states(a, b, steps)
    ends = np.cumsum(steps + 1)
    np.testing.assert_array_equal(states[ends - 1], b)
    np.testing.assert_array_equal(states[ends - steps - 1], a)
    assert np.all((states >= lo) & (states <= hi))
    gap = np.linalg.norm(np.diff(states.astype(np.float64), axis=0), axis=1)
    inner = np.ones(len(states) - 1, bool)
    inner[ends[:-1] - 1] = False  # the jumps from one motion's end to the next one's start
    assert gap[inner].max() <= ref.DENSE_STEP + 1e-6  # float32 states: ~2.4e-7 per coordinate
