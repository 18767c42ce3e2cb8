"""Hostile inputs, the Python API: query arguments, every planner's options (ntq_jax.plan), the
roadmap's memory bound, BIT* from a script, measure_gamma interrupted, A* on a one-cell grid.

Every expected failure is one clear error, nothing is written where it must not be
(split from tests/test_bad_inputs.py by the surface each test probes; the shared
helpers are in bad_inputs_common.py).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest
from bad_inputs_common import _env, _files

import ntq_jax as nj

KEY = jax.random.key(0)


@pytest.fixture(scope="module")
def point_env():
    return nj.make_env("point/3")


@pytest.mark.parametrize(
    "call, exc, message",
    [
        (lambda e: e.sample_queries(KEY, -3), ValueError, r"n must be an int >= 0, got -3"),
        (lambda e: e.sample_queries(KEY, 2.7), TypeError, r"n must be an int >= 0, got 2\.7"),
        (lambda e: e.sample_queries(KEY, True), TypeError, r"n must be an int .*bool"),
        (
            lambda e: e.sample_queries(KEY, 4, p_nt=float("nan")),
            ValueError,
            r"p_nt must be a number in \[0, 1\]",
        ),
        (
            lambda e: e.sample_queries(KEY, 4, p_nt=1.5),
            ValueError,
            r"p_nt must be a number in \[0, 1\], got 1\.5",
        ),
        (
            lambda e: e.sample_queries(KEY, 4, p_nt=True),
            TypeError,
            r"p_nt must be a number in \[0, 1\]",
        ),
        (
            lambda e: e.sample_queries(KEY, 4, p_nt=1.0, n_max=0),
            ValueError,
            r"n_max must be an int >= 1, got 0",
        ),
        (
            lambda e: e.sample_queries(KEY, 4, p_nt=1.0, n_max=2.5),
            TypeError,
            r"n_max must be an int >= 1",
        ),
        (lambda e: e.sample_states(KEY, -1), ValueError, r"n must be an int >= 0, got -1"),
        (lambda e: e.gamma_nt(KEY, 2.7), TypeError, r"n must be an int >= 1, got 2\.7"),
        (lambda e: e.gamma_nt(KEY, 0), ValueError, r"n must be an int >= 1, got 0"),
        (
            lambda e: e.gamma_nt(KEY, 100, chunk=-8),
            ValueError,
            r"chunk must be an int >= 1, got -8",
        ),
        (lambda e: e.gamma_nt(KEY, 100, chunk=0), ValueError, r"chunk must be an int >= 1, got 0"),
        (lambda e: e.gamma_nt(KEY, 100, chunk=4096.0), TypeError, r"chunk must be an int >= 1"),
        (
            lambda e: e.gamma_nt(KEY, 100, chunk=10**12),
            ValueError,
            r"chunk must be an int in \[1, ",
        ),
    ],
    ids=[
        "sq-negative",
        "sq-float",
        "sq-bool",
        "p_nt-nan",
        "p_nt-1.5",
        "p_nt-bool",
        "n_max-0",
        "n_max-float",
        "states-negative",
        "gamma-float",
        "gamma-0",
        "chunk-negative",
        "chunk-0",
        "chunk-float",
        "chunk-huge",
    ],
)
def test_api_query_arguments(point_env, call, exc, message):
    with pytest.raises(exc, match=message):
        call(point_env)


def test_api_query_arguments_accept_numpy_ints(point_env):
    est = point_env.gamma_nt(KEY, np.int64(50), chunk=np.int32(1024))
    assert est.queries == 50
    q, kind = point_env.sample_queries(KEY, np.int32(3), p_nt=np.float32(0.5), n_max=np.int64(5))
    assert q.shape == (3, 2, 2) and kind.shape == (3,)


@pytest.mark.parametrize(
    "planner, options, exc, message",
    [
        (
            "astar",
            {"resolution": 50},
            ValueError,
            r"astar: resolution 50 is too coarse: .* 0 x 0 cells .* at least 2 x 2; use a resolution <= 10",
        ),
        ("astar", {"resolution": 15}, ValueError, r"too coarse: .* 1 x 1 cells"),
        (
            "astar",
            {"resolution": 1e-6},
            ValueError,
            r"astar: resolution 1e-06 is too fine: .* at most 8191",
        ),
        (
            "astar",
            {"resolution": 0},
            ValueError,
            r"astar: resolution must be a finite number > 0, got 0",
        ),
        ("astar", {"resolution": "0.1"}, TypeError, r"astar: resolution must be a finite number"),
        (
            "astar",
            {"resolutin": 0.2},
            TypeError,
            r"astar: unknown option 'resolutin'; its options are .*resolution",
        ),
        ("astar", {"chunk_size": 0}, ValueError, r"astar: chunk_size must be an int >= 1, got 0"),
        (
            "astar",
            {"open_capacity": 10**9},
            ValueError,
            r"astar: open_capacity must be an int in \[1, ",
        ),
        ("astar", {"smooth": "no"}, TypeError, r"astar: smooth must be True or False"),
        (
            "astar",
            {"check": "exact"},
            ValueError,
            r"astar: check must be one of 'discretized', 'certified'",
        ),
        ("visgraph", {"eps": -1.0}, ValueError, r"visgraph: eps must be a finite number > 0"),
        ("visgraph", {"arc_step": 3.0}, ValueError, r"visgraph: arc_step must be .* <= 1\.5708"),
        ("visgraph", {"resolution": 0.1}, TypeError, r"visgraph: unknown option 'resolution'"),
        ("roadmap", {"milestones": 2.5}, TypeError, r"roadmap: milestones must be an int >= 2"),
        (
            "roadmap",
            {"grow_rounds": 9},
            ValueError,
            r"roadmap: grow_rounds must be an int in \[0, 8\]",
        ),
        ("bitstar", {"workers": -1}, ValueError, r"bitstar: workers must be an int >= 0, got -1"),
        (
            "bitstar",
            {"time_budget": 0},
            ValueError,
            r"bitstar: time_budget must be a finite number > 0",
        ),
        (
            "bitstar",
            {"chunk_size": 0},
            ValueError,
            r"bitstar: chunk_size must be an int >= 1, got 0",
        ),
        (
            "bitstar",
            {"stop_on_first": "yes"},
            TypeError,
            r"bitstar: stop_on_first must be True or False",
        ),
        (
            "nope",
            {},
            ValueError,
            r"unknown planner 'nope'; available: astar, .*bitstar, .*roadmap, .*visgraph",
        ),
        ("astar", {"seed": 1.5}, TypeError, r"seed must be an int >= 0"),
    ],
    ids=lambda v: v if isinstance(v, str) else None,
)
def test_api_plan_options(point_env, planner, options, exc, message):
    q, _ = point_env.sample_queries(KEY, 2)
    t0 = time.perf_counter()
    with pytest.raises(exc, match=message):
        nj.plan(point_env, q, planner, **options)
    assert time.perf_counter() - t0 < 30  # refused up front, not after building a grid or graph


@pytest.mark.parametrize(
    "queries, message",
    [
        (
            np.zeros((2, 2, 3), np.float32),
            r"queries must have shape \(K, 2, 2\) for point/3, got \(2, 2, 3\)",
        ),
        (np.zeros((2, 2), np.float32), r"queries must have shape \(K, 2, 2\)"),
        ("start to goal", r"queries must be a numeric \(K, 2, 2\) array"),
    ],
)
def test_api_plan_queries(point_env, queries, message):
    with pytest.raises((TypeError, ValueError), match=message):
        nj.plan(point_env, queries, "astar")


def test_api_plan_astar_smallest_grid_plans(point_env):
    """The boundary of the resolution check: a 2 x 2 grid is accepted and plans."""
    q, _ = point_env.sample_queries(KEY, 2)
    res = nj.plan(point_env, q, "astar", resolution=10)
    assert res.info["grid_shape"] == (2, 2) and res.status.shape == (2,)


def test_api_roadmap_beyond_memory_is_refused_before_any_work(point_env, monkeypatch):
    """issue 52, rough edge 2: ``milestones=10**12`` ran 455 s, then blamed "free space is
    too small"; now one ValueError naming the option, the bytes and the fix, before any
    roadmap is built, also when only the growth rounds' doublings would not fit."""
    import re

    from ntq_jax.planners import options
    from ntq_jax.planners import roadmap as R

    def built(*args, **kwargs):
        raise AssertionError("roadmap built")

    monkeypatch.setattr(R, "roadmap_for", built)  # the check must come before any roadmap
    q, _ = point_env.sample_queries(KEY, 2)
    with pytest.raises(ValueError) as err:  # this machine's own available memory
        nj.plan(point_env, q, "roadmap", milestones=10**12)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("roadmap: milestones 1,000,000,000,000 would need"), (
        msg
    )
    assert re.search(r"at least [\d,]+ bytes .* of memory available; use milestones <= ", msg), msg
    # the default settings (2 growth rounds) pass with 1 GB: about 0.3 GB in 7-D with k 30
    options.roadmap_memory_option(
        "roadmap", R.DEFAULT_MILESTONES, 7, 30, grow_rounds=2, available=10**9
    )

    m, k = 10**6, 10  # memory for exactly this roadmap's first round
    monkeypatch.setattr(options, "available_memory", lambda: options.roadmap_bytes(m, 2, k))
    with pytest.raises(AssertionError, match="roadmap built"):  # round 0 fits: work starts
        nj.plan(point_env, q, "roadmap", milestones=m, k=k, grow_rounds=0)
    with pytest.raises(
        ValueError,
        match=r"roadmap: milestones 1,000,000 .* after 1 growth round "
        r"\(2,000,000 states\).* or fewer grow_rounds$",
    ) as err:
        nj.plan(point_env, q, "roadmap", milestones=m, k=k, grow_rounds=1)
    most = int(re.search(r"use milestones <= ([\d,]+)", str(err.value))[1].replace(",", ""))
    assert m // 3 < most < m  # the advice fits, one more does not
    with pytest.raises(AssertionError, match="roadmap built"):
        nj.plan(point_env, q, "roadmap", milestones=most, k=k, grow_rounds=1)
    with pytest.raises(ValueError, match=f"milestones {most + 1:,} would need"):
        nj.plan(point_env, q, "roadmap", milestones=most + 1, k=k, grow_rounds=1)


BITSTAR_SCRIPT = """\
import jax
import ntq_jax as nj
from ntq_jax.planners import STATUS_NAMES

env = nj.make_env("point/1")
q, _ = env.sample_queries(jax.random.key(0), 2)
res = nj.plan(env, q, "bitstar", time_budget=0.1, workers=2, stop_on_first=True)
print("STATUS", [STATUS_NAMES[int(s)] for s in res.status])
"""


def test_api_bitstar_from_script_without_main_guard(tmp_path):
    """Workers no longer re-run a user's script that lacks ``if __name__ == "__main__":``."""
    pytest.importorskip("ompl")
    script = tmp_path / "user_script.py"
    script.write_text(BITSTAR_SCRIPT)
    proc = subprocess.run(
        [sys.executable, str(script)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env=_env(),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "STATUS ['solved', 'solved']" in proc.stdout
    assert proc.stdout.count("STATUS") == 1  # the script ran once, in the parent only
    assert "bootstrapping phase" not in proc.stderr and "Traceback" not in proc.stderr
    assert "workers cannot start" not in proc.stderr
    assert _files(tmp_path) == {Path("user_script.py")}


def test_gamma_interrupted_carries_the_partial_estimate(point_env):
    """gamma_nt's KeyboardInterrupt is a GammaInterrupted with the chunks counted so far."""
    from ntq_jax.gamma import GammaInterrupted

    calls = []

    def progress(done):
        calls.append(done)
        if len(calls) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as e:
        point_env.gamma_nt(KEY, 10**9, padding=0.0, chunk=4096, progress=progress)
    assert isinstance(e.value, GammaInterrupted)
    est = e.value.estimate
    assert est.queries == calls[-1] > 0 and 0 < est.non_trivial < est.queries
    assert est.ci95[0] <= est.gamma <= est.ci95[1] and est.candidates == 3 * 4096
    full = point_env.gamma_nt(KEY, est.queries, padding=0.0, chunk=4096)
    assert full.non_trivial == est.non_trivial  # the same stream: an exact prefix


def test_grid_astar_on_a_one_cell_grid_map_names_the_map_not_the_resolution(tmp_path):
    from ntq_jax import make_env
    from ntq_jax.planners import plan

    (tmp_path / "one.pgm").write_text("P2\n1 1\n255\n255\n")
    (tmp_path / "one.yaml").write_text(
        "image: one.pgm\nresolution: 1.0\norigin: [0, 0, 0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    env = make_env(tmp_path / "one.yaml")
    q = np.array([[[0.2, 0.2], [0.8, 0.8]]], np.float32)
    for opts in ({}, {"resolution": 0.5}):  # the advice must not be one that fails again
        with pytest.raises(
            ValueError,
            match=r"1 x 1-cell grid.*resolution option does not apply"
            r".*roadmap or visgraph",
        ):
            plan(env, q, "astar", padding=0.0, **opts)
    # the advice works (a small roadmap: the default one checks some 600,000 edges)
    assert plan(env, q, "roadmap", padding=0.0, milestones=500).lengths[0] >= 2
