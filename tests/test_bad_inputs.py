"""Hostile inputs (issue 17): each one clear error (or a correct result), nothing written.

Library functions raise a TypeError / ValueError naming the argument and the
expected value; scripts print one ``error:`` line (or argparse's usage and
error lines) with exit code 2 and no traceback, and write nothing.
"""

import importlib.util
import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import jax
import numpy as np
import pytest

import ntq_jax as nj

ROOT = Path(__file__).resolve().parents[1]


def _script(name):
    spec = importlib.util.spec_from_file_location(f"bad_inputs_{name}", ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _files(folder: Path) -> set:
    return {p.relative_to(folder) for p in folder.rglob("*")}


# --- queries, planners, measure_gamma, plan ---

KEY = jax.random.key(0)


@pytest.fixture(scope="module")
def point_env():
    return nj.make_env("point/3")


@pytest.mark.parametrize("call, exc, message", [
    (lambda e: e.sample_queries(KEY, -3), ValueError, r"n must be an int >= 0, got -3"),
    (lambda e: e.sample_queries(KEY, 2.7), TypeError, r"n must be an int >= 0, got 2\.7"),
    (lambda e: e.sample_queries(KEY, True), TypeError, r"n must be an int .*bool"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=float("nan")), ValueError, r"p_nt must be a number in \[0, 1\]"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=1.5), ValueError, r"p_nt must be a number in \[0, 1\], got 1\.5"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=True), TypeError, r"p_nt must be a number in \[0, 1\]"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=1.0, n_max=0), ValueError, r"n_max must be an int >= 1, got 0"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=1.0, n_max=2.5), TypeError, r"n_max must be an int >= 1"),
    (lambda e: e.sample_states(KEY, -1), ValueError, r"n must be an int >= 0, got -1"),
    (lambda e: e.gamma_nt(KEY, 2.7), TypeError, r"n must be an int >= 1, got 2\.7"),
    (lambda e: e.gamma_nt(KEY, 0), ValueError, r"n must be an int >= 1, got 0"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=-8), ValueError, r"chunk must be an int >= 1, got -8"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=0), ValueError, r"chunk must be an int >= 1, got 0"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=4096.0), TypeError, r"chunk must be an int >= 1"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=10**12), ValueError, r"chunk must be an int in \[1, "),
], ids=["sq-negative", "sq-float", "sq-bool", "p_nt-nan", "p_nt-1.5", "p_nt-bool", "n_max-0",
        "n_max-float", "states-negative", "gamma-float", "gamma-0", "chunk-negative", "chunk-0",
        "chunk-float", "chunk-huge"])
def test_api_query_arguments(point_env, call, exc, message):
    with pytest.raises(exc, match=message):
        call(point_env)


def test_api_query_arguments_accept_numpy_ints(point_env):
    est = point_env.gamma_nt(KEY, np.int64(50), chunk=np.int32(1024))
    assert est.queries == 50
    q, kind = point_env.sample_queries(KEY, np.int32(3), p_nt=np.float32(0.5), n_max=np.int64(5))
    assert q.shape == (3, 2, 2) and kind.shape == (3,)


@pytest.mark.parametrize("planner, options, exc, message", [
    ("astar", {"resolution": 50}, ValueError,
     r"astar: resolution 50 is too coarse: .* 0 x 0 cells .* at least 2 x 2; use a resolution <= 10"),
    ("astar", {"resolution": 15}, ValueError, r"too coarse: .* 1 x 1 cells"),
    ("astar", {"resolution": 1e-6}, ValueError, r"astar: resolution 1e-06 is too fine: .* at most 8191"),
    ("astar", {"resolution": 0}, ValueError, r"astar: resolution must be a finite number > 0, got 0"),
    ("astar", {"resolution": "0.1"}, TypeError, r"astar: resolution must be a finite number"),
    ("astar", {"resolutin": 0.2}, TypeError, r"astar: unknown option 'resolutin'; its options are .*resolution"),
    ("astar", {"chunk_size": 0}, ValueError, r"astar: chunk_size must be an int >= 1, got 0"),
    ("astar", {"open_capacity": 10**9}, ValueError, r"astar: open_capacity must be an int in \[1, "),
    ("astar", {"smooth": "no"}, TypeError, r"astar: smooth must be True or False"),
    ("astar", {"check": "exact"}, ValueError, r"astar: check must be one of 'discretized', 'certified'"),
    ("visgraph", {"eps": -1.0}, ValueError, r"visgraph: eps must be a finite number > 0"),
    ("visgraph", {"arc_step": 3.0}, ValueError, r"visgraph: arc_step must be .* <= 1\.5708"),
    ("visgraph", {"resolution": 0.1}, TypeError, r"visgraph: unknown option 'resolution'"),
    ("roadmap", {"milestones": 2.5}, TypeError, r"roadmap: milestones must be an int >= 2"),
    ("roadmap", {"grow_rounds": 9}, ValueError, r"roadmap: grow_rounds must be an int in \[0, 8\]"),
    ("bitstar", {"workers": -1}, ValueError, r"bitstar: workers must be an int >= 0, got -1"),
    ("bitstar", {"time_budget": 0}, ValueError, r"bitstar: time_budget must be a finite number > 0"),
    ("bitstar", {"chunk_size": 0}, ValueError, r"bitstar: chunk_size must be an int >= 1, got 0"),
    ("bitstar", {"stop_on_first": "yes"}, TypeError, r"bitstar: stop_on_first must be True or False"),
    ("nope", {}, ValueError, r"unknown planner 'nope'; available: astar, bitstar, roadmap, visgraph"),
    ("astar", {"seed": 1.5}, TypeError, r"seed must be an int >= 0"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_api_plan_options(point_env, planner, options, exc, message):
    q, _ = point_env.sample_queries(KEY, 2)
    t0 = time.perf_counter()
    with pytest.raises(exc, match=message):
        nj.plan(point_env, q, planner, **options)
    assert time.perf_counter() - t0 < 30  # refused up front, not after building a grid or graph


@pytest.mark.parametrize("queries, message", [
    (np.zeros((2, 2, 3), np.float32), r"queries must have shape \(K, 2, 2\) for point/3, got \(2, 2, 3\)"),
    (np.zeros((2, 2), np.float32), r"queries must have shape \(K, 2, 2\)"),
    ("start to goal", r"queries must be a numeric \(K, 2, 2\) array"),
])
def test_api_plan_queries(point_env, queries, message):
    with pytest.raises((TypeError, ValueError), match=message):
        nj.plan(point_env, queries, "astar")


def test_api_plan_astar_smallest_grid_plans(point_env):
    """The boundary of the resolution check: a 2 x 2 grid is accepted and plans."""
    q, _ = point_env.sample_queries(KEY, 2)
    res = nj.plan(point_env, q, "astar", resolution=10)
    assert res.info["grid_shape"] == (2, 2) and res.status.shape == (2,)


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
    proc = subprocess.run([sys.executable, str(script)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=_env())
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "STATUS ['solved', 'solved']" in proc.stdout
    assert proc.stdout.count("STATUS") == 1  # the script ran once, in the parent only
    assert "bootstrapping phase" not in proc.stderr and "Traceback" not in proc.stderr
    assert "workers cannot start" not in proc.stderr
    assert _files(tmp_path) == {Path("user_script.py")}


def _env():
    import os
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in [env.get("PYTHONPATH")] if p])
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env


@pytest.mark.parametrize("argv, message", [
    (["--padding", "nan"], "argument --padding: must be a finite number >= 0, got 'nan'"),
    (["--padding", "-1"], "argument --padding: must be a finite number >= 0"),
    (["--queries", "1e20"], "argument --queries: must be at most 1e+15, got '1e20'"),
    (["--queries", "2.5"], "argument --queries: must be a whole number >= 1"),
    (["--chunk", "1e12"], "argument --chunk: must be at most"),
    (["--max-hours", "0"], "argument --max-hours: must be a number of hours > 0"),
])
def test_gamma_script_bad_arguments(tmp_path, capsys, argv, message):
    mg = _script("measure_gamma")
    out = tmp_path / "gamma.json"
    with pytest.raises(SystemExit) as e:
        mg.main(argv + ["--json", str(out), "--no-progress"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_gamma_script_json_unwritable_is_checked_first(tmp_path, capsys):
    mg = _script("measure_gamma")
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    for target, message in [(tmp_path / "a_file" / "gamma.json", "is a file, not a folder"),
                            (tmp_path, "is a folder; give a file name")]:
        t0 = time.perf_counter()
        assert mg.main(["--queries", "1e12", "--max-hours", "inf", "--no-progress",
                        "--json", str(target)]) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: --json") and message in lines[0]
        assert captured.out == ""  # no estimate: nothing was measured
        assert time.perf_counter() - t0 < 30  # 1e12 queries would take hours
    assert _files(tmp_path) == before


def test_gamma_script_refuses_a_run_longer_than_max_hours(tmp_path, capsys):
    mg = _script("measure_gamma")
    out = tmp_path / "gamma.json"
    assert mg.main(["--queries", "1e15", "--no-progress", "--json", str(out)]) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--max-hours 24" in errors[0] and " h left" in errors[0]
    assert captured.out == "" and not out.exists() and _files(tmp_path) == set()


def test_gamma_script_ctrl_c_prints_the_estimate_so_far(tmp_path):
    out = tmp_path / "gamma.json"
    proc = subprocess.Popen([sys.executable, str(ROOT / "scripts" / "measure_gamma.py"),
                             "--queries", "1e12", "--max-hours", "inf", "--no-progress",
                             "--json", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        first = proc.stderr.readline()  # the time estimate: streaming has started
        assert "queries/s: about" in first
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    assert "interrupted after" in stdout and "of 1,000,000,000,000 queries" in stdout
    gamma = [line for line in stdout.splitlines() if line.startswith("gamma_nt = ")]
    assert len(gamma) == 1
    value = float(gamma[0].split()[2])
    lo, hi = (float(v) for v in gamma[0].split("[")[1].rstrip("]").split(","))
    assert lo <= value <= hi and hi - lo < 0.01  # point/0 gamma_nt ~0.31, >= 1e6 queries counted
    assert "not written (interrupted)" in stderr and not out.exists()


def test_gamma_interrupted_carries_the_partial_estimate(point_env):
    """gamma_nt's KeyboardInterrupt is a GammaInterrupted with the chunks counted so far."""
    from ntq_jax.queries import GammaInterrupted

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


@pytest.fixture()
def bare_run(tmp_path):
    """A run folder with a config and no models: enough for plan.py's checks before loading."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("envs: [point/2]\n")
    return run


def test_plan_script_png_unwritable_is_checked_first(bare_run, tmp_path, capsys):
    plan = _script("plan")
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    for png, message in [(tmp_path / "a_file" / "fig.png", "is a file, not a folder"),
                         (tmp_path, "is a folder; give a file name")]:
        assert plan.main(["--run", str(bare_run), "--model", "0", "--start", "1", "1",
                          "--goal", "2", "2", "--png", str(png), "--no-compile-cache"]) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        # the --png error, not the missing models: the check comes before any loading
        assert len(lines) == 1 and lines[0].startswith("error: --png") and message in lines[0]
        assert captured.out == ""
    assert _files(tmp_path) == before


def test_plan_script_default_png_checked_after_the_states(bare_run, capsys):
    """With a writable default figure path the script goes on to the models (missing here)."""
    plan = _script("plan")
    assert plan.main(["--run", str(bare_run), "--model", "0", "--start", "1", "1",
                      "--goal", "2", "2", "--no-compile-cache"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and "--png" not in err
    assert not (bare_run / "figures").exists()


def test_api_json_of_gamma_script_round_trip(tmp_path, capsys):
    """A writable --json is written after the work, with the estimate printed."""
    mg = _script("measure_gamma")
    out = tmp_path / "sub" / "gamma.json"
    assert mg.main(["--queries", "2000", "--no-progress", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["queries"] == 2000 and 0 < data["gamma"] < 1
    assert f"gamma_nt = {data['gamma']:.6f}" in capsys.readouterr().out
